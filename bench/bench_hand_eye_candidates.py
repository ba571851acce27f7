"""What the hand-eye candidates really track (hand_eye.yaml, the loop from images, first seconds).

For every candidate feature of the loop, each frame's measured point ``p_CP`` is mapped into the
hand frame with the TRUE camera pose: ``p_H = X_WH^-1 X_WC p_CP``. A point fixed on the hand or
its tool gives the same ``p_H`` every frame (up to depth noise and pixel quantisation); a corner
sliding along a silhouette, or a depth taken from the background, does not. Prints, per
candidate: frames seen, the median ``p_H`` relative to the rod tip, its wander (RMS and 90 %
distance from the median), and the truth-fit RMS of its samples (``best_p_HP_given_camera`` with
the true camera: what Eq. (30) leaves unexplained even with the right camera; from the samples the
loop's identifiers got). With ``--refine`` the mapped points are the refined ones
(``perception.point_refinement`` with the loop's refinement, ``hand_eye_parts``) rather than the
tracker's own.

Then, against the TRUE 3-D position of the mark each candidate tracks: the rod's checker corners
and cell centres are known in the tool frame (``models/generate_assets.py``: 50 mm square, two
18 mm columns between 7 mm margins, 25 mm rows), so each candidate's median ``p_H`` is snapped to
the nearest such mark, and every sample's error ``p_CP - X_CW X_WH p_H(mark)`` is split into its component
along the camera ray (depth) and across it. Printed for three versions of the same features'
points, on the same frames: the tracker's, the refined ones with the window's median depth, and
the refined ones with the depth on the face's plane at the sub-pixel point (``depth_plane``):
the mean along the ray (the bias that shifts the camera along its optical axis) and the RMS.

    .venv/bin/python bench/bench_hand_eye_candidates.py [--duration 30] [--refine] [--scenario S] [--seed N]
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
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
from sustain_drake.loops.hand_eye import HandEyeParts, hand_eye_parts
from sustain_drake.perception.optical_flow import to_gray
from sustain_drake.perception.point_refinement import (
    RefinementParams,
    local_depth,
    refine_pixels,
    refine_points,
)
from sustain_drake.station import build_station, camera_info, load_scenario
from sustain_drake.station.scenario_files import with_seed
from sustain_drake.systems.optical_flow_tracker import intrinsics_from_camera_info

ROOT = Path(__file__).resolve().parents[1]
VARIANTS = ("tracker", "median depth", "plane depth")


def rod_marks_T() -> tuple[np.ndarray, np.ndarray]:
    """Every point of the rod's side faces that an image feature can be fixed on, in the tool frame T
    (M x 3, m), and their faces' outward normals (M x 3): the checker's corners (across at the
    column edges: margin, margin + cell and margin + 2 cells from one edge; along at every row
    boundary) and its cells' centres (a yellow
    cell is 6-7 x 7-9 px at 0.7-0.8 m: a blob whose centre ``cornerSubPix`` finds). The rod spans z
    in [-0.05, 0.25] (centre at z = 0.1)."""
    spec = importlib.util.spec_from_file_location("generate_assets", ROOT / "models" / "generate_assets.py")
    assets = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(assets)
    half = assets.ROD_WIDTH / 2
    rows = round(assets.ROD_LENGTH / assets.ROD_ROW)
    z0 = 0.1 - assets.ROD_LENGTH / 2
    corners = [(a, z) for a in -half + assets.ROD_MARGIN + assets.ROD_CELL * np.arange(3)
               for z in z0 + assets.ROD_ROW * np.arange(1, rows)]
    centres = [(a, z) for a in -half + assets.ROD_MARGIN + assets.ROD_CELL * (np.arange(2) + 0.5)
               for z in z0 + assets.ROD_ROW * (np.arange(rows) + 0.5)]
    out, normals = [], []
    for sign in (-1.0, 1.0):
        for a, z in corners + centres:
            out += [(sign * half, a, z), (a, sign * half, z)]
            normals += [(sign, 0.0, 0.0), (0.0, sign, 0.0)]
    return np.array(out), np.array(normals)


def run(scenario_path: Path, duration: float, refinement: RefinementParams | None = None,
        compare: RefinementParams | None = None, seed: int | None = None, criteria=None,
        parts: HandEyeParts | None = None) -> dict:
    """The loop's candidates' points over ``duration`` s: ``tracks[id]`` rows of (time, p_H with the
    true camera, rod tip, p_CP, X_WH, and ``criteria(gray, refined pixels)``'s row for the point
    when given: a K x m array of per-point figures) for the ``refinement``'s points (the tracker's
    if None), and
    ``versions[id]`` rows of (X_CH true, {variant: p_CP or None}) for the three ``VARIANTS`` (the
    refined ones with ``compare``'s other settings). The loop runs with ``parts`` (``HandEyeParts``)
    if given, else with the scenario's settings."""
    # A path, or a scenario already loaded (and changed) by the caller.
    scenario = load_scenario(scenario_path) if isinstance(scenario_path, (str, Path)) else scenario_path
    if seed is not None:
        scenario = with_seed(scenario, seed)
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(scenario))
    handle = hand_eye.add_to_diagram(builder, station, scenario, None, parts)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    root = simulator.get_context()
    period = 1.0 / scenario.camera.fps
    tracks: dict[int, list] = {}
    versions: dict[int, list] = {}
    reasons: dict[int, list] = {}
    compare = compare or RefinementParams()
    by_depth = {"median depth": dataclasses.replace(compare, depth_plane=False),
                "plane depth": dataclasses.replace(compare, depth_plane=True)}
    plant = station.GetSubsystemByName("plant")
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
        both = {}
        if station.GetOutputPort("image_time").Eval(sc)[0] == features.time:
            color = station.GetOutputPort("color_image").Eval(sc).data
            depth = station.GetOutputPort("depth_image").Eval(sc).data
            if refinement is not None:
                refined, refined_ok, refined_px = refine_points(color, depth, features.p_px, info, refinement,
                                                                return_pixels=True)
                figures = None if criteria is None else criteria(to_gray(color), refined_px)
            both = {name: refine_points(color, depth, features.p_px, info, params)
                    for name, params in by_depth.items()}
            # Why a refined point is not valid: no corner near the tracked pixel (or the window
            # leaves the image), else no clean depth there (a silhouette, a grazing face).
            pixels, pixel_ok = refine_pixels(to_gray(color), features.p_px, compare)
            depth_ok = np.isfinite(local_depth(depth, pixels, compare))
        X_CH = np.linalg.inv(X_WC) @ X_WH
        for fid in {c.feature_id for c in bank.candidates}:
            k = row.get(fid)
            if k is not None and both:
                reasons.setdefault(fid, []).append((features.time, bool(pixel_ok[k]),
                                                    bool(pixel_ok[k] and depth_ok[k])))
                points = {"tracker": features.p_CP[k].copy() if features.valid[k] else None}
                points.update({name: p[k].copy() if ok[k] else None for name, (p, ok) in both.items()})
                versions.setdefault(fid, []).append((X_CH, points))
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
            figure = None if refinement is None or criteria is None else figures[k]
            tracks.setdefault(fid, []).append((features.time, p_H, tip, p_CP.copy(), X_WH.copy(), figure))
    sc = station.GetMyContextFromRoot(root)
    X_WC = station.GetOutputPort("true_X_WC").Eval(sc).GetAsMatrix4()
    pc = plant.GetMyContextFromRoot(root)
    X_WT = plant.EvalBodyPoseInWorld(pc, plant.GetBodyByName("tool")).GetAsMatrix4()
    X_WH_now = station.GetOutputPort("X_WH").Eval(sc).GetAsMatrix4()
    return {"tracks": tracks, "candidates": seen_candidates, "X_WC": X_WC, "versions": versions,
            "reasons": reasons, "compare": compare,
            "X_HT": np.linalg.inv(X_WH_now) @ X_WT,
            "bank": handle.candidates.bank(handle.candidates.GetMyContextFromRoot(root))}


