"""The camera after it turned (beyond the paper; pure numpy): from the static scene's anchors across a
camera move (``perception.camera_motion.SceneTurn``) the turn, robust to anchors on moving things
(a least-median start), with the shift from the scene's depth or from the held tool's known
points (``camera_after_turn``), and the turn's own uncertainty (``CameraAfterTurn.rotation_sd``).

Every public function raises ``IdentificationError`` with a one-line message for a bad argument.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from sustain_drake.identification.errors import (
    F64,
    MATRIX3,
    VECTOR3,
    IdentificationError,
    check_finite,
    describe,
    integer,
    real_array,
    real_number,
    to_float_array,
)
from sustain_drake.identification.eye_to_hand_points import (
    _known_points_statistic,
    _points,
    _position_given_rotation,
    _statistics,
)
from sustain_drake.identification.rotation import _nearest_rotation, _skew, _so3_exp


class CameraAfterTurn(NamedTuple):
    """``camera_after_turn``'s answer: the camera (``R_WC``, ``p_WC``), the anchors' RMS direction
    misfit (rad) and how many anchors fitted; ``scene_shift``: the position is the static scene's
    (from the anchors' depth on both sides of the move), not the old one left where it was;
    ``rotation_sd``: the turn's 1 sd about its worst-determined axis (rad, ``_turn_rotation_sd``)."""

    R_WC: np.ndarray
    p_WC: np.ndarray
    rms_angle: float
    num_anchors: int
    scene_shift: bool
    rotation_sd: float


# count: the fewest anchors a turn is fitted to. Two bearings fix a rotation; the misfit test (three
# times the median misfit) leaves out the anchors on moving things only while they are fewer than
# half, so five anchors stand two such and still over-determine the turn with three.
MIN_TURN_ANCHORS = 5
# rad: the largest 1 sd of a turn that is used. The camera found after a turn keeps the turn's
# rotation (the tool points place it, they do not turn it), so 3 sd of the turn stay within the
# hand-eye target for an adopted camera's rotation, 0.2 deg.
MAX_TURN_ROTATION_SD = math.radians(0.2) / 3.0


def _turn_rotation_sd(c: np.ndarray, misfit: np.ndarray) -> float:
    """1 sd (rad) of a rotation fitted to unit directions ``c`` (K x 3, before) by their misfit
    angles ``misfit`` (K, rad) after it, about its worst-determined axis: a small turn ``d`` moves a
    direction by ``d x c``, seen only across ``c``, so the information is ``sum (I - c c^T) / s^2``
    with the per-axis direction noise ``s^2 = sum misfit^2 / (2 K - 3)`` (two equations per
    anchor, three unknowns). Anchors bunched at the image centre leave the turn about the optical
    axis weakly determined: that axis's sd is the one returned. inf with fewer than 2 anchors or a
    singular information (all directions parallel)."""
    k = c.shape[0]
    if k < 2:
        return math.inf
    information = k * np.eye(3) - c.T @ c
    smallest = float(np.linalg.eigvalsh(information)[0])
    if not smallest > 1e-12 * k:
        return math.inf
    variance = float(misfit @ misfit) / max(2 * k - 3, 1)
    return math.sqrt(variance / smallest)


# count: the most anchor pairs whose turns ``_least_median_inliers`` tries (all pairs of 32 anchors)
LEAST_MEDIAN_PAIRS = 496


def _least_median_inliers(c: np.ndarray, b1: np.ndarray) -> np.ndarray:
    """The anchors a turn is first fitted to (``c``: unit directions before, ``b1``: bearings after,
    K x 3 each): the turn of two anchors (two bearings fix a rotation) that leaves the smallest
    median misfit over all of them (least median of squares, Rousseeuw 1984), and the anchors within
    three times that median. It stands anchors on moving things up to just under half of them; a
    least-squares start is drawn off by a few anchors misfitting by degrees (the ground by the arm
    where a person walks: 10 of 27 anchors, the turn 0.31 deg off), and the misfit test after it
    then keeps them. Up to ``LEAST_MEDIAN_PAIRS`` pairs, drawn by a fixed-seed generator."""
    k = c.shape[0]
    if k < 3:
        return np.ones(k, bool)
    i, j = np.triu_indices(k, 1)
    if i.size > LEAST_MEDIAN_PAIRS:
        pick = np.random.default_rng(0).choice(i.size, LEAST_MEDIAN_PAIRS, replace=False)
        i, j = i[pick], j[pick]
    # Each pair's turn R (R b1 ~ c): the nearest rotation to c_i b1_i^T + c_j b1_j^T (Kabsch).
    M = c[i, :, None] * b1[i, None, :] + c[j, :, None] * b1[j, None, :]
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    U[:, :, 2] *= d[:, None]
    R = U @ Vt
    misfit = np.linalg.norm(np.cross(np.einsum("pab,kb->pka", R, b1), c[None]), axis=2)
    median = np.median(misfit, axis=1)
    best = int(np.argmin(median))
    return misfit[best] <= max(3.0 * float(median[best]), 1e-5)


def _robust_scale(errors: np.ndarray) -> float:
    """1.4826 times the median of non-negative errors (a Gaussian's sigma from its median absolute
    value), kept off zero for noise-free data."""
    return max(1.4826 * float(np.median(errors)), 1e-9)


def _scene_registration(R, p, b0, q0, b1, q1, far, inliers, used, steps: int = 3):
    """The turn ``R_C0C1`` and shift ``p_C0C1`` that fit the anchors' bearings (``inliers``) and their
    depth on both sides (``used``) together, by Gauss-Newton from ``(R, p)``. The bearings alone
    leave a valley: a turn and a shift along it move a scene at one depth alike; the depth (each
    anchor's ``q0 - R q1 - p``, its noise growing with the depth) tells them apart. Each kind of
    residual is weighted by its robust scale (``_robust_scale``; the depth's scaled by ``z^2``), and depth
    misfits over three scales are left out (an anchor on a moving thing, a depth edge)."""
    z = np.maximum(np.linalg.norm(q1, axis=1), 0.1)
    b1_x = np.array([_skew(v) for v in b1])  # the Jacobians' cross-product matrices, fixed
    q1_x = np.array([_skew(v) for v in np.nan_to_num(q1)])
    for _ in range(steps):
        c = np.where(far[:, None], b0, q0 - p)
        norm = np.linalg.norm(c, axis=1, keepdims=True)
        c = c / norm
        r_b = c - b1 @ R.T  # bearing misfit (rad)
        r_d = q0 - q1 @ R.T - p  # depth misfit (m)
        J_b = np.zeros((len(c), 3, 6))
        J_b[:, :, :3] = np.einsum("ij,njk->nik", R, b1_x)
        near = ~far
        J_b[near, :, 3:] = -(np.eye(3) - c[near, :, None] * c[near, None, :]) / norm[near, :, None]
        J_d = np.zeros((len(c), 3, 6))
        J_d[:, :, :3] = np.einsum("ij,njk->nik", R, q1_x)
        J_d[:, :, 3:] = -np.eye(3)
        e_b = np.linalg.norm(r_b, axis=1)
        e_d = np.linalg.norm(np.nan_to_num(r_d), axis=1) / z**2
        s_b, s_d = _robust_scale(e_b[inliers]), _robust_scale(e_d[used])
        keep = used & (e_d <= 3.0 * s_d)
        w_d = 1.0 / (s_d * z[keep] ** 2)
        A = np.concatenate([(J_b[inliers] / s_b).reshape(-1, 6),
                            (J_d[keep] * w_d[:, None, None]).reshape(-1, 6)])
        b = np.concatenate([(r_b[inliers] / s_b).ravel(), (r_d[keep] * w_d[:, None]).ravel()])
        delta = -np.linalg.lstsq(A, b, rcond=None)[0]
        R, p = R @ _so3_exp(delta[:3]), p + delta[3:]
    return R, p


def _anchors(name: str, value, bearings: bool) -> np.ndarray:
    """``camera_after_turn``'s per-anchor rows checked, K x 3 (or their 3 K entries): bearings finite
    and non-zero; points non-zero where finite (NaN or inf rows: no depth)."""
    what = "a K x 3 array"
    A = value if type(value) is np.ndarray and value.dtype is F64 else to_float_array(name, value, what)
    if not (A.ndim == 2 and A.shape[1] == 3) and not (A.ndim == 1 and A.size % 3 == 0):
        raise IdentificationError(f"{name} must be a K x 3 array, got {describe(value)}")
    A = A.reshape(-1, 3)
    if bearings:
        check_finite(name, A)
    finite = np.all(np.isfinite(A), axis=1)
    if np.any(finite & ~np.any(A != 0.0, axis=1)):
        raise IdentificationError(f"{name} must have non-zero rows, got a zero row")
    return A


class TurnAnchors(NamedTuple):
    """The static scene's anchors across a camera move, per anchor (K x 3 each): its unit bearing
    before ``b0`` (in C0) and after ``b1`` (in C1), its point before ``q0`` (m, in C0) and after
    ``q1`` (m, in C1; None: no depth after); NaN rows of ``q0``, ``q1``: no depth there.
    ``perception.camera_motion.SceneTurn`` has these fields and serves as well."""

    b0: np.ndarray
    q0: np.ndarray
    b1: np.ndarray
    q1: np.ndarray | None = None


def camera_after_turn(R_WC0: np.ndarray, p_WC0: np.ndarray, anchors: TurnAnchors, S_list: list[np.ndarray],
                      p_HP: np.ndarray, min_points: int = MIN_TURN_ANCHORS, iterations: int = 4,
                      max_rotation_sd: float = MAX_TURN_ROTATION_SD):  # fmt: skip
    """The camera after a move (beyond the paper) from two things that the move left as they were:
    the static scene (its rotation) and the held tool (its position).

    - The scene: the ``anchors`` (``TurnAnchors``): per anchor its unit bearings ``b0`` (before, in
      C0) and ``b1`` (after, in C1) and its point before ``q0`` (in C0, m; NaN rows: no depth, taken
      as far away). A static point satisfies ``q0 - p_C0C1 ~ R_C0C1 b1``
      (directions), so given the camera's shift ``p_C0C1`` the turn is an orthogonal Procrustes
      problem on directions. Far anchors pin it to their pixel noise over the focal length, whatever
      the shift; the shift itself (the parallax) they hardly show.
    - The scene's depth after the move too (``q1``, in C1, NaN rows without): a static point
      satisfies ``q0 = R_C0C1 q1 + p_C0C1``, so with at least ``min_points`` fitted anchors that
      have depth on both sides the turn and the shift are fitted to the bearings and the depth
      together (``_scene_registration``). None or empty: no depth after.
    - The tool: points with known ``p_HP`` (K x 3, learned under the camera before) and their
      samples after the move (``S_list``, raw statistics) give ``p_WC`` for a known ``R_WC``
      (``position_given_rotation``).

    Alternates the rotation and the shift from ``p_C0C1 = 0`` (``iterations`` times; the coupling
    is the shift over the anchors' depths, small); the shift is the tool's when there are tool
    samples, else the scene's, else none (the position left at ``p_WC0``: the turn alone, e.g. to
    find the tool's points again). Anchors
    whose direction misfits by more than three times the median are left out (a feature of the
    moving arm, a track that jumped), each fit. Returns a ``CameraAfterTurn``, or None with fewer
    than ``min_points`` anchors left (``MIN_TURN_ANCHORS``) or a turn whose 1 sd
    (``_turn_rotation_sd``, from the anchors' own misfits and their spread) exceeds
    ``max_rotation_sd`` (``MAX_TURN_ROTATION_SD``).

    IdentificationError unless ``R_WC0`` is a finite 3 x 3 matrix, ``p_WC0`` a finite 3-vector,
    ``anchors`` has ``b0`` and ``b1``, K x 3 arrays of finite non-zero bearings, and ``q0`` (and
    ``q1`` unless None or empty), K x 3 arrays whose finite rows are non-zero, ``S_list`` a list of
    finite 16 x 16 statistics with as many finite ``p_HP`` points, ``min_points``, ``iterations``
    integers >= 1 and ``max_rotation_sd`` a number >= 0 (inf: no limit)."""
    R_WC0, p_WC0 = real_array("R_WC0", R_WC0, MATRIX3), real_array("p_WC0", p_WC0, VECTOR3)
    if not all(hasattr(anchors, name) for name in ("b0", "q0", "b1")):
        raise IdentificationError(f"anchors must be a TurnAnchors (b0, q0, b1, q1), got {describe(anchors)}")
    b0, b1 = _anchors("b0", anchors.b0, bearings=True), _anchors("b1", anchors.b1, bearings=True)
    q0 = _anchors("q0", anchors.q0, bearings=False)
    q1 = getattr(anchors, "q1", None)
    q1 = None if q1 is None else _anchors("q1", q1, bearings=False)
    if q1 is None or q1.size == 0:
        q1 = np.full_like(q0, np.nan)
    if not (b1.shape == q0.shape == q1.shape == b0.shape):
        raise IdentificationError(f"camera_after_turn: b0, q0, b1 and q1 must be K x 3 alike, got "
                                  f"{b0.shape}, {q0.shape}, {b1.shape}, {q1.shape}")
    S_list = _statistics(S_list)
    p_HP = _points("p_HP", p_HP, len(S_list))
    min_points, iterations = integer("min_points", min_points, 1), integer("iterations", iterations, 1)
    max_rotation_sd = real_number("max_rotation_sd", max_rotation_sd, finite=False, what="a number >= 0")
    if not max_rotation_sd >= 0.0:
        raise IdentificationError(f"max_rotation_sd must be a number >= 0, got {max_rotation_sd}")
    far = ~np.all(np.isfinite(q0), axis=1)
    deep = ~far & np.all(np.isfinite(q1), axis=1)  # depth on both sides
    P, n = _known_points_statistic(S_list, p_HP)
    if b0.shape[0] < min_points:
        return None
    # Without tool samples, the scene's depth gives the shift (when enough anchors have it).
    scene = n == 0 and np.count_nonzero(deep) >= min_points
    p_C0C1, from_scene = np.zeros(3), False
    start = np.where(far[:, None], b0, q0)
    inliers = _least_median_inliers(start / np.linalg.norm(start, axis=1, keepdims=True), b1)
    for _ in range(iterations if n > 0 or scene else 1):
        c = np.where(far[:, None], b0, q0 - p_C0C1)
        c /= np.linalg.norm(c, axis=1, keepdims=True)
        for _ in range(2):  # fit, leave out the misfits, fit again
            R_C0C1 = _nearest_rotation(c[inliers].T @ b1[inliers])
            angle = np.linalg.norm(np.cross(b1 @ R_C0C1.T, c), axis=1)
            inliers = angle <= max(3.0 * float(np.median(angle)), 1e-5)
            if np.count_nonzero(inliers) < min_points:
                return None
        R_WC = R_WC0 @ R_C0C1
        used = inliers & deep
        if n > 0:
            p_WC = _position_given_rotation(P, n, R_WC)
            p_C0C1 = R_WC0.T @ (p_WC - p_WC0)
            continue
        if scene and np.count_nonzero(used) >= min_points:
            R_C0C1, p_C0C1 = _scene_registration(R_C0C1, p_C0C1, b0, q0, b1, q1, far, inliers, used)
            R_WC, from_scene = R_WC0 @ R_C0C1, True
        p_WC = p_WC0 + R_WC0 @ p_C0C1
    rotation_sd = _turn_rotation_sd(c[inliers], angle[inliers])
    if not rotation_sd <= max_rotation_sd:
        return None
    rms = math.sqrt(float(np.mean(angle[inliers] ** 2)))
    return CameraAfterTurn(R_WC, p_WC, rms, int(np.count_nonzero(inliers)), from_scene, rotation_sd)
