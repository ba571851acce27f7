"""Synthetic eye-to-hand data with a known answer, for the identification tests and benchmarks."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from sustain_drake.identification import EyeToHandIdentifier


@dataclass
class EyeToHandTruth:
    X_WC: np.ndarray
    p_HP: np.ndarray


def make_truth(seed: int = 0) -> EyeToHandTruth:
    rng = np.random.default_rng(seed)
    X_WC = np.eye(4)
    X_WC[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    X_WC[:3, 3] = rng.uniform(-1.0, 1.0, 3) + [0.0, 0.0, 1.0]
    p_HP = rng.uniform(-0.15, 0.15, 3)
    return EyeToHandTruth(X_WC, p_HP)


def make_samples(
    truth: EyeToHandTruth, n: int, noise_m: float = 0.0, seed: int = 1, rotate: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` hand poses spread over a 0.6 m cube and all orientations (or one fixed orientation if
    ``rotate`` is False: pure translation), and the point seen by the camera with Gaussian noise of
    ``noise_m`` metres per axis."""
    rng = np.random.default_rng(seed)
    X_WH = np.tile(np.eye(4), (n, 1, 1))
    if rotate:
        X_WH[:, :3, :3] = Rotation.random(n, random_state=rng).as_matrix()
    else:
        X_WH[:, :3, :3] = Rotation.random(random_state=rng).as_matrix()
    X_WH[:, :3, 3] = rng.uniform(-0.3, 0.3, (n, 3)) + [0.4, 0.0, 0.3]
    p_W = np.einsum("nij,j->ni", X_WH[:, :3, :3], truth.p_HP) + X_WH[:, :3, 3]
    R_WC, p_WC = truth.X_WC[:3, :3], truth.X_WC[:3, 3]
    p_C = (p_W - p_WC) @ R_WC + rng.normal(0.0, noise_m, (n, 3))
    return p_C, X_WH


def rotation_error_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    return float(Rotation.from_matrix(R_a.T @ R_b).magnitude() * 180.0 / np.pi)


def make_points(truth: EyeToHandTruth, p_HP: np.ndarray, n: int, noise_m=0.0, missing: float = 0.0,
                seed: int = 1, rotate: bool = True) -> tuple[dict, np.ndarray]:  # fmt: skip
    """Several points fixed on the hand (``p_HP``: K x 3) seen by one camera over ``n`` hand poses
    (``make_samples``'s): ``({label "p<k>": (samples, p_C)}, X_WH)``, each point missing from a
    sample with probability ``missing`` and measured with Gaussian noise ``noise_m`` (m per axis; a
    number, or one per point)."""
    rng = np.random.default_rng(seed)
    _, X_WH = make_samples(truth, n, seed=seed, rotate=rotate)
    noise = np.broadcast_to(np.asarray(noise_m, dtype=float), (len(p_HP),))
    R_WC, p_WC = truth.X_WC[:3, :3], truth.X_WC[:3, 3]
    points = {}
    for k, (p, sigma) in enumerate(zip(p_HP, noise, strict=True)):
        samples = np.flatnonzero(rng.random(n) >= missing)
        p_W = np.einsum("nij,j->ni", X_WH[samples, :3, :3], p) + X_WH[samples, :3, 3]
        points[f"p{k}"] = (samples, (p_W - p_WC) @ R_WC + rng.normal(0.0, sigma, (len(samples), 3)))
    return points, X_WH


def point_identifiers(points: dict, X_WH: np.ndarray) -> list:
    """One ``EyeToHandIdentifier`` per point of ``make_points``'s ``points``, each fed that point's
    samples (in the labels' order)."""
    identifiers = []
    for samples, p_C in points.values():
        identifier = EyeToHandIdentifier()
        for c, X in zip(p_C, X_WH[samples], strict=True):
            identifier.add(c, X[:3, :3], X[:3, 3])
        identifiers.append(identifier)
    return identifiers
