"""What the end-to-end benches share: run one scenario per seed in parallel processes, check a
figure against its target, and publish a table on the results page (docs/results.md)."""

from __future__ import annotations

import shlex
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from sustain_drake.files import write_atomically


def run_seeds(run_seed, seeds: list[int], jobs: int, *args) -> list:
    """``[run_seed(*args, seed) ...]`` for each seed, ``jobs`` at a time (each run in its own
    process: a Drake simulation holds one core)."""
    with ProcessPoolExecutor(max_workers=max(1, jobs)) as pool:
        n = len(seeds)
        columns = [[a] * n for a in args]
        return list(pool.map(run_seed, *columns, seeds))


def meets(value, op: str, bound: float) -> bool:
    """Whether ``value`` (None: not measured, so not met) satisfies ``op bound``."""
    if value is None:
        return False
    return {">=": value >= bound, "<=": value <= bound, "==": value == bound}[op]


RESULTS_PAGE = Path(__file__).resolve().parents[1] / "docs" / "results.md"


def publish(section: str, lines: list[str], page: Path = RESULTS_PAGE) -> None:
    """Replaces the block ``section`` of the results page (between ``<!-- BEGIN section -->`` and
    ``<!-- END section -->``) with ``lines``, the command that made them and the commit it ran on
    (local changes to code say so). The page's prose around the block is kept."""
    text = page.read_text(encoding="utf-8")
    begin, end = f"<!-- BEGIN {section} -->", f"<!-- END {section} -->"
    if begin not in text or end not in text:
        raise SystemExit(f"{page}: no block {section} (add the markers {begin} ... {end})")
    command = " ".join(["python", *[shlex.quote(a) for a in [_relative(sys.argv[0]), *sys.argv[1:]]]])
    block = [begin, "", f"Command: `{command}`; commit `{_commit()}`, {time.strftime('%Y-%m-%d')}.", "",
             *lines, "", end]
    head, rest = text.split(begin, 1)
    write_atomically(page, head + "\n".join(block) + rest.split(end, 1)[1])


def _relative(path: str) -> str:
    try:
        return str(Path(path).resolve().relative_to(RESULTS_PAGE.parents[1]))
    except ValueError:
        return path


def _commit() -> str:
    def git(*args):
        return subprocess.run(["git", *args], cwd=RESULTS_PAGE.parents[1], capture_output=True,
                              text=True).stdout.strip()
    commit = git("rev-parse", "--short", "HEAD") or "unknown"
    # Changes to the docs (this page among them) do not change what ran.
    dirty = git("status", "--porcelain", "--untracked-files=no", "--", ".", ":!docs")
    return commit + (" with local changes" if dirty else "")
