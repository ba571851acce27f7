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
from typing import ClassVar, NamedTuple

import numpy as np

from sustain_drake.identification.errors import (
    F64,
    MATRIX3,
    VECTOR3,
    check_finite,
    describe,
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
    to_float_array,
)
from sustain_drake.identification.observability import _judge_eye_to_hand
from sustain_drake.identification.rotation import (
    _nearest_rotation,
    _projection_parts,
    _rotation_jacobian,
    _skew,
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
        if a == 0.0 or not math.isfinite(sum(x.tolist())):
            verdict = Verdict(False, "the rotation block of v_N is zero: no rotation to identify")
            verdict = _judge_eye_to_hand(self.criteria, core._S, core.weight, n, eigen, None, verdict)
            return EyeToHandSolution(eigen, 0.0, math.inf, math.inf, None, None, verdict, n)
        expected_mse = a * a * eigen.lambda_N
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


# ---- several points at once (beyond the paper: the paper identifies from one point) -----------
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
    (from the anchors' depth on both sides of the move), not the old one left where it was."""

    R_WC: np.ndarray
    p_WC: np.ndarray
    rms_angle: float
    num_anchors: int
    scene_shift: bool


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


def camera_after_turn(R_WC0: np.ndarray, p_WC0: np.ndarray, b0: np.ndarray, q0: np.ndarray,
                      b1: np.ndarray, S_list: list[np.ndarray], p_HP: np.ndarray, min_points: int = 10,
                      iterations: int = 4, q1: np.ndarray | None = None):  # fmt: skip
    """The camera after a move (beyond the paper) from two things that the move left as they were:
    the static scene (its rotation) and the held tool (its position).

    - The scene: per anchor its unit bearings ``b0`` (before, in C0) and ``b1`` (after, in C1) and
      its point before ``q0`` (in C0, m; NaN rows: no depth, taken as far away); see
      ``perception.camera_motion.SceneTurn``. A static point satisfies ``q0 - p_C0C1 ~ R_C0C1 b1``
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
    than ``min_points`` anchors left.

    IdentificationError unless ``R_WC0`` is a finite 3 x 3 matrix, ``p_WC0`` a finite 3-vector,
    ``b0`` and ``b1`` K x 3 arrays of finite non-zero bearings, ``q0`` (and ``q1`` unless None or
    empty) a K x 3 array whose finite rows are non-zero, ``S_list`` a list of finite 16 x 16
    statistics with as many finite ``p_HP`` points, and ``min_points``, ``iterations`` integers >= 1."""
    R_WC0, p_WC0 = real_array("R_WC0", R_WC0, MATRIX3), real_array("p_WC0", p_WC0, VECTOR3)
    b0, b1 = _anchors("b0", b0, bearings=True), _anchors("b1", b1, bearings=True)
    q0 = _anchors("q0", q0, bearings=False)
    q1 = None if q1 is None else _anchors("q1", q1, bearings=False)
    if q1 is None or q1.size == 0:
        q1 = np.full_like(q0, np.nan)
    if not (b1.shape == q0.shape == q1.shape == b0.shape):
        raise IdentificationError(f"camera_after_turn: b0, q0, b1 and q1 must be K x 3 alike, got "
                                  f"{b0.shape}, {q0.shape}, {b1.shape}, {q1.shape}")
    S_list = _statistics(S_list)
    p_HP = _points("p_HP", p_HP, len(S_list))
    min_points, iterations = integer("min_points", min_points, 1), integer("iterations", iterations, 1)
    far = ~np.all(np.isfinite(q0), axis=1)
    deep = ~far & np.all(np.isfinite(q1), axis=1)  # depth on both sides
    P, n = _known_points_statistic(S_list, p_HP)
    if b0.shape[0] < min_points:
        return None
    # Without tool samples, the scene's depth gives the shift (when enough anchors have it).
    scene = n == 0 and np.count_nonzero(deep) >= min_points
    p_C0C1, inliers, from_scene = np.zeros(3), np.ones(b0.shape[0], bool), False
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
    rms = math.sqrt(float(np.mean(angle[inliers] ** 2)))
    return CameraAfterTurn(R_WC, p_WC, rms, int(np.count_nonzero(inliers)), from_scene)
