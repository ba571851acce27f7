"""Eye-to-hand from several points at once, sharing one camera (beyond the paper, which identifies
from one point; pure numpy): the joint Gauss-Newton refinement of the camera and every point's
``p_HP`` from their Eq. (30) statistics (``refine_joint``, ``rotation_levers``), the camera that known
points give in closed form (``camera_given_points``, ``position_given_rotation``), the camera's
position and the points together under a known rotation (``position_and_points_given_rotation``),
and for recorded data (``batch.calibrate_eye_to_hand_points``) each point's ``p_HP`` under a known
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
from sustain_drake.identification.eye_to_hand import N_UNKNOWNS, _conditioning_transform, _pack_x
from sustain_drake.identification.rotation import (
    _nearest_rotation,
    _projection_parts,
    _rotation_jacobian,
    _so3_exp,
)


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


class PositionAndPoints(NamedTuple):
    """``position_and_points_given_rotation``'s answer: the camera position ``p_WC`` (m), each point's
    ``p_HP`` (K x 3, m), the position's covariance (3 x 3, m^2) and each point's mean squared
    Eq. (30) error with them (K, m^2)."""

    p_WC: np.ndarray
    p_HP: np.ndarray
    covariance: np.ndarray
    mean_squared_errors: np.ndarray


def position_and_points_given_rotation(S_list: list[np.ndarray], R_WC: np.ndarray, independent=None):
    """The camera position and every point's ``p_HP`` that best explain K points' samples (``S_k``,
    raw statistics) when the camera's rotation ``R_WC`` is known: Eq. (35)'s least squares in
    ``p_WC`` and the ``p_HP`` together, linear (3 + 3K unknowns). Each ``p_HP`` is eliminated
    (``p_HP = -S_qq^-1 (S_qp p_WC + S_qc c)``, ``c = [vec R_WC; 1]``), leaving the 3 x 3 Schur
    complement ``H = sum_k H_k`` in ``p_WC``; the position's covariance is ``s^2 H^-1`` with ``s^2``
    the residual sum over its ``3 n - 3 - 3K`` degrees of freedom (``n`` samples in all), each point
    counting its ``independent`` samples (K positive numbers, None: all; as in
    ``joint_covariance``) in ``H``, ``s^2`` and ``n``; the fit itself weighs every sample alike.
    The hand must turn: a translation moves ``p_WC`` and every ``p_HP`` alike. Returns a
    ``PositionAndPoints``, or None when ``H`` is singular (the hand did not turn) or there are too
    few (independent) samples for the degrees of freedom. IdentificationError unless ``S_list`` is
    a non-empty list of finite 16 x 16 statistics, ``R_WC`` a finite 3 x 3 matrix and
    ``independent`` None or K finite positive numbers."""
    S_list = _statistics(S_list)
    if not S_list:
        raise IdentificationError("position_and_points_given_rotation needs at least one statistic")
    R_WC = real_array("R_WC", R_WC, MATRIX3)
    factors = _independent_shares(S_list, independent)
    c = np.concatenate([R_WC.reshape(9, order="F"), [1.0]])
    fixed = np.r_[0:9, 15]
    H_k, g, eliminations = [], np.zeros(3), []
    for S in S_list:
        S_qq = S[12:15, 12:15]
        if not S[9, 9] > 0.0:
            return None
        solve_q = np.linalg.solve(S_qq, np.column_stack([S[12:15, 9:12], S[12:15, fixed] @ c]))
        H_k.append(S[9:12, 9:12] - S[9:12, 12:15] @ solve_q[:, :3])
        g += S[9:12, fixed] @ c - S[9:12, 12:15] @ solve_q[:, 3]
        eliminations.append(solve_q)
    H = np.sum(H_k, axis=0)
    dof = 3.0 * float((factors * _counts(S_list)).sum()) - 3.0 - 3.0 * len(S_list)
    if not (dof > 0 and np.linalg.cond(H) < 1e12):
        return None
    p_WC = -np.linalg.solve(H, g)
    P = np.array([-(q[:, :3] @ p_WC + q[:, 3]) for q in eliminations])
    squared = _squared_errors(S_list, R_WC, p_WC, P)
    information = np.sum([f * Hk for f, Hk in zip(factors, H_k, strict=True)], axis=0)
    covariance = float((factors * squared).sum()) / dof * np.linalg.inv(information)
    return PositionAndPoints(p_WC, P, covariance, squared / _counts(S_list))


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


def joint_tls(S_list: list[np.ndarray]):
    """The paper's total least squares (Eq. (36), §3.1) for K points sharing one camera: the
    unknowns ``z = [vec R_WC; p_WC; p_HP_1; ...; p_HP_K; 1]`` (13 + 3K) and the sum of every point's
    Eq. (30) cost ``x_k^T S_k x_k`` (each ``x_k`` the camera's entries, point k's and the
    homogeneous one) as one quadratic form in ``z``, whose smallest eigenvector, projected onto
    SO(3) as one point's is, is the estimate. Beyond the paper: no point needs enough samples
    and views on its own (a track that ends every few seconds, a person walking between), only
    all of them together, and no starting guess is needed. Conditioned as one point's statistic
    is (``eye_to_hand.conditioning_transform`` of their sum: the pooled camera points centred and
    scaled; each ``p_HP`` as it is). Returns ``(R_WC, p_WC, p_HP)`` (``p_HP``: K x 3), or None
    when the rotation block of the eigenvector vanishes (the hand did not turn) or the solve is
    not finite. IdentificationError unless ``S_list`` is a non-empty list of finite 16 x 16
    statistics of at least one sample."""
    S_list = _statistics(S_list)
    K = len(S_list)
    if not K or not all(S[9, 9] > 0.0 for S in S_list):
        raise IdentificationError("joint_tls needs at least one statistic, each of one sample or more")
    n = 13 + 3 * K
    M, T_joint = np.zeros((n, n)), np.zeros((n, n))
    T = _conditioning_transform(np.sum(S_list, axis=0))
    for k, S in enumerate(S_list):
        idx = np.r_[0:12, 12 + 3 * k: 15 + 3 * k, n - 1]
        M[np.ix_(idx, idx)] += S
        T_joint[np.ix_(idx, idx)] = T  # the camera's and the homogeneous entries are shared
    with np.errstate(all="ignore"):
        _, vectors = np.linalg.eigh(T_joint.T @ M @ T_joint)
        z = T_joint @ vectors[:, 0]
        R, a, _, _ = _projection_parts(z[0:9])
        z = a * z
    if a == 0.0 or not np.all(np.isfinite(z)):
        return None
    return R, z[9:12].copy(), z[12:n - 1].reshape(K, 3).copy()


def spread_off_line(covariance: np.ndarray) -> float:
    """The RMS distance (m) of points from their principal line, from their 3 x 3 covariance:
    the root of its two smallest eigenvalues' sum (0 for points on a line). IdentificationError
    unless ``covariance`` is a finite 3 x 3 matrix."""
    return _spread_off_line(real_array("covariance", covariance, MATRIX3))


def _spread_off_line(covariance: np.ndarray) -> float:
    smallest = np.linalg.eigvalsh(covariance)[:2]
    return math.sqrt(max(float(smallest.sum()), 0.0))


# ---- several points at once from recorded data (batch.calibrate_eye_to_hand_points) --------------
# m^2 (1 um RMS): a point's residual variance below this is round-off (noise-free data); its weight
# in the joint fit is taken against at least this, so noise-free points weigh alike.
ROUND_OFF_VARIANCE = 1e-12


def _counts(S_list: list[np.ndarray]) -> np.ndarray:
    """The samples behind each statistic (A_t's p_WC block is I: ``S[9, 9]`` counts them)."""
    return np.array([float(S[9, 9]) for S in S_list])


def _positive_numbers(name: str, value, K: int) -> np.ndarray:
    """``value`` checked as K finite positive numbers (None: K ones)."""
    if value is None:
        return np.ones(K)
    a = real_array(name, value, (K,), what=f"{K} positive numbers")
    if not np.all(a > 0.0):
        raise IdentificationError(f"{name} must be {K} positive numbers, got {describe(value)}")
    return a


def _independent_shares(S_list: list[np.ndarray], independent) -> np.ndarray:
    """Per point, the share of its samples that count as independent: ``independent / samples``,
    at most 1 (``independent``: K positive numbers, None: all). ``m`` samples that carry one
    repeated error inform a covariance as one sample, not ``m``."""
    if independent is None:
        return np.ones(len(S_list))
    v = _positive_numbers("independent", independent, len(S_list))
    counts = _counts(S_list)
    return np.where(counts > 0.0, np.minimum(v / np.maximum(counts, 1e-300), 1.0), 1.0)


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
                     weights=None, points_known: bool = False,
                     independent=None) -> np.ndarray | None:  # fmt: skip
    """Gauss-Newton's covariance ``sigma^2 H^-1`` ((6 + 3K) x (6 + 3K)) of the joint fit of K points'
    raw statistics at the camera ``(R, p_WC)`` and the points ``p_HP`` (K x 3; the fit's optimum), in
    ``(omega, p_WC, p_HP_1, ..., p_HP_K)``: ``omega`` the camera's turn in its own frame (rad; the truth
    is ``R exp([omega x])``), positions in m. ``H = sum_k w_k J^T S_k J`` is ``refine_joint``'s normal
    matrix of the weighted statistics and ``sigma^2 = sum_k w_k x_k^T S_k x_k / (3 n - 6 - 3K)``
    (``n`` the samples of all points): with ``refine_joint_weighted``'s weights ``sigma^2`` is about
    1 and each point counts with its own noise; one point with weight 1 gives
    ``observability.eye_to_hand_covariance``. ``weights``: K positive numbers (None: all 1).
    ``points_known``: the ``p_HP`` are given, not fitted (``camera_given_points``): the camera's
    6 x 6 covariance alone, from its block of ``H``, with ``3 n - 6`` degrees of freedom.
    ``independent``: K positive numbers, each point's samples counted as independent ones (None:
    all; ``_independent_shares``): errors that repeat from sample to sample inform less than as many
    independent ones, so point k's statistic weighs ``independent_k / n_k`` in ``H``, ``sigma^2``
    and ``n``. None if
    the fit is undetermined or ``3 n <= 6 + 3K`` (``3 n <= 6``). IdentificationError unless
    ``S_list`` is a list of finite 16 x 16 statistics, ``R`` a rotation matrix, ``p_WC`` a finite
    3-vector, ``p_HP`` K finite points and ``weights`` and ``independent`` None or K finite
    positive numbers."""
    S_list = _statistics(S_list)
    K = len(S_list)
    R, p_WC, p_HP = rotation("R", R), real_array("p_WC", p_WC, VECTOR3), _points("p_HP", p_HP, K)
    w = _positive_numbers("weights", weights, K)
    factors = _independent_shares(S_list, independent)
    dof = 3.0 * float((factors * _counts(S_list)).sum()) - 6.0 - (0.0 if points_known else 3.0 * K)
    if not (K > 0 and dof > 0.0):
        return None
    weighted = [wk * fk * S for wk, fk, S in zip(w, factors, S_list, strict=True)]
    H, _ = _joint_normal_equations(weighted, R, p_WC, p_HP)
    H = H[:6, :6] if points_known else H
    try:
        inverse = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        return None
    sigma2 = float(_squared_errors(weighted, R, p_WC, p_HP).sum()) / dof
    covariance = sigma2 * (inverse + inverse.T) / 2.0
    if not (np.isfinite(covariance).all() and np.all(np.diagonal(covariance) >= 0.0)):
        return None
    return covariance
