"""Verdicts that degenerate or mis-scaled data cannot fool (beyond the paper; issue 25). Pure numpy.

The paper's criteria (a)-(c) read the eigenvalues of the statistic, and those can be fooled: with
every hand rotation about one axis, the direction that moves ``p_WC`` and ``p_HP`` together along
that axis enters no measurement, so ``lambda_16`` is exactly zero, the gap looks huge and ``v_N`` is
that direction plus noise: "converged", with a camera kilometres off. A left-handed camera frame
fits as well as a right-handed one (the rotation block comes out a reflection, and the sign fix of
§3.2 turns it into a rotation with ``x_16 = -1``); millimetres fit as well as metres. The checks
here read what the samples determine, from the statistic alone (so the streaming identifiers and
the batch API judge alike), at solve time: never in ``add``, and the costly ones only when (a)-(c)
say converged. A verdict applies them in this order:

1. Units (eye-to-hand): camera points whose RMS distance from the camera exceeds
   ``MAX_DEPTH_RANGE`` (20 m; depth cameras measure up to about 10 m) are not in metres; hand
   positions whose RMS distance from the world origin exceeds ``MAX_HAND_DISTANCE`` (100 m) or whose
   RMS spread exceeds ``MAX_WORKSPACE_SPREAD`` (5 m; an arm reaches a few metres at most) are not
   either. In millimetres they are a thousand times larger.
2. Excitation, independent of the noise. Eye-to-hand: the mean hand rotation ``M = mean R_WH``
   (``S[9:12, 12:15] = -sum R_WH``) gives, per hand-frame direction ``w``, the spread
   ``sqrt(1 - |M w|^2)`` (rad, about the RMS angle by which the rotations turn ``w``). A ``w`` the
   rotations leave fixed is their common axis, and the translation of ``p_WC`` and ``p_HP``
   together along it is undetermined: the smallest spread must be at least
   ``MIN_ROTATION_SPREAD`` (0.01 rad: a turn about a second axis smaller than that is within an
   arm's uncalibrated axis misalignments, 0.01-0.1 deg, so the translation along the axis would
   come from kinematic errors, not from the motion). Payload: gravity's direction in the sensor
   frame must turn (the centre of mass along it is otherwise undetermined): the RMS tilt
   ``sqrt(lambda_min(S[1:4, 1:4]) / S[0, 0])`` (``S[1:4, 1:4] = sum(|f|^2 I - f f^T)``) must be at
   least ``MIN_ROTATION_SPREAD`` and ``NOISE_MARGIN`` (3) times the tilt the force noise alone
   fakes, ``sqrt(2 n sigma_f^2 / sum |f|^2)`` (``sigma_f`` from the force rows' residual).
3. The paper's null-space and gap criteria (``sustainable_identifier.judge``).
4. Frame and scale (eye-to-hand): ``x_16`` of the TLS solution scaled by its rotation block
   (Eq. (21)) is the ratio of the hand's length unit to the camera's; it is 1 for consistent data
   (noise moves it by about the noise over the points' spread: 0.3-1.4 % on the real data set). A
   negative one with an expected RMS within criterion (a) means that a mirrored camera explains the
   samples: the camera frame is left-handed (or one axis is negated). One outside ``SCALE_RANGE``
   ([0.5, 2]: far from 1e-3 and 1e3, the ratios of millimetres and metres) means the units differ.
5. The paper's SSD and expected-RMS criteria.
6. The homogeneous coordinate of the conditioned unit ``v_N`` is at least ``MIN_HOMOGENEOUS``
   (1e-3). Conditioning makes every entry of a true solution of order one (that is its purpose),
   so its homogeneous entry is of order ``1/sqrt(N)`` (0.35-0.5 on the data here); below 1e-3
   (eye-to-hand: a tool point over 700 times the spread of the camera points from the hand)
   ``v_N`` is a direction no sample measures, mixed with the solution by noise or round-off.
7. Agreement (eye-to-hand): the RMS residual of the fit is within criterion (a) and at most
   ``AGREEMENT_FACTOR`` (3) times the TLS's expected RMS, plus ``AGREEMENT_FLOOR`` (1e-3) of
   criterion (a) for round-off (1.0-1.5 times on the real data set). The fit is the projected
   rotation with the translations that fit it best (``_ReducedCost``), or one Gauss-Newton step from
   it if that does not agree (the projection can be 0.1 rad off the optimum; one step comes within
   1 % of the optimum's residual on the data here). (The payload's estimate is the TLS solution
   itself: they agree by construction.)
8. Uncertainty, from Gauss-Newton's covariance ``sigma^2 (J^T S J)^-1`` at the fit (``sigma^2``
   the residual variance per axis). Eye-to-hand: the camera points must not lie on a line (the turn
   about it is undetermined): their RMS distance from their principal line is at least
   ``NOISE_MARGIN`` times what noise alone gives (``sqrt(2) sigma``) and ``LINE_FLOOR`` (1e-3) times
   their spread along it; the RMS errors of the camera position, of ``p_HP`` and of the camera
   rotation (times the points' RMS distance from the camera) are within criterion (a): an
   estimate less certain than the error allowed per sample is not identified. Payload: the centre
   of mass's RMS error is within ``MAX_COM_ERROR`` (10 mm).

A not-converged verdict's reason starts with one of the constants below (``REASONS``), then gives
the figures and what to do. The dynamic payload's checks (``payload_dynamic``) are in
``dynamic_observability``, with these reasons.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.linalg import lapack
from scipy.stats import chi2

from sustain_drake.identification.errors import (
    IdentificationError,
    integer,
    real_array,
    real_number,
    rotation,
)
from sustain_drake.identification.rotation import _rotation_jacobian, _so3_exp
from sustain_drake.identification.sustainable_identifier import ConvergenceCriteria, EigenSolution, Verdict

_MOTION = "motion not rich enough: "
NO_ROTATION = _MOTION + "the hand did not rotate"
ONE_AXIS = _MOTION + "the hand rotated about one axis only"
POINTS_ON_A_LINE = _MOTION + "the point moved along a line in the camera's view"
ONE_ORIENTATION = _MOTION + "one orientation of the payload"
UNDETERMINED = _MOTION + "the solution is a direction that no sample measures"
WEAKLY_DETERMINED = _MOTION + "the samples determine the estimate only weakly"
POINTS_NOT_IN_METRES = "the camera points are not in metres"
HAND_NOT_IN_METRES = "the hand positions are not in metres"
LEFT_HANDED = "the camera frame is left-handed"
SCALE_MISMATCH = "the camera points and the hand positions disagree in scale"
FIT_DISAGREES = "the fit's residuals disagree with the identification"
REASONS = (NO_ROTATION, ONE_AXIS, POINTS_ON_A_LINE, ONE_ORIENTATION, UNDETERMINED, WEAKLY_DETERMINED,
           POINTS_NOT_IN_METRES, HAND_NOT_IN_METRES, LEFT_HANDED, SCALE_MISMATCH,
           FIT_DISAGREES)  # fmt: skip

MAX_DEPTH_RANGE = 20.0  # m
MAX_HAND_DISTANCE = 100.0  # m
MAX_WORKSPACE_SPREAD = 5.0  # m
MIN_ROTATION_SPREAD = 0.01  # rad
NOISE_MARGIN = 3.0
SCALE_RANGE = (0.5, 2.0)
MIN_HOMOGENEOUS = 1e-3
AGREEMENT_FACTOR = 3.0
AGREEMENT_FLOOR = 1e-3
LINE_FLOOR = 1e-3
MAX_COM_ERROR = 0.01  # m


def region_95(dimensions: int) -> float:
    """The radius that holds 95 % of an isotropic normal error in ``dimensions`` dimensions, over the
    error's RMS (``sqrt(trace)`` of its covariance): ``sqrt(chi2_k(0.95) / k)`` (1.960 for one, 1.614
    for three, 1.449 for six). A 95 % region lies within a bound when this times the RMS does.
    IdentificationError unless ``dimensions`` is an integer >= 1."""
    k = integer("dimensions", dimensions, 1)
    return math.sqrt(float(chi2.ppf(0.95, k)) / k)


# region_95 for an effective number of dimensions from 1 to 16 (radius_95 interpolates)
_DIMENSIONS = np.linspace(1.0, 16.0, 301)
_REGION_95 = np.sqrt(chi2.ppf(0.95, _DIMENSIONS) / _DIMENSIONS)


def radius_95(covariance) -> float:
    """The radius that holds 95 % of a normal error of covariance ``covariance`` (k x k, k <= 16):
    ``|e|^2`` is a sum of chi-squares weighted by the eigenvalues ``l_i``, matched (Satterthwaite) by
    ``c chi2_nu`` with ``nu = (sum l_i)^2 / sum l_i^2``, so the radius is ``region_95(nu)`` times the
    RMS ``sqrt(sum l_i)``. An error that is large in one direction only is a one-dimensional one
    (1.96 times its RMS, where an isotropic 3-D one is 1.61). 0 for a zero covariance;
    IdentificationError unless it is a finite square matrix of at most 16 rows."""
    C = real_array("covariance", covariance, (None, None))
    if C.shape[0] != C.shape[1] or not 1 <= C.shape[0] <= 16:
        raise IdentificationError(f"covariance must be a square matrix of 1 to 16 rows, got {C.shape}")
    trace, square = float(np.trace(C)), float(np.sum(C * C))  # sum l_i, sum l_i^2 (C symmetric)
    if not trace > 0.0:
        return 0.0
    nu = min(max(trace * trace / square, 1.0), float(C.shape[0]))  # square > 0 as trace > 0
    return float(np.interp(nu, _DIMENSIONS, _REGION_95)) * math.sqrt(trace)


_AXIS_COS = math.cos(math.radians(10.0))  # an axis within 10 deg of a frame axis is named after it
# Flat indices in the 16 x 16 eye-to-hand statistic: sum c_x^2, c_y^2, c_z^2 (camera points),
# sum |p_WH|^2 and -sum p_WH (hand positions).
_UNITS_FLAT = np.ravel_multi_index(([0, 3, 6, 15, 9, 10, 11], [0, 3, 6, 15, 15, 15, 15]), (16, 16))
# Sums of c_x^2, c_y^2, c_z^2, c_x c_y, c_x c_z, c_y c_z, c_x, c_y, c_z (camera points).
_CAMERA_FLAT = np.ravel_multi_index(([0, 3, 6, 0, 0, 3, 0, 3, 6], [0, 3, 6, 3, 6, 6, 9, 9, 9]), (16, 16))


def _mm(metres: float) -> str:
    return f"{metres * 1e3:.3g} mm"


def _axis_text(v) -> str:
    """A direction in words: ``"z"`` within 10 deg of an axis of its frame, else its unit vector."""
    v = np.asarray(v, dtype=float)
    v = v / (np.linalg.norm(v) or 1.0)
    i = int(np.argmax(np.abs(v)))
    if v[i] < 0.0:
        v = -v
    if v[i] >= _AXIS_COS:
        return "xyz"[i]
    return f"({v[0]:.2f}, {v[1]:.2f}, {v[2]:.2f})"


def _sym3_eigenvalues(xx: float, yy: float, zz: float, xy: float, xz: float, yz: float):
    """The eigenvalues of a symmetric 3 x 3 matrix, ascending (the closed form, in Python floats:
    a tenth of a LAPACK call's cost; absolute error about 1e-16 of the matrix's norm)."""
    off = xy * xy + xz * xz + yz * yz
    q = (xx + yy + zz) / 3.0
    p2 = (xx - q) * (xx - q) + (yy - q) * (yy - q) + (zz - q) * (zz - q) + 2.0 * off
    if not p2 > 0.0:
        return sorted((xx, yy, zz))
    p = math.sqrt(p2 / 6.0)
    a, b, c = (xx - q) / p, (yy - q) / p, (zz - q) / p
    u, v, w = xy / p, xz / p, yz / p
    r = 0.5 * (a * (b * c - w * w) - u * (u * c - w * v) + v * (u * w - b * v))
    phi = math.acos(min(max(r, -1.0), 1.0)) / 3.0
    largest = q + 2.0 * p * math.cos(phi)
    smallest = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
    return smallest, 3.0 * q - largest - smallest, largest


# ---- eye-to-hand --------------------------------------------------------------------------------
def _common_axis(S: np.ndarray, weight: float) -> np.ndarray:
    """The world direction ``M w`` of the hand direction ``w`` the hand rotations turn least (``M``
    the mean hand rotation, ``w`` the eigenvector of the largest eigenvalue of ``M^T M``): the
    rotations' common axis when they have one. From the 16 x 16 statistic of ``weight`` samples."""
    M = S[9:12, 12:15] / -weight
    return M @ np.linalg.eigh(M.T @ M)[1][:, -1]


