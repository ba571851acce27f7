"""Writing files safely, shared by every layer above: a result is written whole or not at all."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def write_atomically(path: str | os.PathLike, data: str | bytes) -> None:
    """Writes ``data`` to ``path`` through a temporary file and a rename, so that an existing
    file is never left half-written (nothing the user had is lost on a crash)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mode = "wb" if isinstance(data, bytes) else "w"
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, mode) as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        # mkstemp makes 0600 files; give the result the permissions a plain open() would (or keep
        # those of the file it replaces).
        os.chmod(tmp, path.stat().st_mode & 0o777 if path.exists() else 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


class OutputPathError(ValueError):
    """An output path that cannot be used; the message is one line naming the option and the path."""


def check_output_paths(outputs: dict, inputs: dict | None = None) -> None:
    """Checks, before anything runs, that every output can be written without touching the inputs.

    ``outputs`` and ``inputs`` map a label (e.g. ``"--out"``) to a path (``None`` entries are
    skipped). Refused: an output that is one of the inputs or shares its path with another output
    (also through a link), a folder, a path under a file, a folder that cannot be written or
    created, an existing read-only file. Raises ``OutputPathError``; writes nothing.
    """
    inputs = {label: Path(p) for label, p in (inputs or {}).items() if p is not None}
    seen: dict[str, Path] = {}
    for label, path in outputs.items():
        if path is None:
            continue
        path = Path(path)
        try:
            _check_output(label, path, inputs, seen)
        except OSError as e:  # e.g. a name too long
            raise OutputPathError(f"{label} {path}: cannot write: {e.strerror or e}") from None
        seen[label] = path


def _check_output(label: str, path: Path, inputs: dict, seen: dict) -> None:
    for other_label, other in inputs.items():
        if _same_file(path, other):
            raise OutputPathError(f"{label} {path} is also the {other_label} file: choose another output")
    for other_label, other in seen.items():
        if _same_file(path, other):
            raise OutputPathError(f"{other_label} and {label} are one file ({path}): give each its own path")
    _check_writable(label, path)


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return os.path.realpath(a) == os.path.realpath(b)


def _check_writable(label: str, path: Path) -> None:
    if path.is_dir():
        raise OutputPathError(f"{label} {path} is a folder: give a file path")
    if path.name in ("", ".", ".."):
        raise OutputPathError(f"{label} {path} is not a file name: give a file path")
    folder = path.parent
    while not folder.exists() and not folder.is_symlink() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise OutputPathError(f"{label} {path}: {folder} is not a folder")
    if folder != path.parent:  # write_atomically creates the missing folders
        if not os.access(folder, os.W_OK | os.X_OK):
            raise OutputPathError(f"{label} {path}: cannot create folders in {folder}: permission denied")
        return
    if path.exists() and not os.access(path, os.W_OK):
        raise OutputPathError(f"{label} {path} is read-only: make it writable or choose another path")
    try:  # the way write_atomically will write: a temporary file beside the output
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp")
        os.close(fd)
        os.unlink(tmp)
    except OSError as e:
        raise OutputPathError(f"{label} {path}: cannot write in {folder}: {e.strerror or e}") from None


def prepare_folder(folder: str | os.PathLike, what: str = "output folder") -> list[Path]:
    """Checks, before a run, that ``folder`` can hold its outputs: creates it (with its parents) and
    writes and removes a probe file. Returns the folders it created, outermost first, for
    ``remove_created`` if the run then fails. Raises ``OutputPathError`` (one line, naming ``what``)."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise OutputPathError(f"{what} {folder} is a file, not a folder")
    missing = []
    for parent in (folder, *folder.parents):
        if parent.exists() or parent.is_symlink():
            if not parent.is_dir():
                raise OutputPathError(f"{what} {folder}: cannot create it, {parent} is a file")
            break
        missing.insert(0, parent)
    created = []
    try:
        for path in missing:
            path.mkdir()
            created.append(path)
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".write-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        remove_created(created)
        reason = e.strerror or type(e).__name__
        raise OutputPathError(f"{what} {folder}: cannot write there ({reason})") from None
    return created


def remove_created(folders: list[Path]) -> None:
    """Removes the folders ``prepare_folder`` created (innermost first), where still empty."""
    for folder in reversed(folders):
        try:
            folder.rmdir()
        except OSError:
            pass


def existing_files(folder: str | os.PathLike, patterns) -> dict[Path, tuple[int, int]]:
    """The files in ``folder`` matching the glob ``patterns``, with their (inode, mtime) now."""
    found = {}
    for pattern in patterns:
        for path in Path(folder).glob(pattern):
            if path.is_file() and not path.is_symlink():
                stat = path.stat()
                found[path] = (stat.st_ino, stat.st_mtime_ns)
    return found


def remove_unchanged(before: dict[Path, tuple[int, int]]) -> list[Path]:
    """Removes the files of ``existing_files`` that are still as they were (not written again since:
    ``write_atomically`` makes a new file); returns them."""
    removed = []
    for path, (inode, mtime) in before.items():
        try:
            stat = path.stat()
            if (stat.st_ino, stat.st_mtime_ns) == (inode, mtime):
                path.unlink()
                removed.append(path)
        except OSError:
            pass
    return removed
