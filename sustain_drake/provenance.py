"""What code a result came from: the commit of the checkout the package runs from."""

from __future__ import annotations

import subprocess
from importlib import metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def source_commit(root: Path = ROOT) -> str:
    """The short commit of the checkout at ``root``, ``"<commit> with local changes"`` when files
    outside ``docs/`` (the results pages benches rewrite) differ from it, or the installed
    package's version outside a git checkout."""
    def git(*args: str) -> str:
        try:
            return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True,
                                  timeout=10).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""
    commit = git("rev-parse", "--short", "HEAD")
    if not commit:
        try:
            return f"sustain_drake {metadata.version('sustain_drake')}"
        except metadata.PackageNotFoundError:
            return "unknown"
    dirty = git("status", "--porcelain", "--untracked-files=no", "--", ".", ":!docs")
    return commit + (" with local changes" if dirty else "")
