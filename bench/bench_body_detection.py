"""Body detection end to end over fifteen motions (issue 4 targets): the cells of
``diagrams/sweeps/body_detection_seeds.yaml`` run by ``sustain_drake.sweeps`` on Dask, checked
against ``experiments.targets``.

    .venv/bin/python bench/bench_body_detection.py [--cells 0 1] [--workers 2] [--results]

Each cell is one run of ``diagrams/body_detection.yaml`` (60 s, the walking person) with a seed for
the motion, the sensor noise and the person's start. Prints one row per cell and, per target, on
how many cells it is met: precision >= 0.95, recall >= 0.8, 0 distractor cells marked body, median
detection latency <= 1 s; and the latency pooled over every detected cell. Seeds 1-10 tuned the
detector; 11-15 are held out. The per-frame cost of the tracker and the detector is
``bench/bench_perception.py``'s.
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import axis_text, bench_main, failed, metrics_of  # noqa: E402

HELD_OUT_FROM_SEED = 11


def row_text(row) -> str:
    if failed(row):
        return f"| {axis_text(row)} | failed: {row['error']} | | | | | | |"
    m = metrics_of(row, "body_detection")
    seed = axis_text(row) + (" (held out)" if int(row["axis.seed"]) >= HELD_OUT_FROM_SEED else "")
    latency = ("n/a" if m["latency_median_s"] is None
               else f"{m['latency_median_s']:.2f} s / {m['latency_p90_s']:.2f} s")
    return (f"| {seed} | {m['precision']:.3f} | {m['recall']:.3f} | {m['iou']:.3f} | "
            f"{m['distractor_cells_marked']} of {m['distractor_cells']} | {latency} | "
            f"{m['body_cells_true']} / {m['body_cells_marked']} | "
            f"{m['parts']['cells']['recall']:.2f} / {m['parts']['features']['recall']:.2f} |")


COLUMNS = ["cell", "precision", "recall", "IoU", "distractor cells marked", "latency median / p90",
           "true / marked cells", "recall: cells / features"]


def pooled_latency(table) -> list[str]:
    """The latency over every detected cell of every run (each run's median is in its row)."""
    pooled = [x for _, row in table.iterrows() if not failed(row)
              for x in metrics_of(row, "body_detection").get("latencies_s", [])]
    if len(pooled) < 2:
        return []
    return [f"- latency over all {len(pooled)} detected cells: median {statistics.median(pooled):.2f} s, "
            f"p90 {statistics.quantiles(pooled, n=10)[-1]:.2f} s"]


def main(argv=None) -> int:
    return bench_main(argv, __doc__, "body_detection_seeds.yaml", "body_detection", COLUMNS, row_text,
                      pooled_latency)


if __name__ == "__main__":
    raise SystemExit(main())