def _rotation_spread_bounds(S: np.ndarray, weight: float) -> tuple[float, float]:
    """The smallest and the largest over hand directions ``w`` of ``sqrt(1 - |M w|^2)`` (rad; ``M``
    the mean hand rotation, ``S[9:12, 12:15] = -sum R_WH``), in Python floats."""
    a, b, c, d, e, f, g, h, i = S[9:12, 12:15].ravel().tolist()  # -weight M, row-major
    k = 1.0 / (weight * weight)
    squares = _sym3_eigenvalues((a * a + d * d + g * g) * k, (b * b + e * e + h * h) * k,
                                (c * c + f * f + i * i) * k, (a * b + d * e + g * h) * k,
                                (a * c + d * f + g * i) * k, (b * c + e * f + h * i) * k)  # fmt: skip
    return math.sqrt(max(1.0 - squares[2], 0.0)), math.sqrt(max(1.0 - squares[0], 0.0))


def _units_problem(S: np.ndarray, weight: float) -> str | None:
    cxx, cyy, czz, pp, px, py, pz = S.take(_UNITS_FLAT).tolist()
    camera = math.sqrt(max(cxx + cyy + czz, 0.0) / weight)
    if not camera <= MAX_DEPTH_RANGE:
        return (f"{POINTS_NOT_IN_METRES} (RMS distance {camera:.4g} from the camera, where a depth camera "
                f"sees {MAX_DEPTH_RANGE:g} m at most: millimetres?): give them in metres")
    rms2 = max(pp, 0.0) / weight
    spread = math.sqrt(max(rms2 - (px * px + py * py + pz * pz) / (weight * weight), 0.0))
    if not (math.sqrt(rms2) <= MAX_HAND_DISTANCE and spread <= MAX_WORKSPACE_SPREAD):
        return (f"{HAND_NOT_IN_METRES} (RMS distance {math.sqrt(rms2):.4g} from the world origin, spread "
                f"{spread:.4g}, where an arm reaches a few metres: millimetres?): give them in metres")
    return None


