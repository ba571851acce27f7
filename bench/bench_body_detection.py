"""Body detection end to end over several seeds (issue 4 targets), through the code path of
``sustain-drake simulate SCENARIO --seed N`` (``experiments.run.simulate_file``).

    .venv/bin/python bench/bench_body_detection.py [--seeds 1 2 3 4 5] [--jobs 2]

Each seed is one run of ``diagrams/body_detection.yaml`` (60 s, the walking person) with the
seed overriding the motion, the sensor noise and the person's start; its outputs go to
``--out/seed_N/`` (metrics.json, likelihood maps). Prints one row per seed and the aggregate,
and checks the targets: precision >= 0.95, recall >= 0.8, 0 distractor cells marked body,
median detection latency <= 1 s. Writes the table to ``--out/summary.json``.

It also times, inside each run, the tracker's and the detector's per-frame work (the pure
cores the two LeafSystems call: ``track_frame``, and ``step`` with the feature memory) and
reports the median per frame (ms), measured while ``--jobs`` runs share the machine.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from seeds import meets, publish, run_seeds  # noqa: E402  (bench/seeds.py)

from sustain_drake.experiments.run import simulate_file  # noqa: E402
from sustain_drake.files import write_atomically  # noqa: E402

TARGETS = {"precision": (">=", 0.95), "recall": (">=", 0.8),
           "distractor_cells_marked": ("==", 0), "latency_median_s": ("<=", 1.0)}
COLUMNS = ("precision", "recall", "iou", "distractor_cells_marked", "latency_median_s",
           "latency_p90_s", "body_cells_true", "body_cells_marked", "distractor_cells")


def _timed(module, name: str, log: list[float]):
    """Wraps ``module.name`` so that each call's duration (s) is appended to ``log``."""
    fn = getattr(module, name)

    def timed(*args, **kwargs):
        start = time.perf_counter()
        out = fn(*args, **kwargs)
        log.append(time.perf_counter() - start)
        return out
    setattr(module, name, timed)
    return fn


def run_seed(scenario: Path, out: Path, duration: float | None, seed: int) -> dict:
    # Per-frame cost of the tracker and the detector in this run (this worker process only).
    import sustain_drake.systems.motion_coincidence_detector as detector_module
    import sustain_drake.systems.optical_flow_tracker as tracker_module
    logs = {"tracker": [], "detector": [], "features": []}
    originals = [(tracker_module, "track_frame", _timed(tracker_module, "track_frame",
                                                         logs["tracker"])),
                 (detector_module, "step", _timed(detector_module, "step", logs["detector"])),
                 (detector_module, "update_feature_memory",
                  _timed(detector_module, "update_feature_memory", logs["features"]))]
    try:
        result = simulate_file(scenario, seed=seed, duration=duration, out=out / f"seed_{seed}",
                               replay=False)
    finally:
        for module, name, fn in originals:
            setattr(module, name, fn)
    n = min(len(v) for v in logs.values())
    per_frame = [sum(v[k] for v in logs.values()) for k in range(n)]
    metrics = json.loads(result.metrics.read_text())
    m = metrics["body_detection"]
    row = {name: m[name] for name in COLUMNS}
    row["latencies_s"] = m["latencies_s"]
    row.update(seed=seed, wall_s=result.wall, features_on_body=m["detector"]["features_on_body"],
               confirm_trials=m["detector"]["confirm_trials"],
               recall_cells=m["parts"]["cells"]["recall"],
               recall_features=m["parts"]["features"]["recall"],
               ms_per_frame=1e3 * statistics.median(per_frame) if per_frame else None)
    return row


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", type=Path, default=ROOT / "diagrams" / "body_detection.yaml")
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    p.add_argument("--duration", type=float, help="simulated seconds (default: the scenario's)")
    p.add_argument("--jobs", type=int, default=1, help="seeds simulated in parallel")
    p.add_argument("--out", type=Path, default=ROOT / "out" / "bench_body_detection")
    p.add_argument("--results", action="store_true", help="also write the table on docs/results.md")
    args = p.parse_args(argv)

    rows = run_seeds(run_seed, args.seeds, args.jobs, args.scenario, args.out, args.duration)
    header = ("seed", "precision", "recall", "iou", "distr.", "latency median / p90", "true",
              "marked", "recall cells/features", "ms/frame", "wall")
    table = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        latency = ("n/a" if r["latency_median_s"] is None
                   else f"{r['latency_median_s']:.2f} / {r['latency_p90_s']:.2f} s")
        table.append(f"| {r['seed']} | {r['precision']:.3f} | {r['recall']:.3f} | {r['iou']:.3f} | "
              f"{r['distractor_cells_marked']} of {r['distractor_cells']} | {latency} | "
              f"{r['body_cells_true']} | {r['body_cells_marked']} | "
              f"{r['recall_cells']:.2f} / {r['recall_features']:.2f} | "
              f"{r['ms_per_frame']:.2f} | {r['wall_s']:.0f} s |")
    summary = {"seeds": args.seeds, "rows": rows, "aggregate": {}, "targets": {}}
    for name, (op, bound) in TARGETS.items():
        values = [r[name] for r in rows]
        known = [v for v in values if v is not None]
        agg = {"min": min(known) if known else None, "median": statistics.median(known)
               if known else None, "max": max(known) if known else None}
        ok = all(meets(v, op, bound) for v in values)
        summary["aggregate"][name] = agg
        summary["targets"][name] = {"target": f"{op} {bound:g}", "met_on_every_seed": ok,
                                    "seeds_met": sum(meets(v, op, bound) for v in values)}
        table.append(f"- {name}: min {agg['min']}, median {agg['median']}, max {agg['max']} "
              f"(target {op} {bound:g}: met on {summary['targets'][name]['seeds_met']} of "
              f"{len(values)} seeds)")
    # The latency over every detected cell of every seed (each seed's median is above).
    pooled = [x for r in rows for x in r["latencies_s"]]
    if pooled:
        summary["aggregate"]["latency_pooled_s"] = {
            "cells": len(pooled), "median": statistics.median(pooled),
            "p90": statistics.quantiles(pooled, n=10)[-1] if len(pooled) > 1 else pooled[0]}
        table.append(f"- latency over all {len(pooled)} detected cells of the {len(rows)} seeds: median "
              f"{statistics.median(pooled):.2f} s, p90 "
              f"{summary['aggregate']['latency_pooled_s']['p90']:.2f} s")
    print("\n".join(table))
    if args.results:
        publish("bench_body_detection", table)
    write_atomically(args.out / "summary.json", json.dumps(summary, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
