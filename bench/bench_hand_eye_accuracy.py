"""Accuracy of the first hand-eye adoption over motion seeds (hand_eye.yaml, short runs).

Runs ``sustain-drake simulate SCENARIO --duration D --seed N --no-replay`` for each seed (``--jobs``
at a time: one simulation holds one core) and prints, per seed, the first adoption's time, its
camera position error (and the part along the optical axis), rotation error and tool point error
(``metrics.json`` ``hand_eye.adopted[0]``), with the mean and worst over the seeds; then the camera
of the model in use at the end of the run (``model_in_use_at_end``: with ``adopt_refinements``
the adopted model refined while observing) and the false alarms.

    .venv/bin/python bench/bench_hand_eye_accuracy.py [--seeds 3 1 2 4] [--duration 50] [--scenario S]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
KEYS = ("time_s", "camera_position_error_mm", "camera_position_error_along_axis_mm",
        "camera_rotation_error_deg", "tool_point_error_mm")


def run_seed(scenario: Path, duration: float, out: Path, seed: int) -> dict | None:
    """The ``hand_eye`` metrics of one run (None if the run failed)."""
    folder = out / f"seed{seed}"
    command = [str(ROOT / ".venv" / "bin" / "sustain-drake"), "simulate", str(scenario), "--duration",
               str(duration), "--seed", str(seed), "--out", str(folder), "--no-replay"]
    done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT)
    if done.returncode != 0:
        print(f"seed {seed}: simulate failed: {done.stderr.strip().splitlines()[-1:]}", file=sys.stderr)
        return None
    return json.loads((folder / "metrics.json").read_text())["hand_eye"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", type=Path, default=ROOT / "diagrams" / "hand_eye.yaml")
    parser.add_argument("--seeds", type=int, nargs="+", default=[3, 1, 2, 4])
    parser.add_argument("--duration", type=float, default=50.0)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "bench_hand_eye_accuracy")
    args = parser.parse_args()
    with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        results = list(pool.map(lambda s: run_seed(args.scenario, args.duration, args.out, s), args.seeds))
    print(f"{'seed':>4} {'adopted (s)':>11} {'camera (mm)':>11} {'along axis':>10} {'rot (deg)':>9} "
          f"{'tool pt (mm)':>12}")
    rows, ends = [], []
    for seed, metrics in zip(args.seeds, results, strict=True):
        a = metrics["adopted"][0] if metrics and metrics["adopted"] else None
        if metrics:
            ends.append((seed, metrics["model_in_use_at_end"], metrics["num_false_alarms"]))
        if a is None:
            print(f"{seed:4d} {'none':>11}")
            continue
        rows.append([a[k] for k in KEYS])
        print(f"{seed:4d} {a['time_s']:11.1f} {a['camera_position_error_mm']:11.2f} "
              f"{a['camera_position_error_along_axis_mm']:10.2f} {a['camera_rotation_error_deg']:9.2f} "
              f"{a['tool_point_error_mm']:12.2f}")
    if rows:
        for name, pick in (("mean", lambda v: sum(v) / len(v)), ("worst", lambda v: max(v, key=abs))):
            values = [pick([r[i] for r in rows]) for i in range(len(KEYS))]
            print(f"{name:>4} {'':>11} {values[1]:11.2f} {values[2]:10.2f} {values[3]:9.2f} "
                  f"{values[4]:12.2f}")
    print(f"\n{'seed':>4} {'model in use at the end: camera (mm)':>37} {'rot (deg)':>9} {'false alarms':>12}")
    for seed, end, alarms in ends:
        if end is None:
            print(f"{seed:4d} {'none':>37} {'':>9} {alarms:12d}")
        else:
            mm, deg = end["camera_position_error_mm"], end["camera_rotation_error_deg"]
            print(f"{seed:4d} {mm:37.2f} {deg:9.2f} {alarms:12d}")


if __name__ == "__main__":
    main()
