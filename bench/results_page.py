"""The results page (docs/results.md): a bench replaces its block with its table, the command that
made it and the commit it ran on. No heavy imports, so any bench can use it."""

from __future__ import annotations

import math
import shlex
import sys
import time
from pathlib import Path

from sustain_drake.files import write_atomically
from sustain_drake.provenance import source_commit

ROOT = Path(__file__).resolve().parents[1]
RESULTS_PAGE = ROOT / "docs" / "results.md"


def number(value, spec: str = ".2f") -> str:
    """A figure of a table: ``value`` formatted with ``spec``; "-" when there is none (None, NaN, inf)."""
    missing = value is None or (isinstance(value, float) and not math.isfinite(value))
    return "-" if missing else format(value, spec)


def publish(section: str, lines: list[str], page: Path = RESULTS_PAGE, commit: str | None = None) -> None:
    """Replaces the block ``section`` of the results page (between ``<!-- BEGIN section -->`` and
    ``<!-- END section -->``) with ``lines``, the command that made them and the commit it ran on
    (``commit``, default this checkout's; local changes to code say so). The page's prose around
    the block is kept."""
    text = page.read_text(encoding="utf-8")
    begin, end = f"<!-- BEGIN {section} -->", f"<!-- END {section} -->"
    if begin not in text or end not in text:
        raise SystemExit(f"{page}: no block {section} (add the markers {begin} ... {end})")
    command = " ".join(["python", *[shlex.quote(a) for a in [_relative(sys.argv[0]), *sys.argv[1:]]]])
    stamp = f"Command: `{command}`; commit `{commit or source_commit()}`, {time.strftime('%Y-%m-%d')}."
    block = [begin, "", stamp, "", *lines, "", end]
    head, rest = text.split(begin, 1)
    write_atomically(page, head + "\n".join(block) + rest.split(end, 1)[1])


def _relative(path: str) -> str:
    try:
        return str(Path(path).resolve().relative_to(ROOT))
    except ValueError:
        return path
