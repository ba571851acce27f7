"""One-point eye-to-hand calibration (paper §3.4, Eqs. (30)-(36)), N = 16, M = 3.

A point P fixed on the hand (or on a held tool) is seen by a camera C that is fixed in the world W::

    R_WC p_CP + p_WC = R_WH p_HP + p_WH                                     (Eq. (30))

which is linear in ``x = [gamma_1; gamma_2; gamma_3; p_WC; p_HP; 1]`` (``R_WC = [gamma_1 gamma_2
gamma_3]``, columns) with::

    A_t = [c_x E, c_y E, c_z E, E, -R_WH, -p_WH]                               (Eq. (35))

where ``p_CP = (c_x, c_y, c_z)`` is measured by the depth camera and ``X_WH`` comes from forward
kinematics. All lengths are in metres; ``s_t = ||A_t x||^2`` is a squared distance in m^2.

Beyond the paper:
- conditioning (Hartley-style): the camera points are centred on their running mean and scaled by
  their RMS spread, and the hand positions centred on theirs, through a transform ``T`` applied at
  solve time (see ``conditioning_transform``), which removes the 10-18 mm bias of plain TLS on
  real data;
- the sign of ``v_N`` and a proper rotation (§3.2, see ``rotation.project_to_rotation``);
- a Gauss-Newton refinement on SO(3) x R^3 x R^3 of the geometric cost
  ``sum ||R_WC p_CP + p_WC - R_WH p_HP - p_WH||^2 = x^T S x``, run from the statistic alone.

Every public function and method raises ``IdentificationError`` (a ``ValueError``, see ``errors``)
with a one-line message for an argument of the wrong type, shape or value.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from sustain_drake.identification.errors import (
    F64,
    MATRIX3,
    VECTOR3,
    flag,
    homogeneous_transform,
    instance,
    integer,
    is_rotation,
    not_a_rotation,
    out_array,
    real_array,
    real_number,
    rotation,
)
from sustain_drake.identification.observability import _judge_eye_to_hand
from sustain_drake.identification.rotation import (
    _nearest_rotation,
    _projection_parts,
    _rotation_jacobian,
    _so3_exp,
)
from sustain_drake.identification.sustainable_identifier import (
    ConvergenceCriteria,
    EigenSolution,
    FormulationIdentifier,
    IdentificationError,
    SolutionProperties,
    Verdict,
    judge,
)

N_UNKNOWNS = 16
M_ROWS = 3
_S_SHAPE = (N_UNKNOWNS, N_UNKNOWNS)

# Index arrays that write [c_x E, c_y E, c_z E, E] into A_t[:, 0:12] without np.kron.
_ROWS = np.tile(np.arange(3), 4)
_COLS = np.arange(12)


def default_criteria() -> ConvergenceCriteria:
    """Defaults for eye-to-hand: expected RMS <= 10 mm, gap >= 10, SSD <= 0.1 (the paper's),
    at least 10 samples."""
    return ConvergenceCriteria(max_expected_rms=0.010, min_gap_ratio=10.0, max_ssd=0.1, min_samples=10)


@dataclass(frozen=True, slots=True)
class EyeToHandEstimate:
    """One estimate of the eye-to-hand model.

    Attributes:
        R_WC: rotation of the camera in the world (3 x 3, det +1).
        p_WC: position of the camera in the world, metres.
        p_HP: the tracked point in the hand frame, metres.
        x: the 16-vector of Eq. (36) (last entry 1 for the refined estimate).
        mean_squared_error: the mean of ``s_t`` over the samples under this estimate, m^2.
    """

    R_WC: np.ndarray
    p_WC: np.ndarray
    p_HP: np.ndarray
    x: np.ndarray
    mean_squared_error: float

    @property
    def X_WC(self) -> np.ndarray:
        """The 4 x 4 pose of the camera in the world."""
        return _pose(self.R_WC, self.p_WC)

    @property
    def rms(self) -> float:
        """Root mean squared per-sample error, metres."""
        return math.sqrt(max(self.mean_squared_error, 0.0))


@dataclass(frozen=True, slots=True)
class EyeToHandSolution(SolutionProperties):
    """Everything one solve gives.

    Attributes:
        eigen: the eigen-decomposition of the conditioned statistic (None before any sample).
        scale: ``a`` of Eq. (21), mapping the conditioned ``v_N`` to ``x``.
        ssd: the §3.2 closeness of the rotation block to a rotation.
        expected_mse: ``a^2 lambda_N`` (Eq. (13)), m^2.
        projected: the TLS estimate projected onto SO(3) (§3.2).
        refined: the Gauss-Newton refinement of ``projected`` (None if not asked for).
        verdict: the convergence verdict from all three criteria.
        num_samples: samples behind this solution.
        refinement: 0 for an identification; counts the refinements of an adopted model in
            OBSERVE (``coordination.CoordinationRule.adopt_refinements``).
    """

    num_unknowns: ClassVar[int] = N_UNKNOWNS

    eigen: EigenSolution | None
    scale: float
    ssd: float
    expected_mse: float
    projected: EyeToHandEstimate | None
    refined: EyeToHandEstimate | None
    verdict: Verdict
    num_samples: int
    refinement: int = 0

    @property
    def estimate(self) -> EyeToHandEstimate | None:
        """The best estimate available: the refined one if computed, else the projected one."""
        return self.refined if self.refined is not None else self.projected

    @property
    def x(self) -> np.ndarray:
        """The best estimate's 16-vector (zeros when there is none)."""
        est = self.estimate
        return est.x if est is not None else np.zeros(N_UNKNOWNS)


def build_A(p_CP: np.ndarray, R_WH: np.ndarray, p_WH: np.ndarray, out: np.ndarray | None = None):
    """``A_t`` of Eq. (35) (3 x 16) for one sample (written into ``out``, a float64 3 x 16 array
    built by an earlier call, if given). IdentificationError unless ``p_CP``, ``R_WH``, ``p_WH`` are
    a real 3-vector, 3 x 3 matrix and 3-vector (NaN and inf are copied as they are)."""
    p_CP = real_array("p_CP", p_CP, VECTOR3, finite=False)
    R_WH = real_array("R_WH", R_WH, MATRIX3, finite=False)
    p_WH = real_array("p_WH", p_WH, VECTOR3, finite=False)
    out = out_array("out", out, (M_ROWS, N_UNKNOWNS))
    A = np.zeros((M_ROWS, N_UNKNOWNS)) if out is None else out
    cx, cy, cz = p_CP[0], p_CP[1], p_CP[2]
    A[_ROWS, _COLS] = (cx, cx, cx, cy, cy, cy, cz, cz, cz, 1.0, 1.0, 1.0)
    A[:, 12:15] = -R_WH
    A[:, 15] = -p_WH
    return A


def predicted_points(estimate: EyeToHandEstimate, X_WH) -> np.ndarray:
    """Eq. (30) solved for the point: ``p_CP = R_WC^T (R_WH p_HP + p_WH - p_WC)`` (k x 3, m) at each
    hand pose of ``X_WH`` (k x 4 x 4) under ``estimate``. IdentificationError unless ``estimate`` is
    an EyeToHandEstimate and ``X_WH`` real 4 x 4 matrices."""
    estimate = instance("estimate", estimate, EyeToHandEstimate, "an EyeToHandEstimate")
    X_WH = real_array("X_WH", X_WH, (None, 4, 4), what="hand poses (k x 4 x 4)")
    p_WP = X_WH[:, :3, :3] @ estimate.p_HP + X_WH[:, :3, 3]
    return (p_WP - estimate.p_WC) @ estimate.R_WC


def path_information(state: np.ndarray, paths) -> tuple[np.ndarray, list[np.ndarray]]:
    """The information ``M`` the statistic holds on the unknowns ``[vec R_WC; p_WC; p_HP]`` (S's block
    over every entry of x but the homogeneous one) and, for each candidate motion, the information
    ``dM = sum_k w_k Phi_k^T Phi_k`` its samples add (``identification.excitation``; issue 25), with
    ``Phi_k`` the unknowns' columns of ``A_t`` (Eq. (35)) at its k-th sample.

    ``state`` is an ``EyeToHandIdentifier``'s state ``[S (256) | n_eff | count]``; each path is
    ``(p_CP, X_WH, w)``: the points predicted along the motion (k x 3, m; ``predicted_points``), the
    hand poses there (k x 4 x 4) and the samples each stands for (k, >= 0). IdentificationError
    unless ``paths`` is a list of such triples of real arrays."""
    n2 = N_UNKNOWNS * N_UNKNOWNS
    state = real_array("state", state, (n2 + 2,))
    what = "paths must be a list of (p_CP, X_WH, w) triples"
    if isinstance(paths, (str, bytes, dict)) or not hasattr(paths, "__iter__"):
        raise IdentificationError(f"{what}, got {type(paths).__name__}")
    unknowns = N_UNKNOWNS - 1
    added = []
    for path in paths:
        if not (isinstance(path, (tuple, list)) and len(path) == 3):
            raise IdentificationError(f"{what}, got an element of type {type(path).__name__}")
        p_CP, X_WH, w = path
        X_WH = real_array("X_WH", X_WH, (None, 4, 4), what="hand poses (k x 4 x 4)")
        k = X_WH.shape[0]
        p_CP = real_array("p_CP", p_CP, (k, 3))
        w = real_array("w", w, (k,))
        if not np.all(w >= 0.0):
            raise IdentificationError("the samples per pose w must be >= 0")
        Phi = np.zeros((k, M_ROWS, unknowns))
        for i in range(3):  # the c_i E blocks, then E, -R_WH (Eq. (35))
            Phi[:, [0, 1, 2], [3 * i, 3 * i + 1, 3 * i + 2]] = p_CP[:, [i]]
        Phi[:, [0, 1, 2], [9, 10, 11]] = 1.0
        Phi[:, :, 12:15] = -X_WH[:, :3, :3]
        added.append(np.einsum("k,kri,krj->ij", w, Phi, Phi))
    S = state[:n2].reshape(N_UNKNOWNS, N_UNKNOWNS)
    return S[:unknowns, :unknowns].copy(), added


def pack_x(R_WC: np.ndarray, p_WC: np.ndarray, p_HP: np.ndarray) -> np.ndarray:
    """Eq. (36): ``x = [vec(R_WC); p_WC; p_HP; 1]`` (``vec`` stacks the columns). IdentificationError
    unless the arguments are a real 3 x 3 matrix and two real 3-vectors."""
    R_WC = real_array("R_WC", R_WC, MATRIX3, finite=False)
    p_WC = real_array("p_WC", p_WC, VECTOR3, finite=False)
    p_HP = real_array("p_HP", p_HP, VECTOR3, finite=False)
    return _pack_x(R_WC, p_WC, p_HP)


def _pack_x(R_WC: np.ndarray, p_WC: np.ndarray, p_HP: np.ndarray) -> np.ndarray:
    return np.concatenate([R_WC.reshape(9, order="F"), p_WC, p_HP, [1.0]])


def conditioning_transform(S: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``T`` with ``x = T x'`` such that ``A_t x = s A'_t x'`` for the normalised sample
    ``A'_t = [c' E ..., E, -R_WH, -p'_WH]`` with ``c' = (p_CP - c_mean)/s`` and
    ``p'_WH = (p_WH - p_mean)/s``, ``s`` the RMS spread of the camera points about their mean.

    In the normalised unknowns ``x' = [gamma; t'; p'_HP; 1]`` every entry is of order one
    (``t' = (R_WC c_mean + p_WC - p_mean)/s``, ``p'_HP = p_HP/s``), which is what makes TLS's unit
    norm a fair normalisation. The ``1/s`` is folded into ``T`` so that ``x = a T v'`` has expected
    mean squared error ``a^2 lambda'_N`` in m^2.

    The running sums it needs are entries of the statistic itself (no extra memory): with
    ``S = sum A_t^T A_t``, ``S[9,9] = n``, ``S[0,9], S[3,9], S[6,9] = sum p_CP``,
    ``S[0,0] + S[3,3] + S[6,6] = sum |p_CP|^2`` and ``S[9:12, 15] = -sum p_WH``.

    IdentificationError unless ``S`` is a finite 16 x 16 statistic of at least one sample
    (``S[9, 9] > 0``) and ``out`` None or a writable float64 16 x 16 array.
    """
    S = real_array("S", S, (N_UNKNOWNS, N_UNKNOWNS))
    if not S[9, 9] > 0.0:
        raise IdentificationError(f"S must hold a sample (S[9, 9] > 0), got S[9, 9] = {S[9, 9]:.3g}")
    out = out_array("out", out, (N_UNKNOWNS, N_UNKNOWNS))
    return _conditioning_transform(S, out)


def _conditioning_transform(S: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``conditioning_transform`` unchecked (every solve)."""
    # Python floats: the same IEEE arithmetic as numpy scalars, at a fraction of the call cost
    # (numpy scalars when n = 0, which give NaN rather than raise).
    sums = S.take(_SUMS_FLAT)
    n, sx, sy, sz, sxx, syy, szz, mpx, mpy, mpz = sums.tolist() if sums[0] != 0.0 else sums
    cx, cy, cz = sx / n, sy / n, sz / n
    spread2 = (sxx + syy + szz) / n - (cx * cx + cy * cy + cz * cz)
    s = math.sqrt(spread2) if spread2 > 1e-18 else 1.0
    T = np.zeros((N_UNKNOWNS, N_UNKNOWNS)) if out is None else out
    k = 1.0 / s
    # Diagonal: gamma / s, t' and p'_HP unscaled, h / s. Then p_WC = s t' - R_WC c_mean + p_mean h
    # (all over s), with R_WC c_mean = [c_x E, c_y E, c_z E] gamma.
    mx, my, mz = -cx * k, -cy * k, -cz * k
    q = -k / n
    T.put(_T_FLAT, [k, k, k, k, k, k, k, k, k, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, k,
                    mx, mx, mx, my, my, my, mz, mz, mz,
                    mpx * q, mpy * q, mpz * q])  # fmt: skip
    return T


# Flat indices in S of the sums ``conditioning_transform`` reads (n, sum p_CP, the sums of c_x^2,
# c_y^2, c_z^2, -sum p_WH).
_SUMS_FLAT = np.ravel_multi_index(
    ([9, 0, 3, 6, 0, 3, 6, 9, 10, 11], [9, 9, 9, 9, 0, 3, 6, 15, 15, 15]), (N_UNKNOWNS, N_UNKNOWNS)
)


# Flat indices of T's variable entries: the diagonal, the -c_mean block, the p_mean column.
_T_FLAT = np.concatenate(
    [
        np.arange(N_UNKNOWNS) * (N_UNKNOWNS + 1),
        (np.tile(np.arange(3), 3) + 9) * N_UNKNOWNS + np.arange(9),
        np.arange(9, 12) * N_UNKNOWNS + 15,
    ]
)


_SMALL_STEP = 1e-6  # radians / metres


def refine(
    S: np.ndarray,
    weight: float,
    R: np.ndarray,
    p_WC: np.ndarray,
    p_HP: np.ndarray,
    max_iterations: int = 30,
    tolerance: float = 1e-12,
) -> EyeToHandEstimate:
    """Gauss-Newton on SO(3) x R^3 x R^3 of ``J = x^T S x`` (the geometric least-squares cost
    ``sum ||R_WC p_CP + p_WC - R_WH p_HP - p_WH||^2``), from the statistic alone.

    ``x`` is linear in the translations and ``A_t x`` is linear in ``x``, so linearising ``x`` in
    the rotation perturbation gives the Gauss-Newton step exactly. It stops when a step is below
    ``tolerance`` (radians and metres). Far from the optimum, a step that would increase the cost is
    halved (at most 10 times); steps below 1e-6 are taken in full.

    IdentificationError unless ``S`` is a finite 16 x 16 matrix, ``weight`` a positive number,
    ``R`` a rotation matrix, ``p_WC`` and ``p_HP`` finite 3-vectors, ``max_iterations`` an integer
    >= 0 and ``tolerance`` a number >= 0.
    """
    # The usual call (float64 arrays, Python numbers, a rotation) runs at once: NaN or inf in S or
    # the points give a NaN cost, checked after the run (checks before it slow it down by more
    # than their own cost).
    if (type(S) is np.ndarray and S.dtype is F64 and S.shape == _S_SHAPE and type(R) is np.ndarray
            and R.dtype is F64 and R.shape == MATRIX3 and type(p_WC) is np.ndarray and p_WC.dtype is F64
            and p_WC.shape == VECTOR3 and type(p_HP) is np.ndarray and p_HP.dtype is F64
            and p_HP.shape == VECTOR3 and type(weight) is float and 0.0 < weight < math.inf
            and type(max_iterations) is int and max_iterations >= 0 and type(tolerance) is float
            and tolerance >= 0.0 and is_rotation(R.tolist())):  # fmt: skip
        try:
            estimate = _gauss_newton(S, weight, R, p_WC, p_HP, max_iterations, tolerance)
        except np.linalg.LinAlgError:  # only for NaN or inf in S
            estimate = None
        if estimate is not None and math.isfinite(estimate.mean_squared_error):
            return estimate
    S = real_array("S", S, _S_SHAPE)
    weight = real_number("weight", weight, what="a positive number")
    if not weight > 0.0:
        raise IdentificationError(f"weight must be a positive number, got {weight}")
    R = rotation("R", R)
    p_WC, p_HP = real_array("p_WC", p_WC, VECTOR3), real_array("p_HP", p_HP, VECTOR3)
    max_iterations = integer("max_iterations", max_iterations, 0)
    tolerance = real_number("tolerance", tolerance, finite=False, what="a number >= 0")
    if not tolerance >= 0.0:
        raise IdentificationError(f"tolerance must be a number >= 0, got {tolerance}")
    try:
        return _gauss_newton(S, weight, R, p_WC, p_HP, max_iterations, tolerance)
    except np.linalg.LinAlgError:
        raise IdentificationError("S gives singular normal equations that cannot be solved") from None


def _gauss_newton(S: np.ndarray, weight: float, R: np.ndarray, p_WC: np.ndarray, p_HP: np.ndarray,
                  max_iterations: int = 30, tolerance: float = 1e-12) -> EyeToHandEstimate:
    """``refine`` unchecked (the identifier's own solves)."""
    x = _pack_x(R, p_WC, p_HP)
    cost = float(x @ S @ x)
    J = np.zeros((N_UNKNOWNS, 9))
    J[9:15, 3:9] = np.eye(6)
    for _ in range(max_iterations):
        _rotation_jacobian(R, J)
        H = J.T @ S @ J
        g = J.T @ (S @ x)
        try:
            delta = -np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            delta = -np.linalg.lstsq(H, g, rcond=None)[0]
        size = np.abs(delta).max()
        # A step of a million metres (or radians) only comes from a singular H: degenerate data.
        if not size < 1e6:
            break
        # Trust region on the rotation: a step beyond pi radians is meaningless on SO(3) (and only
        # happens on degenerate data, where H is singular).
        omega = math.sqrt(delta[0:3] @ delta[0:3])
        step = 1.0 if omega <= math.pi else math.pi / omega
        if size < _SMALL_STEP:
            # Near the optimum the cost's change is below its own round-off (x^T S x is a sum of
            # large terms that cancel), so a cost test cannot judge the step; Gauss-Newton's full
            # step is reliable there.
            R = R @ _so3_exp(delta[0:3])
            p_WC, p_HP = p_WC + delta[3:6], p_HP + delta[6:9]
            x = _pack_x(R, p_WC, p_HP)
            cost = float(x @ S @ x)
            if size < tolerance:
                break
            continue
        for _ in range(10):
            R_new = R @ _so3_exp(step * delta[0:3])
            p_WC_new = p_WC + step * delta[3:6]
            p_HP_new = p_HP + step * delta[6:9]
            x_new = _pack_x(R_new, p_WC_new, p_HP_new)
            cost_new = float(x_new @ S @ x_new)
            if cost_new <= cost:
                break
            step *= 0.5
        else:
            break  # no decrease along the Gauss-Newton direction: at the optimum (to round-off)
        R, p_WC, p_HP, x, cost = R_new, p_WC_new, p_HP_new, x_new, cost_new
    R = _nearest_rotation(R)  # against drift from many small products (no effect on the cost)
    x = _pack_x(R, p_WC, p_HP)
    return EyeToHandEstimate(
        R_WC=R,
        p_WC=p_WC.copy(),
        p_HP=p_HP.copy(),
        x=x,
        mean_squared_error=float(x @ S @ x) / weight,
    )


def _pose(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    X = np.zeros((4, 4))
    X[:3, :3] = R
    X[:3, 3] = p
    X[3, 3] = 1.0
    return X


# A sample whose camera point and hand position have a squared norm sum below this has entries
# below 1e100 (|R_WH| <= 1), so A^T A and its sum cannot overflow (the core's fast-path bound).
_SMALL_SAMPLE = 1e200


class EyeToHandIdentifier(FormulationIdentifier):
    """The sustainable identifier with the eye-to-hand formulation: add samples one at a time
    (O(1) memory), solve at any time.

    Args:
        forgetting_factor: see ``SustainableIdentifier`` (1 = the paper's plain mean).
        criteria: convergence criteria (``default_criteria()`` if None).

    Every method raises IdentificationError for an argument of the wrong type, shape or value.
    """

    def __init__(self, forgetting_factor: float = 1.0, criteria: ConvergenceCriteria | None = None):
        super().__init__(N_UNKNOWNS, forgetting_factor, default_criteria() if criteria is None else criteria)
        A = self._A = np.zeros((M_ROWS, N_UNKNOWNS))
        # Views of A_t's (Eq. (35)) sample-dependent entries, so that ``add`` writes them in a few
        # calls: A[i, 3 k + i] = p_CP[k] (the c_k E blocks, k < 3), -R_WH, -p_WH.
        step = A.itemsize
        blocks = np.lib.stride_tricks.as_strided(A, (M_ROWS, 4), ((N_UNKNOWNS + 1) * step, 3 * step))
        blocks[:, 3] = 1.0  # the E block
        self._A_c, self._A_R, self._A_p = blocks[:, :3], A[:, 12:15], A[:, 15]
        self._T = np.zeros((N_UNKNOWNS, N_UNKNOWNS))

    def add(self, p_CP: np.ndarray, R_WH: np.ndarray, p_WH: np.ndarray) -> None:
        """Adds one sample: the point measured in the camera frame (m) and the hand pose.

        Raises:
            IdentificationError: ``p_CP`` or ``p_WH`` is not a finite 3-vector, or ``R_WH`` not a
                rotation matrix (``errors.ROTATION_TOLERANCE``). The state is then unchanged.
        """
        # The usual sample (float64 3-vectors) is written as it is; anything else is converted
        # and checked first (a scalar or a 1-vector would broadcast into A_t).
        if type(p_CP) is not np.ndarray or p_CP.shape != VECTOR3 or p_CP.dtype is not F64:
            p_CP = real_array("p_CP", p_CP, VECTOR3, finite=False)
        if type(p_WH) is not np.ndarray or p_WH.shape != VECTOR3 or p_WH.dtype is not F64:
            p_WH = real_array("p_WH", p_WH, VECTOR3, finite=False)
        A_c, A_R = self._A_c, self._A_R
        A_c[0] = p_CP  # row 0 first, then copied to rows 1 and 2
        A_c[1:] = A_c[0]
        try:
            np.negative(R_WH, out=A_R)
        except (TypeError, ValueError):  # not a real array that fits 3 x 3
            raise not_a_rotation("R_WH", R_WH) from None
        np.negative(p_WH, out=self._A_p)
        # Python floats: the rotation check (on -R_WH, which may have been broadcast into A_t) and
        # the size of the sample in a few operations, in place of the core's array checks.
        if not is_rotation(A_R.tolist(), -1.0):
            raise not_a_rotation("R_WH", R_WH)
        cx, cy, cz = p_CP.tolist()
        px, py, pz = p_WH.tolist()
        if cx * cx + cy * cy + cz * cz + px * px + py * py + pz * pz < _SMALL_SAMPLE:
            self._core._add_product(self._A)
            return
        real_array("p_CP", p_CP, VECTOR3)  # NaN or inf: the error names the argument
        real_array("p_WH", p_WH, VECTOR3)
        try:
            self._core.add(self._A)  # finite but huge: the core's checked path (overflow)
        except IdentificationError:
            raise IdentificationError("p_CP or p_WH is too large: A_t^T A_t overflows") from None

    def add_pose(self, p_CP: np.ndarray, X_WH: np.ndarray) -> None:
        """Adds one sample with the hand pose as a 4 x 4 homogeneous transform (``add``'s
        IdentificationError, or one for ``X_WH`` not a 4 x 4 transform)."""
        X_WH = homogeneous_transform("X_WH", X_WH, rotation_block=False)
        self.add(p_CP, X_WH[:3, :3], X_WH[:3, 3])

    def sample_error(self, p_CP, R_WH, p_WH, estimate: EyeToHandEstimate) -> float:
        """``s_t = ||A_t x||^2`` (Eq. (2)), m^2: how well ``estimate`` explains a new sample.
        IdentificationError unless ``p_CP``, ``R_WH``, ``p_WH`` are a real 3-vector, 3 x 3 matrix,
        3-vector and ``estimate`` an EyeToHandEstimate (NaN or inf give a non-finite error)."""
        p_CP = real_array("p_CP", p_CP, VECTOR3, finite=False)
        R_WH = real_array("R_WH", R_WH, MATRIX3, finite=False)
        p_WH = real_array("p_WH", p_WH, VECTOR3, finite=False)
        estimate = instance("estimate", estimate, EyeToHandEstimate, "an EyeToHandEstimate")
        r = estimate.R_WC @ p_CP + estimate.p_WC - R_WH @ estimate.p_HP - p_WH
        return float(r @ r)

    def solve(self, refine_estimate: bool = True) -> EyeToHandSolution:
        """Solves the accumulated statistic (§3.1, §3.2) and judges convergence.

        Args:
            refine_estimate: also run the Gauss-Newton refinement (about 10x the cost of the
                rest of the solve; a streaming system can refine only when it adopts a model).

        Lazy: the solution is computed at the first call after a change of the statistic (or of
        ``criteria``) and the same object is returned until the next one; the refinement too is
        run once, when first asked for.

        Never raises for degenerate data: too few or too similar samples give a "not converged"
        verdict with the reason. IdentificationError if ``refine_estimate`` is not a bool.
        """
        if type(refine_estimate) is not bool:
            refine_estimate = flag("refine_estimate", refine_estimate)
        cache = self._cached()
        if cache is None:
            cache = self._cache = [self._core._revision, self.criteria, self._solve_tls(), None]
        solution = cache[2]
        if not refine_estimate or solution.projected is None:
            return solution
        if cache[3] is None:
            cache[3] = self._refine(solution)
        return cache[3]

    def _solve_tls(self) -> EyeToHandSolution:
        """The solution without refinement: the eigen-solve, the SO(3) projection, the verdict."""
        core = self._core
        n = core.num_samples
        eigen = core.eigen(_conditioning_transform(core._S, self._T)) if n > 0 else None
        if eigen is None:
            reason = "no samples" if n == 0 else "statistic is not finite (overflow)"
            return EyeToHandSolution(None, 0.0, math.inf, math.inf, None, None,
                                     Verdict(False, reason), n)  # fmt: skip
        direction = eigen.direction
        R, a, ssd, _ = _projection_parts(direction[0:9])
        x = a * direction
        # A rotation block so small that a * a overflows is zero to the precision of the solve.
        expected_mse = a * a * eigen.lambda_N
        if a == 0.0 or not math.isfinite(sum(x.tolist())) or not math.isfinite(expected_mse):
            verdict = Verdict(False, "the rotation block of v_N is zero: no rotation to identify")
            verdict = _judge_eye_to_hand(self.criteria, core._S, core.weight, n, eigen, None, verdict)
            return EyeToHandSolution(eigen, 0.0, math.inf, math.inf, None, None, verdict, n)
        projected = EyeToHandEstimate(R, x[9:12], x[12:15], x, expected_mse)
        expected_rms = math.sqrt(expected_mse)
        verdict = judge(self.criteria, n, eigen, expected_rms, None, ssd, " m")
        verdict = _judge_eye_to_hand(self.criteria, core._S, core.weight, n, eigen, (x, R, expected_rms),
                                    verdict)  # fmt: skip
        return EyeToHandSolution(eigen, a, ssd, expected_mse, projected, None, verdict, n)

    def _refine(self, solution: EyeToHandSolution) -> EyeToHandSolution:
        """``solution`` with its Gauss-Newton refinement (None if it is not finite)."""
        core, est = self._core, solution.projected
        with np.errstate(all="ignore"):  # absurd magnitudes: dropped below, never a NaN out
            refined = _gauss_newton(core._S, core.weight, est.R_WC, est.p_WC.copy(), est.p_HP.copy())
        if not math.isfinite(refined.mean_squared_error + refined.x.sum()):
            return solution
        return dataclasses.replace(solution, refined=refined)
