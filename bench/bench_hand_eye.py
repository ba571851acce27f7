"""Hand-eye coordination end to end over sixteen motions (issue 5 targets): the cells of
``diagrams/sweeps/hand_eye_seeds.yaml`` run by ``sustain_drake.sweeps`` on Dask, checked against
``experiments.targets``.

    .venv/bin/python bench/bench_hand_eye.py [--cells 0 1 2] [--workers 2] [--duration 130] [--results]

Each cell is one run of ``diagrams/hand_eye.yaml`` (130 s: the slip at 75 s, the head move at
113 s, the walking person) with a seed for the motion, the sensor noise and the person's start
(cell 0: the scenario's own seeds). Prints one row per cell (each adoption, each disturbance, the
false alarms) and, per target, on how many cells it is met: each adopted camera within 2 mm and
0.2 deg, each adopted tool point within 2 mm, the camera in use within the same, the first
convergence within 15 s of the tool point being found, each change detected within 1 s and
re-converged within 15 s of its detection, no false alarm. The sweep's table and summary are in
``--out`` (a re-run skips the cells already there: move it away to measure again).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import axis_text, bench_main, failed, metrics_of  # noqa: E402
from results_page import number  # noqa: E402


def row_text(row) -> str:
    """One cell's line: its adoptions, its changes and their latencies, its false alarms."""
    if failed(row):
        return f"| {row['cell']} | {axis_text(row)} | failed: {row['error']} | | | | |"
    m = metrics_of(row, "hand_eye")
    adoptions = "; ".join(
        f"{a['time_s']:.1f} s {a['kind'].split(',')[0]}: {a['camera_position_error_mm']:.2f} / "
        f"{a['camera_rotation_error_deg']:.2f}, {a['tool_point_error_mm']:.2f}" for a in m["adopted"])
    changes = "; ".join(
        f"{d['kind']} {d['time_s']:.0f} s: {number(d['detection_latency_s'])} s, "
        f"{number(d['reconvergence_after_detection_s'], '.1f')} s" for d in m["disturbances"])
    alarms = ", ".join(f"{t:.1f} s" for t in m["false_alarms_s"]) or "0"
    first = number(m["first_convergence_after_found_s"], ".1f")
    return (f"| {row['cell']} | {axis_text(row)} | {first} s | {adoptions or 'none'} | {changes} | {alarms} "
            f"| {row['wall_s']:.0f} s |")


COLUMNS = ["cell", "seed", "first convergence after found",
           "adoptions: time, kind, camera mm / deg, tool point mm",
           "changes: time, detected after, re-converged after", "false alarms", "wall"]


def main(argv=None) -> int:
    return bench_main(argv, __doc__, "hand_eye_seeds.yaml", "hand_eye", COLUMNS, row_text)


if __name__ == "__main__":
    raise SystemExit(main())
