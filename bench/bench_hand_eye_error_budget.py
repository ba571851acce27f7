"""Where the hand-eye camera error comes from: the measured points against the motion that probes them.

Runs the hand-eye loop from images (``bench_hand_eye_candidates.run``: the candidates' refined points
and hand poses, every frame) and, for every track of a point on the rod, compares the camera that
Eq. (30) gives from

- the MEASURED samples ``p_CP``;
- the TRUE positions of the same point (its median ``p_H`` under the true camera, mapped through
  each frame's hand pose) plus independent noise of ``--noise-along`` m along the ray and
  ``--noise-across`` m across it (a depth camera's error if it were white): what the motion allows;
- the true positions plus only the measured error's component along the ray, or only across it
  (which of the two limits the camera).

Each single track is solved with the paper's identifier, and all tracks together with one camera
(``eye_to_hand.refine_joint``, started at the true camera). A track is split where its refined point
was missing for more than ``--max-gap`` s: a track that comes back after a stretch without a clean
point (the face turned away) can be on another surface (seen: a 25 mm jump along the ray, from
one face of the rod onto its neighbour). Also printed: each track's spread in the camera frame
(std, mm) and the hand origin's, in 15 s windows: a camera rotation error of d rad that the points
can absorb with a shift of the camera is only seen through the points' spread, so a correlated
error e (m) costs about e / spread (rad).

    .venv/bin/python bench/bench_hand_eye_error_budget.py [--scenario S] [--duration 30] [--seed N]
        [--resolution 640 480]

Writes the figures to ``out/bench_hand_eye_error_budget/<scenario>.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from bench_hand_eye_candidates import run  # noqa: E402  (bench/bench_hand_eye_candidates.py)

from sustain_drake.files import write_atomically  # noqa: E402
from sustain_drake.identification.eye_to_hand import EyeToHandIdentifier  # noqa: E402
from sustain_drake.identification.eye_to_hand_points import refine_joint  # noqa: E402
from sustain_drake.identification.rotation import rotation_angle  # noqa: E402
from sustain_drake.loops.hand_eye import hand_eye_parts  # noqa: E402
from sustain_drake.station import load_scenario  # noqa: E402

MIN_SAMPLES = 100  # a track shorter than this is left out (the loop's observe_min_samples)
ROD_HALF_WIDTH, ROD_Z = 0.03, (-0.06, 0.26)  # m, a box around the rod in its tool frame T


def split_at_gaps(tracks: dict, max_gap: float) -> dict:
    """Tracks ``{id: rows}`` (rows start with the time) cut where two samples are more than
    ``max_gap`` s apart: ``{(id, k): rows}``."""
    out = {}
    for fid, rows in tracks.items():
        k, start = 0, 0
        for i in range(1, len(rows) + 1):
            if i == len(rows) or rows[i][0] - rows[i - 1][0] > max_gap:
                out[(fid, k)] = rows[start:i]
                k, start = k + 1, i
    return out


def identifier(P: np.ndarray, X: np.ndarray) -> EyeToHandIdentifier:
    """The paper's identifier fed points ``P`` (n x 3) at hand poses ``X`` (n x 4 x 4)."""
    ident = EyeToHandIdentifier()
    for p, x in zip(P, X, strict=True):
        ident.add_pose(p, x)
    return ident


def camera_error(R: np.ndarray, p: np.ndarray, X_WC: np.ndarray) -> tuple[float, float]:
    """(mm, deg) of an estimated camera against the true one."""
    return (1e3 * float(np.linalg.norm(p - X_WC[:3, 3])),
            math.degrees(rotation_angle(R.T @ X_WC[:3, :3])))


def single_track(ident: EyeToHandIdentifier, X_WC: np.ndarray):
    """The camera error of one track's own solution (mm, deg), or None without an estimate."""
    estimate = ident.solve().estimate
    return None if estimate is None else camera_error(estimate.R_WC, estimate.p_WC, X_WC)


