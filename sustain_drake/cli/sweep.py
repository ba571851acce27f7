"""``sustain-drake sweep SWEEP.yaml --out DIR``: run many cells of a scenario on Dask.

A sweep file names a base scenario and axes of values for its keys (``sweeps.spec``). The cells
run on a local Dask cluster (one single-threaded worker per core) or on an existing scheduler
(``--scheduler tcp://host:8786``). ``DIR/results.parquet`` gets a row per cell as it finishes; a
re-run skips the cells already there, so an interrupted sweep resumes. ``DIR/summary.md`` and
``DIR/summary_<axis>.png`` give each target's pass rate per axis value. Exit 0 when every cell ran
(targets met or not), 1 when a cell failed (its row has the error), 2 on bad input.
"""

from __future__ import annotations

from pathlib import Path

from sustain_drake.cli.common import EXIT_OK, CliError

EXIT_CELLS_FAILED = 1


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "sweep", help="run the cells of a sweep file on Dask, into a results table and a summary",
        description="Run every cell of a sweep file (a base scenario and axes of values for its "
        "keys) on Dask distributed; results.parquet, summary.md and summary_<axis>.png go to --out. "
        "A re-run skips the cells already in the table.")
    p.add_argument("sweep", type=Path, help="sweep YAML file, e.g. diagrams/sweeps/kinesthetic_seeds.yaml")
    p.add_argument("--out", type=Path, help="output folder (default out/sweeps/<sweep file name>)")
    p.add_argument("--workers", type=int,
                   help="local worker processes (default: one per core); not with --scheduler")
    p.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://host:8786")
    p.add_argument("--retry-failed", action="store_true", help="run again the cells that failed")
    p.add_argument("--list", action="store_true", help="print the cells and exit (nothing runs)")
    p.set_defaults(handler=run)


def run(args) -> int:
    from sustain_drake.sweeps import (
        SweepError,
        SweepRunError,
        load_sweep,
        open_client,
        run_sweep,
        write_summary,
    )

    if args.workers is not None and args.scheduler:
        raise CliError("--workers sets up a local cluster: leave it out with --scheduler")
    if args.workers is not None and args.workers < 1:
        raise CliError(f"--workers must be >= 1, got {args.workers}")
    try:
        sweep = load_sweep(args.sweep)
    except SweepError as e:
        raise CliError(str(e)) from None
    if args.list:
        for cell in sweep.cells:
            values = ", ".join(f"{a}={v}" for a, v in cell.overrides) or "the base scenario"
            print(f"cell {cell.index} [{cell.id}] {cell.duration:g} s: {values}")
        return EXIT_OK
    out = args.out or Path("out") / "sweeps" / args.sweep.stem
    try:
        with open_client(args.workers, args.scheduler) as client:
            table = run_sweep(sweep, out, client, retry_failed=args.retry_failed)
        summary = write_summary(table, sweep, out)
    except SweepRunError as e:
        raise CliError(str(e)) from None
    failed = int(table["error"].notna().sum()) if not table.empty else 0
    print(f"{len(table)} of {len(sweep.cells)} cells in {out / 'results.parquet'}; summary: {summary}")
    if failed:
        print(f"{failed} cell(s) failed: see the error column and {out}/cells/<id>/error.txt")
        return EXIT_CELLS_FAILED
    return EXIT_OK