def _rotation_problem(S: np.ndarray, weight: float) -> str | None:
    smallest, largest = _rotation_spread_bounds(S, weight)
    if not largest >= MIN_ROTATION_SPREAD:
        return (f"{NO_ROTATION} (pure translation, or the same pose repeated): rotate it about two "
                "different axes")
    if not smallest >= MIN_ROTATION_SPREAD:
        return f"{ONE_AXIS} (world {_axis_text(_common_axis(S, weight))}): rotate about another axis"
    return None


def _frame_problem(x16: float, expected_rms: float, criteria: ConvergenceCriteria) -> str | None:
    if not expected_rms <= criteria.max_expected_rms:
        return None
    if x16 < 0.0:
        return (f"{LEFT_HANDED} (or one axis negated: a mirrored camera fits the samples to "
                f"{_mm(expected_rms)} RMS): give the points in a right-handed frame (Drake/OpenCV: +x "
                "right, +y down, +z along the optical axis)")
    if not SCALE_RANGE[0] <= x16 <= SCALE_RANGE[1]:
        scale = f"{1.0 / x16:.3g}" if x16 else "inf"
        return (f"{SCALE_MISMATCH} (the samples fit with the points scaled by {scale}: millimetres "
                "against metres?): give both in metres")
    return None


_ROTATION_ROWS = np.r_[0:9, 15]  # r = [vec R_WC; 1]: the unknowns left with the translations eliminated
_B_FLAT = np.ravel_multi_index(np.ix_(np.arange(9, 15), _ROTATION_ROWS), (16, 16))
_RR_FLAT = np.ravel_multi_index(np.ix_(_ROTATION_ROWS, _ROTATION_ROWS), (16, 16))