def budget(out: dict, max_gap: float, noise_along: float, noise_across: float, seed: int = 0) -> dict:
    """The error budget of a run's tracks (see the module docstring)."""
    rng = np.random.default_rng(seed)
    X_WC = out["X_WC"]
    X_CW, X_TH = np.linalg.inv(X_WC), np.linalg.inv(out["X_HT"])
    versions = {"measured": [], "along only": [], "across only": [], "white noise": []}
    rows_out, starts = [], []
    for key, rows in sorted(split_at_gaps(out["tracks"], max_gap).items()):
        if len(rows) < MIN_SAMPLES:
            continue
        p_H = np.array([r[1] for r in rows])
        P = np.array([r[3] for r in rows])
        X = np.array([r[4] for r in rows])
        median = np.median(p_H, axis=0)
        p_T = X_TH[:3, :3] @ median + X_TH[:3, 3]
        if np.abs(p_T[:2]).max() > ROD_HALF_WIDTH or not ROD_Z[0] < p_T[2] < ROD_Z[1]:
            continue  # not a point of the rod (the gripper's, the arm's)
        truth = np.einsum("ij,njk,k->ni", X_CW[:3], X, np.r_[median, 1.0])
        ray = truth / np.linalg.norm(truth, axis=1)[:, None]
        error = P - truth
        along = np.einsum("ni,ni->n", error, ray)
        across = error - along[:, None] * ray
        white = (truth + ray * rng.normal(0.0, noise_along, (len(P), 1))
                 + rng.normal(0.0, noise_across, P.shape))
        samples = {"measured": P, "along only": truth + along[:, None] * ray,
                   "across only": truth + across, "white noise": white}
        identifiers = {name: identifier(Q, X) for name, Q in samples.items()}
        for name, ident in identifiers.items():
            versions[name].append(ident.core.S)
        starts.append(median)
        measured = single_track(identifiers["measured"], X_WC)
        ideal = single_track(identifiers["white noise"], X_WC)
        rows_out.append({
            "track": f"{key[0]}.{key[1]}", "samples": len(rows), "t": [rows[0][0], rows[-1][0]],
            "p_T_mm": (1e3 * p_T).round(1).tolist(),
            "along_mean_mm": 1e3 * float(along.mean()),
            "along_rms_mm": 1e3 * float(np.sqrt(np.mean(along**2))),
            "across_rms_mm": 1e3 * float(np.sqrt(np.mean(np.sum(across**2, axis=1)))),
            "spread_in_C_mm": (1e3 * P.std(axis=0)).round(1).tolist(),
            "camera_measured": measured, "camera_white_noise": ideal})
    joint = {}
    for name, S in versions.items():
        if S:
            solved = refine_joint(S, X_WC[:3, :3], X_WC[:3, 3], np.array(starts))
            joint[name] = None if solved is None else camera_error(solved[0], solved[1], X_WC)
    poses = {round(r[0], 4): r[4] for rows in out["tracks"].values() for r in rows}
    times = np.array(sorted(poses))
    hand = np.array([(X_CW @ poses[t])[:3, 3] for t in times]) if len(times) else np.zeros((0, 3))
    windows = []
    for lo in np.arange(0.0, times.max() if len(times) else 0.0, 15.0):
        m = (times >= lo) & (times < lo + 15.0)
        if m.sum() > 1:
            windows.append({"from_s": float(lo), "to_s": float(lo + 15.0),
                            "hand_std_in_C_mm": (1e3 * hand[m].std(axis=0)).round(1).tolist()})
    return {"tracks": rows_out, "joint": joint, "hand_spread": windows,
            "noise": {"along_m": noise_along, "across_m": noise_across}, "max_gap_s": max_gap}


def report(b: dict) -> None:
    def cam(c):
        return "      -      " if c is None else f"{c[0]:7.1f} {c[1]:5.2f}"
    print(f"{'track':>8} {'n':>5} {'t0':>5} {'t1':>5}  along mean/rms  across  spread in C (mm)       "
          f"camera: measured  white noise (mm, deg)")
    for r in b["tracks"]:
        s = r["spread_in_C_mm"]
        print(f"{r['track']:>8} {r['samples']:5d} {r['t'][0]:5.1f} {r['t'][1]:5.1f}  "
              f"{r['along_mean_mm']:6.2f} {r['along_rms_mm']:5.2f}   {r['across_rms_mm']:5.2f}  "
              f"[{s[0]:5.1f} {s[1]:5.1f} {s[2]:5.1f}]"
              f"      {cam(r['camera_measured'])}   {cam(r['camera_white_noise'])}")
    n = b["noise"]
    print(f"\nAll tracks, one camera (from the true camera; white noise: {1e3 * n['along_m']:.1f} mm along "
          f"the ray, {1e3 * n['across_m']:.1f} mm across):")
    for name, c in b["joint"].items():
        print(f"  {name:>12}: {cam(c)}")
    print("\nHand origin in the camera frame, std (mm):")
    for w in b["hand_spread"]:
        print(f"  {w['from_s']:5.0f}-{w['to_s']:3.0f} s: {w['hand_std_in_C_mm']}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", type=Path, default=ROOT / "diagrams" / "hand_eye.yaml")
    parser.add_argument("--duration", type=float, default=30.0)
    parser.add_argument("--seed", type=int, help="as sustain-drake simulate --seed (default: the scenario's)")
    parser.add_argument("--max-gap", type=float, default=0.1, help="s without a point that splits a track")
    parser.add_argument("--noise-along", type=float, default=0.0015, help="m, white noise along the ray")
    parser.add_argument("--noise-across", type=float, default=0.0005, help="m, white noise across the ray")
    parser.add_argument("--resolution", type=int, nargs=2, metavar=("WIDTH", "HEIGHT"),
                        help="px, instead of the scenario's camera size")
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "bench_hand_eye_error_budget")
    args = parser.parse_args()
    scenario = load_scenario(args.scenario)
    name = args.scenario.stem
    if args.resolution:
        scenario.camera.width, scenario.camera.height = args.resolution
        name += f"_{args.resolution[0]}x{args.resolution[1]}"
    refinement = hand_eye_parts(scenario.hand_eye).refinement
    out = run(scenario, args.duration, refinement, refinement, args.seed)
    b = budget(out, args.max_gap, args.noise_along, args.noise_across)
    report(b)
    b.update(scenario=str(args.scenario), resolution=[scenario.camera.width, scenario.camera.height],
             duration_s=args.duration, seed=args.seed)
    path = args.out / f"{name}{'' if args.seed is None else f'_seed{args.seed}'}.json"
    write_atomically(path, json.dumps(b, indent=1))
    print(f"\nwritten: {path}")


if __name__ == "__main__":
    main()
