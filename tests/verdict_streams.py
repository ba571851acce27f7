"""Random sample streams with a known truth for the verdict tests and bench (issue 25): eye-to-hand
and payload streams that are well excited, degenerate (the motion cannot determine the unknowns),
or in the wrong units or frame. Each stream is a function of its seed and kind."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from sustain_drake.identification import EyeToHandIdentifier, PayloadIdentifier, observability
from sustain_drake.identification.payload import STANDARD_GRAVITY_W

# "excited": turns about every axis; "weak": wide turns about one axis, small ones (0.003 to 0.3 rad)
# about the others.
EYE_DEGENERATE = ("pure_translation", "single_axis", "repeated", "two_poses")
EYE_UNITS_AND_FRAMES = ("hand_mm", "points_mm", "both_mm", "left_handed", "negated")
PAYLOAD_DEGENERATE = ("one_orientation", "about_gravity", "repeated")


@dataclass
class EyeStream:
    p_C: np.ndarray  # (n, 3) the point in the camera frame
    X_WH: np.ndarray  # (n, 4, 4) hand poses
    X_WC: np.ndarray  # the true camera
    p_HP: np.ndarray  # the true point in the hand
    noise: float  # m per axis on p_C


@dataclass
class PayloadStream:
    wrench: np.ndarray  # (n, 6) [tau; f] in K
    R_WK: np.ndarray  # (n, 3, 3)
    mass: float
    p_KCm: np.ndarray
    force_noise: float  # N per axis
    torque_noise: float  # N m per axis


def _noise(rng, largest: float) -> float:
    """None a fifth of the time, else log-uniform up to ``largest``."""
    return 0.0 if rng.random() < 0.2 else float(largest * 10.0 ** rng.uniform(-3.0, 0.0))


def _rotations(rng, kind: str, n: int) -> np.ndarray:
    R0 = Rotation.random(random_state=rng)
    if kind in ("pure_translation", "one_orientation", "repeated"):
        return np.tile(R0.as_matrix(), (n, 1, 1))
    if kind in ("single_axis", "about_gravity"):
        axis = (0.0, 0.0, 1.0) if kind == "about_gravity" else _random_axis(rng)
        angles = rng.uniform(-1.0, 1.0, n) * rng.uniform(0.1, np.pi)
        return (Rotation.from_rotvec(np.outer(angles, axis)) * R0).as_matrix()
    if kind == "weak":  # wide turns about one axis (vertical half the time), small ones about the others
        axis = (0.0, 0.0, 1.0) if rng.random() < 0.5 else _random_axis(rng)
        wobble = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-2.5, -0.5)
        return (Rotation.from_rotvec(np.outer(rng.uniform(-np.pi, np.pi, n), axis) + wobble) * R0).as_matrix()
    if kind == "two_poses":
        pair = np.stack([R0.as_matrix(), Rotation.random(random_state=rng).as_matrix()])
        return pair[_two_pose_choice(rng, n)]
    # Well excited: turns about every axis, up to a random amplitude of 0.5 rad to pi.
    turns = Rotation.from_rotvec(rng.normal(size=(n, 3)) * rng.uniform(0.5, np.pi) / np.sqrt(3.0))
    return (turns * R0).as_matrix()


def _random_axis(rng) -> np.ndarray:
    return Rotation.random(random_state=rng).apply([0.0, 0.0, 1.0])


def _two_pose_choice(rng, n: int) -> np.ndarray:
    choice = rng.integers(0, 2, n)
    choice[:2] = (0, 1)
    return choice


def eye_stream(seed: int, kind: str = "excited", n: int | None = None,
               noise: float | None = None) -> EyeStream:  # fmt: skip
    """A stream of ``kind`` (``"excited"``, ``"weak"``, one of ``EYE_DEGENERATE`` or
    ``EYE_UNITS_AND_FRAMES``)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(10, 300)) if n is None else n
    noise = _noise(rng, 2e-3) if noise is None else noise
    X_WC = np.eye(4)
    X_WC[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    X_WC[:3, 3] = rng.uniform(-1.0, 1.0, 3) + [0.4, 0.0, 1.5]
    p_HP = rng.uniform(-0.2, 0.2, 3)
    X_WH = np.tile(np.eye(4), (n, 1, 1))
    X_WH[:, :3, :3] = _rotations(rng, kind, n)
    X_WH[:, :3, 3] = rng.uniform(-1.0, 1.0, (n, 3)) * rng.uniform(0.02, 0.3) + [0.4, 0.0, 0.3]
    if kind == "repeated":
        X_WH[:] = X_WH[0]
    elif kind == "two_poses":
        X_WH[:] = X_WH[:2][_two_pose_choice(rng, n)]
    p_W = np.einsum("nij,j->ni", X_WH[:, :3, :3], p_HP) + X_WH[:, :3, 3]
    p_C = (p_W - X_WC[:3, 3]) @ X_WC[:3, :3] + rng.normal(0.0, noise, (n, 3))
    if kind in ("hand_mm", "both_mm"):
        X_WH[:, :3, 3] *= 1000.0
    if kind in ("points_mm", "both_mm"):
        p_C = p_C * 1000.0
    if kind == "left_handed":
        p_C[:, rng.integers(0, 3)] *= -1.0
    if kind == "negated":
        p_C = -p_C
    return EyeStream(p_C, X_WH, X_WC, p_HP, noise)


def payload_stream(seed: int, kind: str = "excited", n: int | None = None,
                   noise: tuple[float, float] | None = None) -> PayloadStream:  # fmt: skip
    """A payload stream of ``kind`` (``"excited"``, ``"weak"`` or one of ``PAYLOAD_DEGENERATE``), at rest,
    with ``noise = (force N, torque N m)`` per axis (random if None)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(10, 300)) if n is None else n
    mass, p_KCm = float(rng.uniform(0.2, 5.0)), rng.uniform(-0.15, 0.15, 3)
    force_noise, torque_noise = (_noise(rng, 0.05), _noise(rng, 1e-3)) if noise is None else noise
    R_WK = _rotations(rng, kind, n)
    f_K = np.einsum("nji,j->ni", R_WK, -mass * STANDARD_GRAVITY_W)
    tau_K = np.cross(p_KCm, f_K) + rng.normal(0.0, torque_noise, (n, 3))
    f_K = f_K + rng.normal(0.0, force_noise, (n, 3))
    return PayloadStream(np.hstack([tau_K, f_K]), R_WK, mass, p_KCm, force_noise, torque_noise)


def checkpoints(n: int, count: int = 4) -> list[int]:
    """Sample counts (1-based, distinct, the last ``n``) at which a streaming identifier is solved."""
    return sorted({max(1, round(n * k / count)) for k in range(1, count + 1)})


def stream_eye(stream: EyeStream, refine: bool = False):
    """Feeds the stream sample by sample into an ``EyeToHandIdentifier``; yields its solution at
    every checkpoint."""
    identifier = EyeToHandIdentifier()
    marks = set(checkpoints(len(stream.p_C)))
    for i, (c, X) in enumerate(zip(stream.p_C, stream.X_WH, strict=True), start=1):
        identifier.add(c, X[:3, :3], X[:3, 3])
        if i in marks:
            yield identifier.solve(refine_estimate=refine)


def stream_payload(stream: PayloadStream):
    """``stream_eye`` for a payload stream and a ``PayloadIdentifier``."""
    identifier = PayloadIdentifier()
    marks = set(checkpoints(len(stream.wrench)))
    for i, (w, R) in enumerate(zip(stream.wrench, stream.R_WK, strict=True), start=1):
        identifier.add(w, R)
        if i in marks:
            yield identifier.solve()


# An estimate is "within the noise" when each error is at most this many standard deviations that
# the stream's true noise and excitation give (Gauss-Newton's covariance at the truth), plus a
# round-off floor for noise-free streams.
SD_FACTOR = 6.0
FLOOR = 1e-6  # m, rad, kg


def eye_within_noise(stream: EyeStream, X_WC: np.ndarray, p_HP: np.ndarray,
                     count: int | None = None) -> bool:  # fmt: skip
    """Whether the camera and the point identified from the first ``count`` samples (all: None) are
    within ``SD_FACTOR`` sd of the truth (3-D errors)."""
    identifier = EyeToHandIdentifier()
    for c, X in zip(stream.p_C[:count], stream.X_WH[:count], strict=True):
        identifier.add(c, X[:3, :3], X[:3, 3])
    sd = observability.eye_to_hand_standard_errors(identifier.core.S, stream.X_WC[:3, :3], stream.noise**2)
    if sd is None:
        return False
    turn = Rotation.from_matrix(stream.X_WC[:3, :3].T @ X_WC[:3, :3]).magnitude()
    errors = (turn, np.linalg.norm(X_WC[:3, 3] - stream.X_WC[:3, 3]), np.linalg.norm(p_HP - stream.p_HP))
    return all(e <= SD_FACTOR * s + FLOOR for e, s in zip(errors, sd, strict=True))


def payload_within_noise(stream: PayloadStream, mass: float, p_KCm: np.ndarray,
                         count: int | None = None) -> bool:  # fmt: skip
    """Whether the mass and the centre of mass identified from the first ``count`` samples (all:
    None) are within ``SD_FACTOR`` sd of the truth: the centre of mass's from the torque rows (torque
    noise and the force noise's lever ``|p_KCm|``), the mass's from the force rows."""
    f = np.einsum("nji,j->ni", stream.R_WK[:count], -stream.mass * STANDARD_GRAVITY_W)
    S_pp = np.einsum("ni,nj->ij", f, f)
    S_pp = np.trace(S_pp) * np.eye(3) - S_pp  # sum [f x]^T [f x]
    sigma2 = stream.torque_noise**2 + (np.linalg.norm(stream.p_KCm) * stream.force_noise) ** 2
    sd_p = np.sqrt(sigma2 * np.trace(np.linalg.inv(S_pp)))
    sd_m = stream.mass * stream.force_noise / (stream.mass * 9.81 * np.sqrt(len(f)))
    return bool(np.linalg.norm(p_KCm - stream.p_KCm) <= SD_FACTOR * sd_p + FLOOR
                and abs(mass - stream.mass) <= SD_FACTOR * sd_m + FLOOR)
