"""Which points stay fixed on the tool: centrally symmetric corners against points anchored on the
patch where their track began, on scene-matrix tuning cells (issue 27, item 4; never the held-out
set).

Runs each cell's hand-eye loop with the code's defaults (so the motion is the loop's own) and, for
every tracked feature on the held tool (the renderer's labels: evaluation only), computes each
frame both kinds of point from the same images: the refiner's symmetric corners
(``refine_features`` with the loop's refinement) and an anchored point for every track
(``refine_anchored`` with the symmetry test off, so that no track is a corner). Each track seen
in at least 80 % of the frames from ``--start`` to ``--end`` then gets its own camera
(``calibrate_eye_to_hand`` on its samples, with the TRUE tool pose as the hand: the camera is
what the point alone would give). A point fixed on the tool gives the true camera up to the
noise; one whose position moves with the view gives a camera off by its bias times the views'
lever. Prints, per cell and kind, the tracks and their cameras' position error (median and
quartiles, mm).

    .venv/bin/python bench/bench_point_kinds.py --cells 15 17 9 --end 11.5
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

sys.path.insert(0, str(Path(__file__).resolve().parent))
from make_scene_matrix import SWEEPS  # noqa: E402

from sustain_drake.experiments import hand_eye  # noqa: E402
from sustain_drake.identification.batch import calibrate_eye_to_hand  # noqa: E402
from sustain_drake.perception.anchored_points import AnchoredTracks, refine_anchored  # noqa: E402
from sustain_drake.perception.point_refinement import refine_features  # noqa: E402
from sustain_drake.station import build_station, camera_info  # noqa: E402
from sustain_drake.station.scenario_files import load_scenario_string  # noqa: E402
from sustain_drake.sweeps import load_sweep  # noqa: E402
from sustain_drake.systems.optical_flow_tracker import intrinsics_from_camera_info  # noqa: E402

KINDS = ("symmetric corners", "anchored")


def cell_tracks(scenario, start: float, end: float) -> dict:
    """``{kind: {track id: [(p_CP, X_WT, X_WC)]}}`` of the tool's tracked features from ``start`` to
    ``end`` s of a run of ``scenario``, with the poses at each image's capture time."""
    scenario.camera.label = True  # the tool's pixels, for the evaluation only
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(scenario))
    handle = hand_eye.add_to_diagram(builder, station, scenario, None)
    diagram = builder.Build()
    refiner = next(s for s in diagram.GetSystems() if s.get_name() == "feature_refiner")
    corners = refiner.params
    anchored = dataclasses.replace(corners, symmetry_window_px=0)
    sigma = refiner.depth_noise.sigma
    intrinsics = intrinsics_from_camera_info(camera_info(scenario))
    plant = station.GetSubsystemByName("plant")
    tool_body = plant.GetBodyByName("tool")
    tool = int(tool_body.index())
    simulator = Simulator(diagram)
    root = simulator.get_context()
    period = 1.0 / scenario.camera.fps
    out, anchors, t = {kind: {} for kind in KINDS}, AnchoredTracks(), 0.5 * period
    while t < end:
        t += period
        simulator.AdvanceTo(t - 0.5 * period)  # the image's capture time: the poses the camera saw
        sc = station.GetMyContextFromRoot(root)
        X_WC = station.GetOutputPort("true_X_WC").Eval(sc).GetAsMatrix4()
        X_WT = plant.EvalBodyPoseInWorld(plant.GetMyContextFromRoot(root), tool_body).GetAsMatrix4()
        simulator.AdvanceTo(t)  # the tracker has processed that image
        sc = station.GetMyContextFromRoot(root)
        tracker = handle.tracker
        features = tracker.GetOutputPort("tracked_features").Eval(tracker.GetMyContextFromRoot(root))
        if len(features) == 0 or station.GetOutputPort("image_time").Eval(sc)[0] != features.time:
            continue
        color = station.GetOutputPort("color_image").Eval(sc).data
        depth = station.GetOutputPort("depth_image").Eval(sc).data
        label = station.GetOutputPort("label_image").Eval(sc).data[:, :, 0]
        points = {KINDS[0]: refine_features(color, depth, features.p_px, intrinsics, corners)}
        anchors, points[KINDS[1]] = refine_anchored(anchors, color, depth, features.ids, features.p_px,
                                                    intrinsics, anchored, sigma)
        if features.time < start:
            continue
        for kind, refined in points.items():
            pixel = np.clip(np.rint(refined.p_px).astype(int), 0, [label.shape[1] - 1, label.shape[0] - 1])
            on_tool = label[pixel[:, 1], pixel[:, 0]] == tool
            for k in np.flatnonzero(refined.valid & on_tool):
                out[kind].setdefault(int(features.ids[k]), []).append((refined.p_CP[k].copy(), X_WT, X_WC))
    return out


def camera_errors(tracks: dict, min_samples: int) -> np.ndarray:
    """Each long enough track's own camera's position error (mm)."""
    errors = []
    for rows in tracks.values():
        if len(rows) < min_samples:
            continue
        result = calibrate_eye_to_hand(np.array([r[0] for r in rows]), np.array([r[1] for r in rows]))
        errors.append(1e3 * np.linalg.norm(result.X_WC[:3, 3] - rows[-1][2][:3, 3]))
    return np.array(errors)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cells", type=int, nargs="+", required=True, help="tuning cells (with a tool)")
    p.add_argument("--start", type=float, default=3.1, help="s: samples from (default 3.1)")
    p.add_argument("--end", type=float, default=11.5, help="s: to (default 11.5, the first adoption's)")
    args = p.parse_args()
    sweep = load_sweep(SWEEPS / "scene_matrix_tuning.yaml")
    for index in args.cells:
        scenario = load_scenario_string(sweep.cells[index].scenario_text)
        tracks = cell_tracks(scenario, args.start, args.end)
        min_samples = int(0.8 * (args.end - args.start) * scenario.camera.fps)
        scene = ", ".join(value for _, value in sweep.cells[index].overrides if len(value) < 24)
        print(f"cell {index} ({scene}):", flush=True)
        for kind in KINDS:
            e = camera_errors(tracks[kind], min_samples)
            figure = (f"median {np.median(e):.1f} mm, quartiles {np.percentile(e, 25):.1f}-"
                      f"{np.percentile(e, 75):.1f} mm" if e.size else "-")
            print(f"  {kind:>18}: {e.size:3d} tracks of >= {min_samples} samples, own camera {figure}",
                  flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
