"""What the hand-eye candidates really track (hand_eye.yaml, the loop from images, first seconds).

For every candidate feature of the loop, each frame's measured point ``p_CP`` is mapped into the
hand frame with the TRUE camera pose: ``p_H = X_WH^-1 X_WC p_CP``. A point fixed on the hand or
its tool gives the same ``p_H`` every frame (up to depth noise and pixel quantisation); a corner
sliding along a silhouette, or a depth taken from the background, does not. Prints, per
candidate: frames seen, the median ``p_H`` relative to the rod tip, its wander (RMS and 90 %
distance from the median), and the truth-fit RMS of its samples (``best_p_HP_given_camera`` with
the true camera: what Eq. (30) leaves unexplained even with the right camera; from the samples the
loop's identifiers got). With ``--refine`` the mapped points are the refined ones
(``perception.point_refinement`` with the scenario's ``hand_eye.refinement``) rather than the
tracker's own.

    .venv/bin/python bench/bench_hand_eye_candidates.py [--duration 30] [--refine] [--scenario S]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from sustain_drake.experiments import hand_eye
from sustain_drake.identification.candidates import (
    best_p_HP_given_camera,
    mean_squared_error_of,
    pose_at,
    rotation_spread,
)
from sustain_drake.identification.eye_to_hand import pack_x
from sustain_drake.perception.point_refinement import RefinementParams, refine_points
from sustain_drake.station import build_station, camera_info, load_scenario
from sustain_drake.systems.optical_flow_tracker import intrinsics_from_camera_info

ROOT = Path(__file__).resolve().parents[1]


def run(scenario_path: Path, duration: float, refinement: RefinementParams | None = None) -> dict:
    scenario = load_scenario(scenario_path)
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(scenario))
    handle = hand_eye.add_to_diagram(builder, station, scenario, None)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    root = simulator.get_context()
    period = 1.0 / scenario.camera.fps
    tracks: dict[int, list] = {}
    seen_candidates: dict[int, object] = {}
    last_frame = -1.0
    t = 0.0
    info = intrinsics_from_camera_info(camera_info(scenario))
    t = 0.5 * period  # between the tracker's update (0.25 period) and the next image
    while t < duration:
        t += period
        simulator.AdvanceTo(t)
        cc = handle.candidates.GetMyContextFromRoot(root)
        bank = handle.candidates.bank(cc)
        features = handle.tracker.GetOutputPort("tracked_features").Eval(
            handle.tracker.GetMyContextFromRoot(root))
        if features.time <= last_frame:
            continue
        last_frame = features.time
        sc = station.GetMyContextFromRoot(root)
        X_WC = station.GetOutputPort("true_X_WC").Eval(sc).GetAsMatrix4()
        tip = station.GetOutputPort("true_p_HP").Eval(sc).copy()
        X_WH = pose_at(bank, features.time, 0.3 * period)
        if X_WH is None:
            continue
        for c in bank.candidates:
            seen_candidates[c.feature_id] = c
        row = {int(i): k for k, i in enumerate(features.ids)}
        refined, refined_ok = np.zeros((0, 3)), np.zeros(0, bool)
        if refinement is not None and station.GetOutputPort("image_time").Eval(sc)[0] == features.time:
            refined, refined_ok = refine_points(station.GetOutputPort("color_image").Eval(sc).data,
                                                station.GetOutputPort("depth_image").Eval(sc).data,
                                                features.p_px, info, refinement)
        for fid in {c.feature_id for c in bank.candidates}:
            k = row.get(fid)
            if refinement is not None:
                if k is None or k >= refined_ok.size or not refined_ok[k]:
                    continue
                p_CP = refined[k]
            elif k is None or not features.valid[k]:
                continue
            else:
                p_CP = features.p_CP[k]
            p_W = X_WC[:3, :3] @ p_CP + X_WC[:3, 3]
            p_H = X_WH[:3, :3].T @ (p_W - X_WH[:3, 3])
            tracks.setdefault(fid, []).append((features.time, p_H, tip, p_CP.copy(), X_WH.copy()))
    sc = station.GetMyContextFromRoot(root)
    X_WC = station.GetOutputPort("true_X_WC").Eval(sc).GetAsMatrix4()
    return {"tracks": tracks, "candidates": seen_candidates, "X_WC": X_WC,
            "bank": handle.candidates.bank(handle.candidates.GetMyContextFromRoot(root))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", type=Path, default=ROOT / "diagrams" / "hand_eye.yaml")
    parser.add_argument("--duration", type=float, default=30.0)
    parser.add_argument("--refine", action="store_true",
                        help="map the refined points (hand_eye.refinement) instead of the tracker's")
    args = parser.parse_args()
    refinement = load_scenario(args.scenario).hand_eye.refinement.params() if args.refine else None
    out = run(args.scenario, args.duration, refinement)
    R_WC, p_WC = out["X_WC"][:3, :3], out["X_WC"][:3, 3]
    print(f"{'id':>6} {'frames':>6} {'t0':>6} {'t1':>6}  p_H - tip (mm)            wander rms/90% (mm)"
          f"  truth-fit rms (mm)  spread (rad)  solver rms (mm)")
    for fid, rows in sorted(out["tracks"].items()):
        times = np.array([r[0] for r in rows])
        p_H = np.array([r[1] for r in rows])
        tip = rows[-1][2]
        median = np.median(p_H, axis=0)
        d = np.linalg.norm(p_H - median, axis=1)
        c = out["candidates"][fid]
        p_fit = best_p_HP_given_camera(c.statistic, R_WC, p_WC)
        fit = math.sqrt(max(mean_squared_error_of(c.statistic, pack_x(R_WC, p_WC, p_fit)), 0.0))
        rel = 1e3 * (median - tip)
        leader = "LEADER" if fid == out["bank"].leader else ""
        print(f"{fid:6d} {len(rows):6d} {times[0]:6.1f} {times[-1]:6.1f}  "
              f"[{rel[0]:7.1f} {rel[1]:7.1f} {rel[2]:7.1f}]   {1e3 * math.sqrt(np.mean(d * d)):7.1f} "
              f"{1e3 * np.percentile(d, 90):7.1f}   {1e3 * fit:10.2f}      "
              f"{rotation_spread(c.statistic):6.3f}      {1e3 * c.solution.expected_rms:8.2f} {leader}")
    for a in out["bank"].adoptions:
        print(f"adoption t={a.time:.2f} feature {a.feature_id} kind {a.kind}")


if __name__ == "__main__":
    main()