class _ReducedCost(NamedTuple):
    """The geometric cost ``x^T S x`` with the translations ``t = (p_WC, p_HP)`` eliminated (they
    enter linearly): for ``r = [vec R_WC; 1]`` the best ``t`` is ``-S_tt^-1 B r`` (``B = S_tr``,
    6 x 10) and the cost left is ``r^T P r``, ``P = S_rr - B^T S_tt^-1 B`` (10 x 10). ``TB`` is
    ``S_tt^-1 B`` and ``T_diagonal`` the diagonal of ``S_tt^-1``."""

    P: np.ndarray
    TB: np.ndarray
    T_diagonal: np.ndarray

    def cost(self, R: np.ndarray) -> float:
        """The least ``x^T S x`` for the camera rotation ``R`` (the weighted sum of squares, m^2)."""
        r = _r(R)
        return max(float(r @ self.P @ r), 0.0)

    def step(self, R: np.ndarray) -> np.ndarray | None:
        """The camera rotation after one Gauss-Newton step from ``R`` (None if undetermined)."""
        J = _rotation_jacobian(R, np.zeros((10, 3)))
        PJ = self.P @ J
        inverse = _inverse3(J.T @ PJ)
        if inverse is None:
            return None
        return R @ _so3_exp(-(inverse @ (_r(R) @ PJ)))

    def errors(self, R: np.ndarray, sigma2: float) -> tuple[float, float, float] | None:
        """The RMS errors (1 sd of the 3-D error) of the camera rotation (rad), the camera position
        and ``p_HP`` (m) at ``R`` under Gauss-Newton's covariance ``sigma2 (J^T S J)^-1``, from its
        blocks: the rotation's is the inverse ``C`` of ``J_r^T P J_r``, the translations'
        ``S_tt^-1 + K C K^T`` with ``K = S_tt^-1 B J_r`` (None if the rotation is undetermined)."""
        J = _rotation_jacobian(R, np.zeros((10, 3)))
        C = _inverse3(J.T @ self.P @ J)
        if C is None:
            return None
        K = self.TB @ J
        d = (self.T_diagonal + ((K @ C) * K).sum(axis=1)).tolist()
        c = C.ravel().tolist()
        parts = (c[0] + c[4] + c[8], d[0] + d[1] + d[2], d[3] + d[4] + d[5])
        return tuple(math.sqrt(max(sigma2 * v, 0.0)) for v in parts)


