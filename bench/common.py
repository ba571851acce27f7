"""What the end-to-end benches share: run a sweep file's cells (``sustain_drake.sweeps``, on Dask),
count each target over the cells, and publish a table on the results page (docs/results.md)."""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import pandas as pd
from results_page import publish  # bench/results_page.py

from sustain_drake.experiments.targets import TARGETS
from sustain_drake.sweeps import Sweep, load_sweep, open_client, read_table, run_sweep, write_summary

ROOT = Path(__file__).resolve().parents[1]


def sweep_arguments(description: str, sweep: str, out: str) -> argparse.ArgumentParser:
    """The options every end-to-end bench takes (its sweep file and output folder by default)."""
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--sweep", type=Path, default=ROOT / "diagrams" / "sweeps" / sweep,
                   help="the sweep file whose cells are run (default: %(default)s)")
    p.add_argument("--cells", type=int, nargs="+", help="run only these cells (indices, see "
                   "`sustain-drake sweep FILE --list`)")
    p.add_argument("--duration", type=float, help="simulated seconds of every cell (default: the sweep's)")
    p.add_argument("--workers", type=int, help="local Dask workers (default: one per core)")
    p.add_argument("--scheduler", help="address of a running Dask scheduler instead")
    p.add_argument("--out", type=Path, default=ROOT / "out" / out,
                   help="the sweep's output folder; a re-run skips the cells already there")
    p.add_argument("--results", action="store_true", help="also write the table on docs/results.md")
    p.add_argument("--report", action="store_true", help="run nothing: report the cells already in "
                   "--out (with --results, published as a partial table saying how many ran)")
    p.set_defaults(default_sweep=ROOT / "diagrams" / "sweeps" / sweep)
    return p


def run_bench(args) -> pd.DataFrame:
    """Runs the chosen cells of ``args.sweep`` (those already in ``args.out`` are kept) and returns
    their rows of the results table, in cell order; writes the sweep's summary beside it."""
    if args.results and (args.cells or args.duration or args.sweep != args.default_sweep):
        raise SystemExit("--results publishes the default sweep's whole cells only (no --cells, "
                         "--duration or --sweep)")
    sweep = select_cells(load_sweep(args.sweep), args.cells, args.duration)
    if args.report:
        table = read_table(args.out)
        if table.empty:
            raise SystemExit(f"{args.out} holds no results of {args.sweep.name} yet")
        return table[table["cell_id"].isin({c.id for c in sweep.cells})].sort_values("cell")
    with open_client(args.workers, args.scheduler) as client:
        table = run_sweep(sweep, args.out, client)
    write_summary(table, sweep, args.out)
    return table


def select_cells(sweep: Sweep, indices: list[int] | None, duration: float | None) -> Sweep:
    """``sweep`` with only the cells ``indices`` (None: all), each ``duration`` s long (None: as
    the sweep file says)."""
    cells = sweep.cells
    if indices is not None:
        unknown = sorted(set(indices) - {c.index for c in cells})
        if unknown:
            raise SystemExit(f"{sweep.path} has no cell(s) {unknown} (it has 0-{len(cells) - 1})")
        cells = tuple(c for c in cells if c.index in indices)
    if duration is not None:
        cells = tuple(dataclasses.replace(c, duration=duration) for c in cells)
    return dataclasses.replace(sweep, cells=cells)


def failed(row) -> bool:
    """Whether a row's cell failed (its ``error`` holds why; empty is None or NaN)."""
    return isinstance(row["error"], str)


def metrics_of(row, experiment: str) -> dict:
    """A row's metrics section of ``experiment`` ({} for a failed cell)."""
    return json.loads(row["metrics_json"]).get(experiment, {})


def axis_text(row) -> str:
    """A row's cell as its axes' values, e.g. ``seed=4``."""
    return ", ".join(f"{k[5:]}={row[k]}" for k in row.index if k.startswith("axis.")) or "base"


def target_lines(table: pd.DataFrame, experiment: str) -> list[str]:
    """``- <target> <op> <bound>: met on k of n cells`` for each target of ``experiment`` (a failed
    cell counts as not met)."""
    lines = []
    for target in TARGETS[experiment]:
        column = f"target.{experiment}.{target.name}.met"
        met = int(table[column].fillna(False).astype(bool).sum()) if column in table else 0
        lines.append(f"- {target.text}: met on {met} of {len(table)} cells")
    failed = int(table["error"].notna().sum())
    if failed:
        lines.append(f"- {failed} cell(s) failed: " + "; ".join(
            f"cell {r['cell']}: {r['error']}" for _, r in table[table["error"].notna()].iterrows()))
    return lines


def bench_main(argv, doc: str, sweep: str, experiment: str | None, columns: list[str], row_text,
               extra=lambda table: [], block: str | None = None) -> int:
    """A bench's whole run: its options, its sweep's cells, then a table (``columns``, one
    ``row_text(row)`` per cell; none when ``columns`` is empty), the targets of ``experiment``
    (none when it is None) and ``extra(table)`` lines, printed and, with ``--results``, published
    as the block ``block`` (default ``bench_<experiment>``)."""
    block = block or f"bench_{experiment}"
    args = sweep_arguments(doc.splitlines()[0], sweep, block).parse_args(argv)
    table = run_bench(args)
    lines = []
    if columns:  # else ``extra`` tables the cells itself
        lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
        lines += [row_text(row) for _, row in table.iterrows()]
    lines += (target_lines(table, experiment) if experiment else []) + extra(table)
    ran_at = sorted(set(table["commit"])) if "commit" in table and not table.empty else []
    if ran_at:
        lines.append("- cells run at commit(s): " + ", ".join(f"`{c}`" for c in ran_at))
    total = len(select_cells(load_sweep(args.sweep), args.cells, args.duration).cells)
    if len(table) < total:
        lines.append(f"- {len(table)} of the sweep's {total} cells have run (the rest: not yet)")
    print("\n".join(lines))
    if args.results:  # stamped with the commit(s) the cells ran at (a report may come later)
        publish(block, lines, commit=", ".join(ran_at) or None)
    return 0
