"""Whether the joint fit's own uncertainty tells when the views determine the camera (issue 25): before
the first adoption of ``diagrams/hand_eye.yaml``'s runs, every ``--every`` s, the camera the
candidate with the most samples would lead with (refined jointly with the points it explains,
``fitting.joint_refined``), its error against the true camera and its 1 sd from the joint fit's
Gauss-Newton covariance (``fitting.joint_camera_sd``). The run itself is left as it is (reads only).

    .venv/bin/python bench/bench_view_uncertainty.py [--seeds ~ 1 2 4] [--duration 14] [--every 0.2]

Prints, per seed, the rows nearest 100, 150, 200 and 250 samples of that candidate: samples, points
in the joint fit, camera error (mm, deg) and its 1 sd (mm, deg). A rule "adopt when the 1 sd is at
most B" would judge the views themselves rather than count samples (``hand_eye.min_samples``);
docs/hand_eye_record.md has what it showed.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from sustain_drake.experiments import hand_eye
from sustain_drake.identification.candidates.admission import identifier_of
from sustain_drake.identification.candidates.fitting import joint_camera_sd, joint_refined
from sustain_drake.identification.rotation import rotation_angle
from sustain_drake.station import build_station, load_scenario
from sustain_drake.station.scenario_files import with_seed

ROOT = Path(__file__).resolve().parents[1]
MIN_SAMPLES = 40  # samples before a candidate is looked at (the TLS has no branch to speak of before)
SHOWN = (100, 150, 200, 250)  # samples of the rows printed


def row(t: float, candidates, bank, X_WC) -> dict | None:
    """The row at ``t``: the candidate with the most samples (at least ``MIN_SAMPLES``) refined and
    joined with the points it explains, its camera's error against ``X_WC`` (a RigidTransform) and
    its 1 sd; None before such a candidate or when the joint fit is undetermined."""
    ready = [c for c in bank.candidates if c.solution.num_samples >= MIN_SAMPLES]
    if not ready:
        return None
    best = max(ready, key=lambda c: c.solution.num_samples)
    solution = identifier_of(best, candidates.criteria, 1.0).solve(refine_estimate=True)
    joint, statistics, independent = joint_refined(replace(best, solution=solution), bank.candidates,
                                             bank.archive, candidates.params)
    estimate = joint.solution.estimate
    sd = joint_camera_sd(statistics, estimate, candidates.params, independent)
    if sd is None:
        return None
    return {"time": t, "samples": solution.num_samples, "points": len(statistics),
            "error_mm": 1e3 * float(np.linalg.norm(estimate.p_WC - X_WC.translation())),
            "error_deg": math.degrees(rotation_angle(estimate.R_WC.T @ X_WC.rotation().matrix())),
            "sd_mm": 1e3 * sd[0], "sd_deg": math.degrees(sd[1])}


def run(seed: int | None, duration: float, every: float) -> list[dict]:
    """One run of ``hand_eye.yaml`` (``seed``: the motion's, None: the scenario's) to ``duration`` s
    or its first adoption: the rows every ``every`` s."""
    scenario = load_scenario(ROOT / "diagrams" / "hand_eye.yaml", "hand_eye")
    if seed is not None:
        scenario = with_seed(scenario, seed)
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(scenario))
    candidates = hand_eye.add_to_diagram(builder, station, scenario, None).candidates
    simulator = Simulator(builder.Build())
    root = simulator.get_context()
    rows, t = [], 0.0
    while t < duration - 1e-9:
        t = min(t + every, duration)
        simulator.AdvanceTo(t)
        bank = candidates.bank(candidates.GetMyContextFromRoot(root))
        if bank.adoptions:
            break
        X_WC = station.GetOutputPort("true_X_WC").Eval(station.GetMyContextFromRoot(root))
        found = row(t, candidates, bank, X_WC)
        if found is not None:
            rows.append(found)
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", nargs="+", default=["~", "1", "2", "4"],
                   help="motion seeds (~: the scenario's)")
    p.add_argument("--duration", type=float, default=14.0, help="simulated s per run (default 14)")
    p.add_argument("--every", type=float, default=0.2, help="s between rows (default 0.2)")
    args = p.parse_args()
    print("| seed | samples | points | camera error (mm / deg) | its 1 sd (mm / deg) |")
    print("|---|---|---|---|---|")
    for text in args.seeds:
        rows = run(None if text == "~" else int(text), args.duration, args.every)
        for target in SHOWN:
            near = min(rows, key=lambda r: abs(r["samples"] - target), default=None)
            if near is None or abs(near["samples"] - target) > 20:
                continue
            print(f"| {text} | {near['samples']} | {near['points']} | {near['error_mm']:.2f} / "
                  f"{near['error_deg']:.3f} | {near['sd_mm']:.2f} / {near['sd_deg']:.3f} |", flush=True)


if __name__ == "__main__":
    main()