def _r(R: np.ndarray) -> np.ndarray:
    r = np.empty(10)
    r[0:9] = R.ravel(order="F")
    r[9] = 1.0
    return r


def _reduced_cost(S: np.ndarray) -> _ReducedCost | None:
    """``_ReducedCost`` of the 16 x 16 eye-to-hand statistic ``S``; None if the translations are
    undetermined (``S_tt`` singular: the hand never turned, or about one axis only)."""
    factor, info = lapack.dpotrf(S[9:15, 9:15])
    if info != 0:
        return None
    B = S.take(_B_FLAT)
    TB, info = lapack.dpotrs(factor, B)
    T, info2 = lapack.dpotri(factor)
    if info != 0 or info2 != 0:
        return None
    return _ReducedCost(S.take(_RR_FLAT) - B.T @ TB, TB, np.diagonal(T).copy())


def eye_to_hand_standard_errors(S: np.ndarray, R: np.ndarray,
                                sigma2: float) -> tuple[float, float, float] | None:  # fmt: skip
    """1 sd (the RMS of the 3-D error) of the camera rotation (rad), the camera position and
    ``p_HP`` (m) of the eye-to-hand fit of the 16 x 16 statistic ``S`` at the camera rotation ``R``,
    for a noise of variance ``sigma2`` (m^2) per axis of each sample's residual: Gauss-Newton's
    covariance ``sigma2 (J^T S J)^-1``. None if the fit is undetermined. IdentificationError unless
    ``S`` is a finite 16 x 16 matrix, ``R`` a rotation and ``sigma2`` a finite number."""
    S, R = real_array("S", S, (16, 16)), rotation("R", R)
    sigma2 = real_number("sigma2", sigma2)
    reduced = _reduced_cost(S)
    return None if reduced is None else reduced.errors(R, sigma2)


