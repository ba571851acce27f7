"""Sweep throughput on Dask: the same cells on 1 and on 2 local workers (issue: 2 workers >= 1.8x
the throughput of 1).

    .venv/bin/python bench/bench_sweep.py [--sweep diagrams/sweeps/hand_eye_seeds.yaml] [--cells 0 1 2 3]
                                          [--duration 10] [--repeat 2] [--results]

Each measurement starts a local cluster, then times ``run_sweep`` over the cells into a fresh
folder (cluster start-up is not counted; each worker's first cell pays its imports). Worker counts
alternate (1, 2, 1, 2, ...) so that a change in the machine's load hits both; the median of
``--repeat`` runs each is reported. Run it on a quiet machine: the two workers need both cores.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import ROOT, select_cells  # noqa: E402
from results_page import publish  # noqa: E402

from sustain_drake.sweeps import load_sweep, open_client, run_sweep  # noqa: E402


def cells_per_minute(sweep, workers: int) -> float:
    with open_client(workers) as client, tempfile.TemporaryDirectory() as out:
        client.wait_for_workers(workers)
        start = time.perf_counter()
        table = run_sweep(sweep, out, client, progress=False)
        wall = time.perf_counter() - start
    if table["error"].notna().any():
        raise SystemExit(f"a cell failed: {table['error'].dropna().iloc[0]}")
    return 60.0 * len(table) / wall


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sweep", type=Path, default=ROOT / "diagrams" / "sweeps" / "hand_eye_seeds.yaml")
    p.add_argument("--cells", type=int, nargs="+", default=[0, 1, 2, 3])
    p.add_argument("--duration", type=float, default=10.0)
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--results", action="store_true", help="also write the table on docs/results.md")
    args = p.parse_args()
    sweep = select_cells(load_sweep(args.sweep), args.cells, args.duration)
    rates = {1: [], 2: []}
    for _ in range(args.repeat):
        for workers in (1, 2):
            rates[workers].append(cells_per_minute(sweep, workers))
            print(f"{workers} worker(s): {rates[workers][-1]:.2f} cells/min", flush=True)
    one, two = (statistics.median(rates[w]) for w in (1, 2))
    lines = [f"{len(sweep.cells)} cells of `{args.sweep.name}` ({args.duration:g} s each), "
             f"median of {args.repeat}:",
             "", "| workers | cells per minute | runs |", "|---|---|---|"]
    lines += [f"| {w} | {statistics.median(rates[w]):.2f} | {', '.join(f'{r:.2f}' for r in rates[w])} |"
              for w in (1, 2)]
    lines += ["", f"2 workers / 1 worker: **{two / one:.2f}x**"]
    print("\n".join(lines))
    if args.results:
        publish("bench_sweep", lines)


if __name__ == "__main__":
    main()
