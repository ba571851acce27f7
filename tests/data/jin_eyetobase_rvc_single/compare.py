"""Each point of the Jin et al. data set alone against the three jointly: the table of
docs/results.md ("Offline calibration on real data"). Run from the repository root::

    .venv/bin/python tests/data/jin_eyetobase_rvc_single/compare.py

Rows: the camera of each point's own fit, the joint fit (``calibrate_eye_to_hand_points``, each
point weighted by its noise) and, for comparison, the joint fit unweighted (``refine_joint`` from
the same start). Columns: the camera position, its 1 sd, its offset from the joint camera, and the
RMS residual of every point under that camera (each with its best ``p_HP`` there,
``points_given_camera``); then the cameras' offsets from one another.
"""

import itertools
import math
from pathlib import Path

import numpy as np

from sustain_drake.identification import EyeToHandIdentifier, calibrate_eye_to_hand_points
from sustain_drake.identification import eye_to_hand_points as joint
from sustain_drake.identification.rotation import rotation_angle
from sustain_drake.recorded_data import read_point_tracks_csv, read_poses_csv

HERE = Path(__file__).resolve().parent


def statistic(samples, p_C, X_WH) -> np.ndarray:
    identifier = EyeToHandIdentifier()
    for c, X in zip(p_C, X_WH[samples], strict=True):
        identifier.add(c, X[:3, :3], X[:3, 3])
    return identifier.core.S.copy()


def pose(R, p) -> np.ndarray:
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, p
    return X


def rms_under(S_list, X_WC) -> list[float]:
    """Every point's RMS residual (mm) under the camera ``X_WC``, each with its best ``p_HP``."""
    P = joint.points_given_camera(S_list, X_WC[:3, :3], X_WC[:3, 3])
    out = []
    for S, p in zip(S_list, P, strict=True):
        x = np.concatenate([X_WC[:3, :3].reshape(9, order="F"), X_WC[:3, 3], p, [1.0]])
        out.append(1e3 * math.sqrt(max(float(x @ S @ x), 0.0) / S[9, 9]))
    return out


def offset(X_a, X_b) -> str:
    return (f"{1e3 * np.linalg.norm(X_a[:3, 3] - X_b[:3, 3]):.2f} mm, "
            f"{math.degrees(rotation_angle(X_a[:3, :3].T @ X_b[:3, :3])):.3f} deg")  # fmt: skip


def main():
    X_WH = read_poses_csv(HERE / "poses.csv")
    tracks = read_point_tracks_csv(HERE / "all_points.csv", num_samples=len(X_WH)).points
    result = calibrate_eye_to_hand_points(tracks, X_WH)
    S_list = [statistic(s, p, X_WH) for s, p in tracks.values()]
    start = result.single[result.seed].refined
    R, p_WC, _ = joint.refine_joint(S_list, start.R_WC, start.p_WC,
                                    joint.points_given_camera(S_list, start.R_WC, start.p_WC))  # fmt: skip
    rows = [(f"{label} alone", r.X_WC, r.standard_errors[:2])
            for label, r in zip(result.labels, result.single, strict=True)]
    rows += [("all three jointly", result.X_WC, result.standard_errors[:2]),
             ("all three jointly, unweighted", pose(R, p_WC), None)]  # fmt: skip
    print(f"verdict: {result.verdict}; weights {', '.join(f'{w:.3g}' for w in result.weights)}")
    print("| camera from | position (mm) | 1 sd: position, rotation | from the joint camera "
          "| RMS under it, mm: " + " / ".join(result.labels) + " |")
    print("|---|---|---|---|---|")
    for name, X, sd in rows:
        position = "(" + ", ".join(f"{1e3 * v:.1f}" for v in X[:3, 3]) + ")"
        spread = f"{1e3 * sd[1]:.2f} mm, {math.degrees(sd[0]):.3f} deg" if sd else ""
        print(f"| {name} | {position} | {spread} | {offset(X, result.X_WC)} | "
              + " / ".join(f"{v:.3f}" for v in rms_under(S_list, X)) + " |")
    for (a, X_a, _), (b, X_b, _) in itertools.combinations(rows[:3], 2):
        print(f"{a} to {b}: {offset(X_a, X_b)}")
    alone = [r.standard_errors[2] for r in result.single]
    print("p_HP 1 sd, mm, alone: " + " / ".join(f"{1e3 * v:.2f}" for v in alone) + "; jointly: "
          + " / ".join(f"{1e3 * v:.2f}" for v in result.standard_errors[2]))


if __name__ == "__main__":
    main()