def _inverse3(M: np.ndarray) -> np.ndarray | None:
    """The inverse of a symmetric positive definite 3 x 3 matrix (cofactors; None if not positive
    definite)."""
    a, b, c, _, d, e, _, _, f = M.ravel().tolist()
    A, B, C = d * f - e * e, c * e - b * f, b * e - c * d
    det = a * A + b * B + c * C
    if not (a > 0.0 and a * d - b * b > 0.0 and det > 0.0 and math.isfinite(det)):  # Sylvester
        return None
    k = 1.0 / det
    return np.array([[A * k, B * k, C * k], [B * k, (a * f - c * c) * k, (b * c - a * e) * k],
                     [C * k, (b * c - a * e) * k, (a * d - b * b) * k]])  # fmt: skip


def _fit_problem(S, weight, R, expected_rms, criteria: ConvergenceCriteria) -> str | None:
    reduced = _reduced_cost(S)
    if reduced is None:
        return f"{UNDETERMINED} (the translations): rotate the hand about two different axes"
    bound = criteria.max_expected_rms
    limit = min(bound, AGREEMENT_FACTOR * expected_rms + AGREEMENT_FLOOR * bound)
    sse = reduced.cost(R)
    if not sse <= limit * limit * weight:  # the projected rotation does not agree: one step closer
        R = reduced.step(R)
        sse = reduced.cost(R) if R is not None else math.inf
    fit_rms = math.sqrt(sse / weight)
    if not fit_rms <= limit:
        return (f"{FIT_DISAGREES} (residuals {_mm(fit_rms)} RMS where it expected {_mm(expected_rms)}): "
                "are the points in metres, the camera frame right-handed and each point paired with its "
                "own pose?")
    sigma2 = sse / max(3.0 * weight - 9.0, 1.0)  # per axis
    xx, yy, zz, xy, xz, yz, mx, my, mz = (v / weight for v in S.take(_CAMERA_FLAT).tolist())
    eig = _sym3_eigenvalues(xx - mx * mx, yy - my * my, zz - mz * mz,
                            xy - mx * my, xz - mx * mz, yz - my * mz)  # the points' covariance
    off, along = math.sqrt(max(eig[0] + eig[1], 0.0)), math.sqrt(max(eig[2], 0.0))
    if not (off >= NOISE_MARGIN * math.sqrt(2.0 * sigma2) and off >= LINE_FLOOR * along):
        return (f"{POINTS_ON_A_LINE} ({_mm(off)} RMS off it, {_mm(along)} along it): move the hand so that "
                "the point sweeps an area of the view")
    errors = reduced.errors(R, sigma2)
    lever = math.sqrt(max(xx + yy + zz, 0.0))
    if errors is None or not max(errors[0] * lever, errors[1], errors[2]) <= bound:
        figures = "undetermined" if errors is None else (
            f"1 sd: camera position {_mm(errors[1])}, tool point {_mm(errors[2])}, camera rotation "
            f"{math.degrees(errors[0]):.2g} deg ({_mm(errors[0] * lever)} at the points), over the "
            f"{_mm(bound)} allowed")
        return (f"{WEAKLY_DETERMINED} ({figures}): rotate the hand more widely about two axes, take more "
                "samples")
    return None


def _homogeneous_problem(h: float, advice: str) -> str | None:
    if abs(h) >= MIN_HOMOGENEOUS:
        return None
    return f"{UNDETERMINED} (its homogeneous coordinate is {abs(h):.2g} < {MIN_HOMOGENEOUS:g}): {advice}"


def _guarded(judge_fn):
    """``judge_fn`` returning its ``verdict`` argument (the last) not converged when the statistic's
    magnitudes are absurd (Python floats raise on overflow or a zero divisor: NaN never converges)."""

    def guarded(*args) -> Verdict:
        try:
            return judge_fn(*args)
        except (ArithmeticError, ValueError):
            verdict = args[-1]
            return verdict if not verdict.converged else Verdict(False, "statistic is not finite (overflow)")

    guarded.__doc__ = judge_fn.__doc__
    return guarded


