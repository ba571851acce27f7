"""Eye-to-hand from several points at once, sharing one camera (beyond the paper, which identifies
from one point; pure numpy): the joint Gauss-Newton refinement of the camera and every point's
``p_HP`` from their Eq. (30) statistics (``refine_joint``, ``rotation_levers``), the camera that known
points give in closed form (``camera_given_points``, ``position_given_rotation``) and the camera
after it turned, from the static scene's anchors and the known points (``camera_after_turn``), and
for recorded data (``batch.calibrate_eye_to_hand_points``) each point's ``p_HP`` under a known
camera (``points_given_camera``), the joint fit with each point weighted by its own noise
(``refine_joint_weighted``) and its covariance (``joint_covariance``).

Every statistic is the 16 x 16 ``S`` of ``eye_to_hand`` (``x^T S x`` is the sum of squared Eq. (30)
residuals, m^2); every public function raises ``IdentificationError`` with a one-line message for
a bad argument.
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
    rotation,
    to_float_array,
)
from sustain_drake.identification.eye_to_hand import N_UNKNOWNS, _pack_x
from sustain_drake.identification.rotation import _nearest_rotation, _rotation_jacobian, _skew, _so3_exp


def _statistics(S_list) -> list[np.ndarray]:
    """``S_list`` checked: a list or tuple (or a K x 16 x 16 array) of finite 16 x 16 statistics."""
    if isinstance(S_list, np.ndarray) and S_list.ndim == 3:
        S_list = list(S_list)
    if not isinstance(S_list, (list, tuple)):
        raise IdentificationError(f"S_list must be a list of 16 x 16 statistics, got {describe(S_list)}")
    return [real_array(f"S_list[{k}]", S, (N_UNKNOWNS, N_UNKNOWNS)) for k, S in enumerate(S_list)]


def _points(name: str, value, K: int) -> np.ndarray:
    """``value`` checked as K finite points: a K x 3 array (or its 3 K entries), returned K x 3."""
    what = f"a {K} x 3 array (one point per statistic)"
    P = value if type(value) is np.ndarray and value.dtype is F64 else to_float_array(name, value, what)
    if not (P.shape == (K, 3) or P.shape == (3 * K,)):
        raise IdentificationError(f"{name} must be {what}, got {describe(value)}")
    check_finite(name, P)
    return P.reshape(K, 3)


def refine_joint(S_list: list[np.ndarray], R: np.ndarray, p_WC: np.ndarray, p_HP: np.ndarray,
                 max_iterations: int = 30, tolerance: float = 1e-10):
    """Gauss-Newton on SO(3) x R^3 x (R^3)^K of ``sum_k x_k^T S_k x_k`` (every point's geometric
    least-squares cost, one camera; ``S_k`` the raw 16 x 16 statistic of point k), from the
    statistics alone: ``refine`` for K points fixed on the hand, which need not be seen in the same
    frames. The camera is what all of them must agree on, so its rotation is excited by the union of
    the points' views. Start from a single point's estimate (``p_HP``: K x 3). Returns
    ``(R_WC, p_WC, p_HP)``, or None if the normal equations are singular (degenerate data).
    IdentificationError unless ``S_list`` is a list of finite 16 x 16 statistics, ``R`` a rotation
    matrix, ``p_WC`` a finite 3-vector, ``p_HP`` K finite points, ``max_iterations`` an integer >= 0
    and ``tolerance`` a number >= 0."""
    S_list = _statistics(S_list)
    K = len(S_list)
    R, p_WC = rotation("R", R).copy(), real_array("p_WC", p_WC, VECTOR3).copy()
    p_HP = _points("p_HP", p_HP, K).copy()
    max_iterations = integer("max_iterations", max_iterations, 0)
    tolerance = real_number("tolerance", tolerance, finite=False, what="a number >= 0")
    if not tolerance >= 0.0:
        raise IdentificationError(f"tolerance must be a number >= 0, got {tolerance}")
    for _ in range(max_iterations):
        H, g = _joint_normal_equations(S_list, R, p_WC, p_HP)
        try:
            delta = -np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            return None
        if not np.all(np.isfinite(delta)) or np.abs(delta).max() > 1e3:
            return None
        R = R @ _so3_exp(delta[0:3])
        p_WC = p_WC + delta[3:6]
        p_HP = p_HP + delta[6:].reshape(K, 3)
        if np.abs(delta).max() < tolerance:
            break
    return _nearest_rotation(R), p_WC, p_HP


def _joint_normal_equations(S_list: list[np.ndarray], R: np.ndarray, p_WC: np.ndarray, p_HP: np.ndarray):
    """Gauss-Newton's normal matrix ``H`` and gradient ``g`` of ``sum_k x_k^T S_k x_k`` at the
    camera ``(R, p_WC)`` and the points ``p_HP`` (K x 3), in the unknowns ``(omega, dp_WC, dp_HP_1..K)``
    (``omega`` the camera's turn in its own frame)."""
    K = len(S_list)
    J = _rotation_jacobian(R, np.zeros((N_UNKNOWNS, 9)))
    J[9:15, 3:9] = np.eye(6)
    n = 6 + 3 * K
    H, g = np.zeros((n, n)), np.zeros(n)
    for k, S in enumerate(S_list):
        idx = np.r_[0:6, 6 + 3 * k: 9 + 3 * k]
        H[np.ix_(idx, idx)] += J.T @ S @ J
        g[idx] += J.T @ (S @ _pack_x(R, p_WC, p_HP[k]))
    return H, g


def rotation_levers(S_list: list[np.ndarray], R: np.ndarray, p_WC: np.ndarray, p_HP: np.ndarray):
    """How well K points' samples pin the camera's rotation (beyond the paper): for each principal
    axis of a turn of the camera, the RMS displacement of the samples per radian of turn that
    neither the camera's position nor the points' ``p_HP`` can absorb (m, ascending): the square
    roots of the eigenvalues of the rotation block of the joint normal matrix (``refine_joint``'s,
    at ``R, p_WC, p_HP``) with the other unknowns eliminated (its Schur complement), per sample.

    A camera turned by ``delta`` about an axis of lever ``L`` fits the samples worse by only
    ``delta L`` RMS, so errors of the points that agree from sample to sample (a view's error is
    the same each time the view recurs) of size ``e`` turn it by about ``e / L``: while the hand
    moves little, the smallest lever is millimetres and the camera turns about the workspace
    (``hand_eye.yaml``, four runs: 6-9 mm at the first convergences, whose cameras were up to
    2.7 mm off; 25-30 mm a few seconds of babbling later, when the same points put the camera about
    1 mm off). Zeros if the other unknowns are not determined. IdentificationError as for
    ``refine_joint``."""
    S_list = _statistics(S_list)
    K = len(S_list)
    p_HP = _points("p_HP", p_HP, K)
    H, _ = _joint_normal_equations(S_list, rotation("R", R), real_array("p_WC", p_WC, VECTOR3), p_HP)
    n_samples = sum(float(S[9, 9]) for S in S_list)  # A_t's p_WC block is I: S[9, 9] counts samples
    try:
        schur = H[:3, :3] - H[:3, 3:] @ np.linalg.solve(H[3:, 3:], H[3:, :3])
    except np.linalg.LinAlgError:
        return np.zeros(3)
    if not (n_samples > 0 and np.all(np.isfinite(schur))):
        return np.zeros(3)
    return np.sqrt(np.maximum(np.linalg.eigvalsh(schur / n_samples), 0.0))


def _known_points_statistic(S_list: list[np.ndarray], p_HP: np.ndarray):
    """``sum_k x_k^T S_k x_k`` with each ``p_HP`` fixed, as a quadratic form ``w^T P w`` in
    ``w = [vec R_WC; p_WC; 1]`` (13 x 13), and the number of samples in all."""
    p_HP = np.asarray(p_HP, dtype=float).reshape(-1, 3)
    P = np.zeros((13, 13))
    E = np.zeros((N_UNKNOWNS, 13))  # x = E w
    E[:12, :12] = np.eye(12)
    E[15, 12] = 1.0
    for S, p in zip(S_list, p_HP, strict=True):
        E[12:15, 12] = p
        P += E.T @ np.asarray(S, dtype=float) @ E
    return P, P[9, 9]


def _position_given_rotation(P: np.ndarray, n: float, R_WC: np.ndarray) -> np.ndarray:
    """The ``p_WC`` minimising ``w^T P w`` for a given ``R_WC`` (affine in ``vec R_WC``)."""
    return -(P[9:12, 0:9] @ R_WC.reshape(9, order="F") + P[9:12, 12]) / n


def position_given_rotation(S_list: list[np.ndarray], p_HP: np.ndarray, R_WC: np.ndarray):
    """The camera position that best explains the samples of K points whose ``p_HP`` is known
    (``S_k`` the raw statistics; ``p_HP``: K x 3) when its rotation ``R_WC`` is known too: Eq. (35)'s
    least squares in ``p_WC`` alone, the mean of ``R_WH p_HP + p_WH - R_WC p_CP`` over the samples.
    None for no samples. IdentificationError unless ``S_list`` is a list of finite 16 x 16
    statistics, ``p_HP`` as many finite points and ``R_WC`` a finite 3 x 3 matrix."""
    S_list = _statistics(S_list)
    p_HP = _points("p_HP", p_HP, len(S_list))
    R_WC = real_array("R_WC", R_WC, MATRIX3)
    P, n = _known_points_statistic(S_list, p_HP)
    return _position_given_rotation(P, n, R_WC) if n > 0 else None


def camera_given_points(S_list: list[np.ndarray], p_HP: np.ndarray):
    """The camera pose that best explains the samples of K points whose ``p_HP`` is known
    (``S_k`` the raw 16 x 16 statistic of point k; ``p_HP``: K x 3): Eq. (35)'s least squares with
    ``p_HP`` fixed, in closed form from the statistics alone. Beyond the paper: a moved camera leaves
    the held tool as it was, so only the camera (6 unknowns) is new.

    With ``p_HP`` fixed, ``sum_k x_k^T S_k x_k`` is quadratic in ``(vec R_WC, p_WC)``; the
    minimising ``p_WC`` is affine in ``R_WC``, and the remaining quadratic term in ``R_WC`` is
    ``tr(C)`` (``C`` the scatter of the camera-frame points), constant on SO(3): what is left is
    linear in ``R_WC``, an orthogonal Procrustes problem (SVD). Returns ``(R_WC, p_WC, spread)``:
    ``spread`` (m), the RMS distance of the camera-frame points from their principal line, says how
    well the samples pin the rotation (a turn about any axis moves the points by at least the angle
    times it; 0: the points on a line, where the turn about it is free; points in a plane pin it).
    None for no samples. IdentificationError unless ``S_list`` is a list of finite 16 x 16
    statistics and ``p_HP`` as many finite points."""
    S_list = _statistics(S_list)
    P, n = _known_points_statistic(S_list, _points("p_HP", p_HP, len(S_list)))
    if not n > 0:
        return None
    # p_WC = -(P_tR vec R + P_t1) / n; the cost's term linear in vec R is then 2 g^T vec R.
    g = P[0:9, 12] - P[0:9, 9:12] @ P[9:12, 12] / n
    R = _nearest_rotation(-g.reshape(3, 3, order="F"))  # max tr(-G^T R) on SO(3)
    p_WC = _position_given_rotation(P, n, R)
    scatter = P[0:9:3, 0:9:3] - np.outer(P[0:9:3, 9], P[0:9:3, 9]) / n  # n C: P_RR = (sum a a^T) x I
    return R, p_WC, _spread_off_line(scatter / n)


def spread_off_line(covariance: np.ndarray) -> float:
    """The RMS distance (m) of points from their principal line, from their 3 x 3 covariance:
    the root of its two smallest eigenvalues' sum (0 for points on a line). IdentificationError
    unless ``covariance`` is a finite 3 x 3 matrix."""
    return _spread_off_line(real_array("covariance", covariance, MATRIX3))


def _spread_off_line(covariance: np.ndarray) -> float:
    smallest = np.linalg.eigvalsh(covariance)[:2]
    return math.sqrt(max(float(smallest.sum()), 0.0))


class CameraAfterTurn(NamedTuple):
    """``camera_after_turn``'s answer: the camera (``R_WC``, ``p_WC``), the anchors' RMS direction
    misfit (rad) and how many anchors fitted; ``scene_shift``: the position is the static scene's
    (from the anchors' depth on both sides of the move), not the old one left where it was;
    ``rotation_sd``: the turn's 1 sd about its worst-determined axis (rad, ``turn_rotation_sd``)."""

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


def turn_rotation_sd(c: np.ndarray, misfit: np.ndarray) -> float:
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
    (``turn_rotation_sd``, from the anchors' own misfits and their spread) exceeds
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
    rotation_sd = turn_rotation_sd(c[inliers], angle[inliers])
    if not rotation_sd <= max_rotation_sd:
        return None
    rms = math.sqrt(float(np.mean(angle[inliers] ** 2)))
    return CameraAfterTurn(R_WC, p_WC, rms, int(np.count_nonzero(inliers)), from_scene, rotation_sd)


# ---- several points at once from recorded data (batch.calibrate_eye_to_hand_points) --------------
# m^2 (1 um RMS): a point's residual variance below this is round-off (noise-free data); its weight
# in the joint fit is taken against at least this, so noise-free points weigh alike.
ROUND_OFF_VARIANCE = 1e-12


def _counts(S_list: list[np.ndarray]) -> np.ndarray:
    """The samples behind each statistic (A_t's p_WC block is I: ``S[9, 9]`` counts them)."""
    return np.array([float(S[9, 9]) for S in S_list])


def _squared_errors(S_list: list[np.ndarray], R: np.ndarray, p_WC: np.ndarray, p_HP: np.ndarray):
    """Each point's sum of squared Eq. (30) residuals ``x_k^T S_k x_k`` (m^2, >= 0)."""
    return np.array([max(float(x @ S @ x), 0.0)
                     for S, x in ((S, _pack_x(R, p_WC, p)) for S, p in zip(S_list, p_HP, strict=True))])


def _points_given_camera(S_list: list[np.ndarray], R_WC: np.ndarray, p_WC: np.ndarray) -> np.ndarray:
    P = np.zeros((len(S_list), 3))
    x = _pack_x(R_WC, p_WC, np.zeros(3))
    for k, S in enumerate(S_list):
        if S[9, 9] > 0.0:  # S[12:15, 12:15] = sum R_WH^T R_WH = S[9, 9] I
            P[k] = -(S[12:15, :] @ x) / S[9, 9]
    return P


def points_given_camera(S_list: list[np.ndarray], R_WC: np.ndarray, p_WC: np.ndarray) -> np.ndarray:
    """The ``p_HP`` (K x 3) that best explains each point's samples when the camera is known: Eq. (35)'s
    least squares in ``p_HP`` alone, the mean of ``R_WH^T (R_WC p_CP + p_WC - p_WH)`` over the point's
    samples, from its raw statistic ``S_k`` (zeros for a point without samples). IdentificationError
    unless ``S_list`` is a list of finite 16 x 16 statistics, ``R_WC`` a rotation matrix and ``p_WC``
    a finite 3-vector."""
    S_list = _statistics(S_list)
    return _points_given_camera(S_list, rotation("R_WC", R_WC), real_array("p_WC", p_WC, VECTOR3))


def _inverse_variance_weights(S_list, R, p_WC, p_HP) -> np.ndarray:
    """Each point's weight: the inverse of its residual variance per axis under the fit,
    ``x_k^T S_k x_k / (3 m_k - 3)`` (its own ``p_HP`` takes 3 of its ``3 m_k`` equations), floored at
    ``ROUND_OFF_VARIANCE``; scaled so that the weighted samples number as many as the samples."""
    m = _counts(S_list)
    variance = _squared_errors(S_list, R, p_WC, p_HP) / np.maximum(3.0 * m - 3.0, 1.0)
    weights = 1.0 / np.maximum(variance, ROUND_OFF_VARIANCE)
    return weights * (m.sum() / float(weights @ m))


def refine_joint_weighted(S_list: list[np.ndarray], R: np.ndarray, p_WC: np.ndarray,
                          max_rounds: int = 10, tolerance: float = 1e-3):  # fmt: skip
    """The joint fit of K points fixed on the hand when each has its own noise (beyond the paper): the
    maximum-likelihood camera and ``p_HP`` per point, by ``refine_joint`` on the statistics weighted
    by the inverse of each point's residual variance (``x_k^T S_k x_k / (3 m_k - 3)`` per axis, ``m_k``
    its samples; floored at ``ROUND_OFF_VARIANCE``), the variances found again under each new fit
    until no weight changes by more than ``tolerance`` (relative) or after ``max_rounds`` fits.
    Unweighted, a point measured with 4 mm of noise pulls the camera as hard as one measured with
    0.5 mm (on the real data set the corner's residual grows from 0.50 to 0.73 mm RMS); weighted, each
    pulls by what it knows. Starts from the camera ``(R, p_WC)`` (a single point's) with each point's
    ``points_given_camera``. Returns ``(R_WC, p_WC, p_HP, weights)`` (``p_HP`` K x 3; the weights
    scaled so that the weighted samples number as many as the samples), or None if the normal
    equations are singular. IdentificationError unless ``S_list`` is a list of finite 16 x 16
    statistics, ``R`` a rotation matrix, ``p_WC`` a finite 3-vector, ``max_rounds`` an integer >= 1
    and ``tolerance`` a number >= 0."""
    S_list = _statistics(S_list)
    R, p_WC = rotation("R", R), real_array("p_WC", p_WC, VECTOR3)
    max_rounds = integer("max_rounds", max_rounds, 1)
    tolerance = real_number("tolerance", tolerance, what="a number >= 0")
    if not tolerance >= 0.0:
        raise IdentificationError(f"tolerance must be a number >= 0, got {tolerance}")
    with np.errstate(all="ignore"):  # absurd magnitudes: no fit (None), never a NaN out
        P = _points_given_camera(S_list, R, p_WC)
        weights = _inverse_variance_weights(S_list, R, p_WC, P)
        for _ in range(max_rounds):
            if not np.isfinite(weights).all():
                return None
            fit = refine_joint([w * S for w, S in zip(weights, S_list, strict=True)], R, p_WC, P)
            if fit is None:
                return None
            R, p_WC, P = fit
            previous, weights = weights, _inverse_variance_weights(S_list, R, p_WC, P)
            if np.abs(weights / previous - 1.0).max() <= tolerance:
                break
    return (R, p_WC, P, weights) if np.isfinite(weights).all() else None


def joint_covariance(S_list: list[np.ndarray], R: np.ndarray, p_WC: np.ndarray, p_HP: np.ndarray,
                     weights=None) -> np.ndarray | None:  # fmt: skip
    """Gauss-Newton's covariance ``sigma^2 H^-1`` ((6 + 3K) x (6 + 3K)) of the joint fit of K points'
    raw statistics at the camera ``(R, p_WC)`` and the points ``p_HP`` (K x 3; the fit's optimum), in
    ``(omega, p_WC, p_HP_1, ..., p_HP_K)``: ``omega`` the camera's turn in its own frame (rad; the truth
    is ``R exp([omega x])``), positions in m. ``H = sum_k w_k J^T S_k J`` is ``refine_joint``'s normal
    matrix of the weighted statistics and ``sigma^2 = sum_k w_k x_k^T S_k x_k / (3 n - 6 - 3K)``
    (``n`` the samples of all points): with ``refine_joint_weighted``'s weights ``sigma^2`` is about
    1 and each point counts with its own noise; one point with weight 1 gives
    ``observability.eye_to_hand_covariance``. ``weights``: K positive numbers (None: all 1). None if
    the fit is undetermined or ``3 n <= 6 + 3K``. IdentificationError unless ``S_list`` is a list of
    finite 16 x 16 statistics, ``R`` a rotation matrix, ``p_WC`` a finite 3-vector, ``p_HP`` K finite
    points and ``weights`` None or K finite positive numbers."""
    S_list = _statistics(S_list)
    K = len(S_list)
    R, p_WC, p_HP = rotation("R", R), real_array("p_WC", p_WC, VECTOR3), _points("p_HP", p_HP, K)
    w = np.ones(K) if weights is None else real_array("weights", weights, (K,), what=f"{K} positive numbers")
    if not np.all(w > 0.0):
        raise IdentificationError(f"weights must be {K} positive numbers, got {describe(weights)}")
    dof = 3.0 * float(_counts(S_list).sum()) - 6.0 - 3.0 * K
    if not (K > 0 and dof > 0.0):
        return None
    weighted = [wk * S for wk, S in zip(w, S_list, strict=True)]
    H, _ = _joint_normal_equations(weighted, R, p_WC, p_HP)
    try:
        inverse = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        return None
    sigma2 = float(_squared_errors(weighted, R, p_WC, p_HP).sum()) / dof
    covariance = sigma2 * (inverse + inverse.T) / 2.0
    if not (np.isfinite(covariance).all() and np.all(np.diagonal(covariance) >= 0.0)):
        return None
    return covariance