def errors_against_true_marks(out: dict, max_snap: float = 0.0045) -> dict:
    """Per candidate whose true-camera ``p_H`` (median over its frames) lies within ``max_snap`` (half
    the 9 mm between a cell's centre and its edge) of a checker mark (``rod_marks_T``), and per
    variant: every sample's error against that mark, split along the camera ray and across it:
    ``{"errors": {variant: {id: (along (n,), across (n,), incidence (n,))}}, "snaps": {id: distance}}``
    (incidence: the angle between the camera ray and the mark's face normal, rad)."""
    marks, normals = rod_marks_T()
    marks_H = (out["X_HT"] @ np.c_[marks, np.ones(len(marks))].T).T[:, :3]
    normals_H = normals @ out["X_HT"][:3, :3].T
    result = {v: {} for v in VARIANTS}
    snaps = {}
    for fid, rows in out["tracks"].items():
        median = np.median(np.array([r[1] for r in rows]), axis=0)
        d = np.linalg.norm(marks_H - median, axis=1)
        snaps[fid] = float(d.min())
        if d.min() > max_snap or fid not in out["versions"]:
            continue
        corner, normal = marks_H[int(np.argmin(d))], normals_H[int(np.argmin(d))]
        for variant in VARIANTS:
            along, across, incidence = [], [], []
            for X_CH, points in out["versions"][fid]:
                p = points[variant]
                if p is None:
                    continue
                truth = X_CH[:3, :3] @ corner + X_CH[:3, 3]
                ray = truth / np.linalg.norm(truth)
                e = p - truth
                along.append(float(e @ ray))
                across.append(float(np.linalg.norm(e - (e @ ray) * ray)))
                incidence.append(math.acos(min(1.0, abs(float(ray @ (X_CH[:3, :3] @ normal))))))
            if along:
                result[variant][fid] = (np.array(along), np.array(across), np.array(incidence))
    return {"errors": result, "snaps": snaps}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", type=Path, default=ROOT / "diagrams" / "hand_eye.yaml")
    parser.add_argument("--duration", type=float, default=30.0)
    parser.add_argument("--seed", type=int, help="as sustain-drake simulate --seed (default: the scenario's)")
    parser.add_argument("--refine", action="store_true",
                        help="map the refined points (hand_eye.refinement) instead of the tracker's")
    args = parser.parse_args()
    scenario_refinement = hand_eye_parts(load_scenario(args.scenario).hand_eye).refinement
    refinement = scenario_refinement if args.refine else None
    out = run(args.scenario, args.duration, refinement, scenario_refinement, args.seed)
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
    # Why the candidates' refined points are missing, and how their tracks end (the tracker's id
    # gone: lost by Lucas-Kanade or its checks; a candidate's samples also stop when it is dropped).
    frames = [r for rows in out["reasons"].values() for r in rows]
    if frames:
        no_corner = sum(not r[1] for r in frames) / len(frames)
        no_depth = sum(r[1] and not r[2] for r in frames) / len(frames)
        print(f"\nRefined points of the candidates' tracked frames ({len(frames)}): no corner/blob within "
              f"{out['compare'].max_shift_px:g} px {100 * no_corner:.1f} %, no clean depth "
              f"{100 * no_depth:.1f} %")
    truth = errors_against_true_marks(out)
    far = {fid: d for fid, d in truth["snaps"].items() if d > 0.0045}
    print(f"\nErrors against the true checker mark (mm; {len(truth['snaps']) - len(far)} of "
          f"{len(truth['snaps'])} candidates within 4.5 mm of a corner or cell centre; the others, at "
          f"{', '.join(f'{1e3 * d:.0f}' for d in sorted(far.values()))} mm, left out)")
    print(f"{'id':>6} " + " ".join(f"{v + ' along mean/rms, across rms':>40}" for v in VARIANTS))
    ids = sorted(set().union(*[set(truth["errors"][v]) for v in VARIANTS]))
    for fid in ids:
        cells = []
        for v in VARIANTS:
            if fid in truth["errors"][v]:
                along, across, _ = truth["errors"][v][fid]
                rms = 1e3 * np.sqrt(np.mean(along**2))
                cells.append(f"{len(along):5d} {1e3 * along.mean():7.2f} {rms:6.2f} "
                             f"{1e3 * np.sqrt(np.mean(across**2)):6.2f}".rjust(40))
            else:
                cells.append("-".rjust(40))
        print(f"{fid:6d} " + " ".join(cells))
    for v in VARIANTS:
        pooled = [truth["errors"][v][fid] for fid in ids if fid in truth["errors"][v]]
        if pooled:
            along = np.concatenate([p[0] for p in pooled])
            across = np.concatenate([p[1] for p in pooled])
            print(f"{v:>14}: {along.size} samples, along the ray mean {1e3 * along.mean():.2f} mm, "
                  f"RMS {1e3 * np.sqrt(np.mean(along**2)):.2f} mm; across RMS "
                  f"{1e3 * np.sqrt(np.mean(across**2)):.2f} mm")
            incidence = np.degrees(np.concatenate([p[2] for p in pooled]))
            for lo, hi in ((0, 30), (30, 45), (45, 60), (60, 75), (75, 90)):
                m = (incidence >= lo) & (incidence < hi)
                if m.any():
                    print(f"{'':>16}face seen at {lo:2d}-{hi:2d} deg: {m.sum():5d} samples, along mean "
                          f"{1e3 * along[m].mean():6.2f} RMS {1e3 * np.sqrt(np.mean(along[m]**2)):5.2f} mm, "
                          f"across RMS {1e3 * np.sqrt(np.mean(across[m]**2)):5.2f} mm")


if __name__ == "__main__":
    main()