@_guarded
def _judge_eye_to_hand(criteria: ConvergenceCriteria, S: np.ndarray, weight: float, num_samples: int,
                       eigen: EigenSolution | None, tls: tuple | None, verdict: Verdict) -> Verdict:
    """``verdict`` (the paper's criteria, from ``judge``) with the checks of the module docstring
    applied around it, for the eye-to-hand statistic ``S`` of ``weight`` (``num_samples``)
    samples, its eigen-solution and ``tls = (x, R, expected_rms)``: the TLS solution scaled by its
    rotation block, the projected rotation and ``sqrt(a^2 lambda_N)`` (None if the rotation block
    is zero). Internal (the identifier's solve)."""
    if eigen is None or num_samples < criteria.min_samples or not weight > 0.0:
        return verdict
    reason = _units_problem(S, weight) or _rotation_problem(S, weight)
    determined = eigen.num_null < 2 and eigen.gap_ratio >= criteria.min_gap_ratio  # (b)
    if reason is None and tls is not None and determined:
        x, R, expected_rms = tls
        reason = _frame_problem(float(x[15]), expected_rms, criteria)
        if reason is None and verdict.converged:
            reason = (_homogeneous_problem(float(eigen.v_N[15]), "rotate the hand about two different axes")
                      or _fit_problem(S, weight, R, expected_rms, criteria))
    return verdict if reason is None else Verdict(False, reason)


# ---- payload ------------------------------------------------------------------------------------
@_guarded
def _judge_payload(criteria: ConvergenceCriteria, S: np.ndarray, weight: float, num_samples: int,
                   eigen: EigenSolution | None, x: np.ndarray, g_W: np.ndarray, verdict: Verdict) -> Verdict:
    """``verdict`` with the payload's checks (module docstring) for the 5 x 5 statistic ``S`` of
    ``weight`` (``num_samples``) samples, its eigen-solution and the solution ``x = [1/m; p_KCm;
    1]`` (zeros if there is none) under gravity ``g_W``. Internal (the identifier's solve)."""
    if eigen is None or num_samples < criteria.min_samples or not weight > 0.0:
        return verdict
    inv_m = float(x[0])
    f2, xx, xy, xz, yy, yz, zz = S.take(_PAYLOAD_FLAT).tolist()  # f2 = sum |f|^2
    lowest = _sym3_eigenvalues(xx, yy, zz, xy, xz, yz)[0]
    tilt = math.sqrt(max(lowest, 0.0) / f2) if f2 > 0.0 else 0.0
    noise_tilt = sse_force = 0.0
    if inv_m > 0.0 and math.isfinite(inv_m) and f2 > 0.0:
        sse_force = _force_sse(S, weight, inv_m, g_W)
        sigma_f2 = sse_force / (inv_m * inv_m * max(3.0 * weight - 1.0, 1.0))  # N^2 per axis
        noise_tilt = math.sqrt(2.0 * weight * sigma_f2 / f2)
    if not tilt >= max(MIN_ROTATION_SPREAD, NOISE_MARGIN * noise_tilt):
        axis = _axis_text(np.linalg.eigh(S[1:4, 1:4])[1][:, 0])
        return Verdict(False, f"{ONE_ORIENTATION} (gravity stayed along {axis} in the sensor frame, tilting "
                              f"{tilt:.2g} rad RMS: one rest, or turns about the vertical only): tilt it")
    if not verdict.converged:
        return verdict
    reason = _homogeneous_problem(float(eigen.v_N[4]), "tilt the payload")
    if reason is None:
        sigma_t2 = max(float(x @ S @ x) - sse_force, 0.0) / max(3.0 * weight - 3.0, 1.0)  # (N m)^2 per axis
        # trace of the inverse of S[1:4, 1:4]: its principal 2 x 2 minors over its determinant
        minors = (yy * zz - yz * yz) + (xx * zz - xz * xz) + (xx * yy - xy * xy)
        det = xx * (yy * zz - yz * yz) - xy * (xy * zz - yz * xz) + xz * (xy * yz - yy * xz)
        com_error = math.sqrt(sigma_t2 * minors / det) if det > 0.0 and minors > 0.0 else math.inf
        if not com_error <= MAX_COM_ERROR:
            reason = (f"{WEAKLY_DETERMINED} (1 sd: centre of mass {_mm(com_error)}, over the "
                      f"{_mm(MAX_COM_ERROR)} allowed): tilt the payload more widely, take more samples")
    return verdict if reason is None else Verdict(False, reason)


