"""Which refined points stay fixed on the hand, by the refiner's point criteria, on scene-matrix
tuning cells (issue 27, item 4; never the held-out set).

Runs the hand-eye loop of each cell with its refiner's point test off, and for every candidate's
refined point each frame records the criteria (``central_symmetry``, ``view_shift``) and the point
mapped into the hand frame with the TRUE camera (``bench_hand_eye_candidates.run``). A point fixed
on the hand gives the same ``p_H`` every frame; its wander (the distance from its track's median)
is what a criterion should predict. Prints, per cell and per criterion threshold, the candidates'
samples kept and their wander (RMS and 90 %, mm).

    .venv/bin/python bench/bench_point_criteria.py --cells 9 15 17 --duration 25
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_hand_eye_candidates import run  # noqa: E402
from make_scene_matrix import SWEEPS  # noqa: E402

from sustain_drake.loops.hand_eye import hand_eye_parts  # noqa: E402
from sustain_drake.loops.pixel_scale import pixel_scale, scaled  # noqa: E402
from sustain_drake.perception.point_refinement import central_symmetry, view_shift  # noqa: E402
from sustain_drake.station import camera_info  # noqa: E402
from sustain_drake.station.scenario_files import load_scenario_string  # noqa: E402
from sustain_drake.sweeps import load_sweep  # noqa: E402

CRITERIA = {"symmetry >= 0.5": (0, lambda v: v >= 0.5),
            **{f"view shift <= {t:g} px": (1, lambda v, t=t: v <= t) for t in (0.25, 0.5, 1.0)},
            "all": (0, lambda v: np.ones_like(v, bool))}


def cell_samples(scenario, duration: float):
    """``(figures (n x 2), wander (n,) m, drift (n,) m)`` of every candidate sample of a run of
    ``scenario``: the sample's distance from its track's median ``p_H``, and that of the median of
    the track's samples in the same second (the view-dependent part; the depth noise averages out)."""
    scale = pixel_scale(camera_info(scenario))
    parts = hand_eye_parts(scenario.hand_eye)
    base = dataclasses.replace(parts.refinement, symmetry_window_px=0)
    refinement = scaled(base, scale, lengths=("max_shift_px",),
                        windows=("corner_window_px", "depth_window_px"))
    sym_half, corner_half = max(1, round(3 * scale)), refinement.corner_window_px
    parts = dataclasses.replace(parts, refinement=base)

    def criteria(gray, p_px):
        return np.c_[central_symmetry(gray, p_px, sym_half), view_shift(gray, p_px, corner_half)]

    out = run(scenario, duration, refinement, refinement, criteria=criteria, parts=parts)
    figures, wander, drift = [], [], []
    for rows in out["tracks"].values():
        p_H, t = np.array([r[1] for r in rows]), np.array([r[0] for r in rows])
        median = np.median(p_H, axis=0)
        wander.append(np.linalg.norm(p_H - median, axis=1))
        second = np.floor(t).astype(int)
        by_second = {s: np.median(p_H[second == s], axis=0) for s in np.unique(second)}
        drift.append(np.array([np.linalg.norm(by_second[s] - median) for s in second]))
        figures.append(np.array([r[5] for r in rows]))
    if not figures:
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0)
    return np.concatenate(figures), np.concatenate(wander), np.concatenate(drift)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cells", type=int, nargs="+", required=True)
    p.add_argument("--duration", type=float, default=25.0)
    args = p.parse_args()
    sweep = load_sweep(SWEEPS / "scene_matrix_tuning.yaml")
    for index in args.cells:
        figures, wander, drift = cell_samples(load_scenario_string(sweep.cells[index].scenario_text),
                                              args.duration)
        print(f"cell {index}: {wander.size} candidate samples", flush=True)
        for name, (column, keep) in CRITERIA.items():
            kept = keep(figures[:, column]) if wander.size else np.zeros(0, bool)
            figure = " ".join(f"{what} RMS {1e3 * np.sqrt(np.mean(v[kept]**2)):5.2f} mm, 90 % "
                              f"{1e3 * np.percentile(v[kept], 90):5.2f} mm" if kept.any() else f"{what} -"
                              for what, v in (("wander", wander), ("per-second drift", drift)))
            print(f"  {name:>22}: {kept.sum():6d} kept, {figure}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
