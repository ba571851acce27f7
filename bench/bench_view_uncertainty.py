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
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from sustain_drake.experiments.run import simulate_scenario
from sustain_drake.identification.candidates.admission import identifier_of
from sustain_drake.identification.candidates.fitting import joint_camera_sd, joint_refined
from sustain_drake.station import load_scenario
from sustain_drake.station.scenario_files import with_seed

ROOT = Path(__file__).resolve().parents[1]
MIN_SAMPLES = 40  # samples before a candidate is looked at (the TLS has no branch to speak of before)
SHOWN = (100, 150, 200, 250)  # samples of the rows printed


def _find(system, name: str):
    """The subsystem called ``name`` anywhere in the diagram ``system`` (None if there is none)."""
    for s in system.GetSystems():
        if s.get_name() == name:
            return s
        if hasattr(s, "GetSystems"):
            found = _find(s, name)
            if found is not None:
                return found
    return None


def _angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    return math.degrees(math.acos(min(1.0, max(-1.0, (np.trace(R_a.T @ R_b) - 1.0) / 2.0))))


class ViewUncertainty:
    """``simulate_scenario``'s ``on_step``: until the first adoption, every ``every`` s, the row of
    the candidate with the most samples (reads only)."""

    def __init__(self, every: float):
        self.every, self.next, self.rows, self.systems = every, 0.0, [], None

    def __call__(self, t: float, simulator) -> None:
        if t + 1e-9 < self.next:
            return
        self.next = t + self.every
        diagram, root = simulator.get_system(), simulator.get_context()
        if self.systems is None:
            self.systems = _find(diagram, "candidate_identifiers"), _find(diagram, "true_X_WC_matrix")
        candidates, truth = self.systems
        bank = candidates.bank(candidates.GetMyContextFromRoot(root))
        ready = [c for c in bank.candidates if c.solution.num_samples >= MIN_SAMPLES]
        if bank.adoptions or not ready:
            return
        best = max(ready, key=lambda c: c.solution.num_samples)
        solution = identifier_of(best, candidates.criteria, 1.0).solve(refine_estimate=True)
        joint, statistics = joint_refined(replace(best, solution=solution), bank.candidates, bank.archive,
                                          candidates.params)
        estimate = joint.solution.estimate
        sd = joint_camera_sd(statistics, estimate, candidates.params)
        if estimate is None or sd is None:
            return
        X_WC = truth.get_output_port().Eval(truth.GetMyContextFromRoot(root)).reshape(4, 4)
        self.rows.append({"time": t, "samples": solution.num_samples, "points": len(statistics),
                          "error_mm": 1e3 * float(np.linalg.norm(estimate.p_WC - X_WC[:3, 3])),
                          "error_deg": _angle_deg(estimate.R_WC, X_WC[:3, :3]),
                          "sd_mm": 1e3 * sd[0], "sd_deg": math.degrees(sd[1])})


def run(seed: int | None, duration: float, every: float) -> list[dict]:
    scenario = load_scenario(ROOT / "diagrams" / "hand_eye.yaml", "hand_eye")
    if seed is not None:
        scenario = with_seed(scenario, seed)
    monitor = ViewUncertainty(every)
    with tempfile.TemporaryDirectory() as out:
        simulate_scenario(scenario, out, label="view_uncertainty", duration=duration, log_rate=1.0,
                          replay=False, on_step=monitor)
    return monitor.rows


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