# Flat indices in the 5 x 5 payload statistic: sum |f|^2 and S[1:4, 1:4]'s six entries.
_PAYLOAD_FLAT = np.ravel_multi_index(([0, 1, 1, 1, 2, 2, 3], [0, 1, 2, 3, 2, 3, 3]), (5, 5))


# ---- covariances of the batch results (item 3 of issue 25) -----------------------------------------
def eye_to_hand_covariance(S: np.ndarray, R: np.ndarray) -> np.ndarray | None:
    """Gauss-Newton's covariance ``sigma^2 (J^T S J)^-1`` (9 x 9) of the eye-to-hand fit at the camera
    rotation ``R`` (the refined estimate's), in ``(omega, p_WC, p_HP)``: ``omega`` the camera's turn
    in its own frame (rad; the truth is ``R exp([omega x])``), the positions in m. ``sigma^2`` is the
    residual variance per axis of the fit at ``R`` (its sum of squares over ``3 n - 9``, ``n`` the
    samples' weight ``S[9, 9]``). None if the translations or the rotation are undetermined or
    ``n <= 3``. IdentificationError unless ``S`` is a finite 16 x 16 matrix and ``R`` a rotation."""
    S = real_array("S", S, (16, 16))
    R = rotation("R", R)
    reduced = _reduced_cost(S)
    weight = float(S[9, 9])
    if reduced is None or not weight > 3.0:
        return None
    J = _rotation_jacobian(R, np.zeros((16, 9)))
    J[9:15, 3:9] = np.eye(6)
    try:
        inverse = np.linalg.inv(J.T @ S @ J)
    except np.linalg.LinAlgError:
        return None
    covariance = reduced.cost(R) / (3.0 * weight - 9.0) * (inverse + inverse.T) / 2.0
    return covariance if np.isfinite(covariance).all() else None


def payload_covariance(S: np.ndarray, weight: float, x: np.ndarray, g_W: np.ndarray) -> np.ndarray | None:
    """The covariance (4 x 4) of ``(mass, p_KCm)`` (kg, m) for the 5 x 5 payload statistic ``S`` of
    ``weight`` samples and its solution ``x = [1/m; p_KCm; 1]`` under gravity ``g_W``: the force rows
    determine ``1/m`` (variance ``sigma_f^2 / S[0, 0]``, ``sigma_f^2`` their residual variance per
    axis, over ``3 n - 1``; the mass's by ``dm = -m^2 d(1/m)``), the torque rows ``p_KCm``
    (``sigma_t^2 S[1:4, 1:4]^-1``, over ``3 n - 3``); the blocks are independent (``S[0, 1:4] = 0``).
    None without a positive ``1/m``, with ``p_KCm`` undetermined or ``weight <= 1``.
    IdentificationError unless ``S`` is a finite 5 x 5 matrix, ``weight`` a number, ``x`` a finite
    5-vector and ``g_W`` a finite 3-vector."""
    S, x, g_W = real_array("S", S, (5, 5)), real_array("x", x, (5,)), real_array("g_W", g_W, (3,))
    weight = real_number("weight", weight)
    inv_m, f2 = float(x[0]), float(S[0, 0])
    if not (inv_m > 0.0 and f2 > 0.0 and weight > 1.0):
        return None
    sse_force = _force_sse(S, weight, inv_m, g_W)
    sse_torque = max(float(x @ S @ x) - sse_force, 0.0)
    try:
        com = np.linalg.inv(S[1:4, 1:4]) * (sse_torque / (3.0 * weight - 3.0))
    except np.linalg.LinAlgError:
        return None
    covariance = np.zeros((4, 4))
    covariance[0, 0] = sse_force / (3.0 * weight - 1.0) / f2 / (inv_m * inv_m) / (inv_m * inv_m)
    covariance[1:4, 1:4] = (com + com.T) / 2.0
    return covariance if np.isfinite(covariance).all() else None


def _force_sse(S: np.ndarray, weight: float, inv_m: float, g_W: np.ndarray) -> float:
    """The force rows' sum of squares ``sum |R f / m + g_W|^2`` (m/s^2)^2 from the payload statistic."""
    return max(inv_m * inv_m * float(S[0, 0]) + 2.0 * inv_m * float(S[0, 4]) + weight * float(g_W @ g_W), 0.0)
