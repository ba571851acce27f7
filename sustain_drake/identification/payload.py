"""Static payload identification from a wrist force/torque sensor (paper §3.5, §4.4, Eqs. (37)-(38)),
N = 5, M = 6.

Wrench sign convention (used throughout sustain_drake). The sensor frame K is fixed to the sensor's
outboard side (the hand). A wrench sample is the 6-vector ``[tau_K; f_K]`` (Drake's SpatialForce
order: torque first), the force and torque APPLIED BY THE SENSOR (the wrist) ON THE OUTBOARD BODY
(hand + held object), about K's origin, expressed in K. This is what Drake's
``MultibodyPlant.get_reaction_forces_output_port()`` reports for the wrist weld's child frame. At
rest, with the outboard mass m at ``p_KCm`` and gravity ``g_W`` (e.g. ``(0, 0, -9.81)`` m/s^2)::

    R_WK f_K = -m g_W              (the sensor holds the payload up)
    tau_K    = p_KCm x f_K         (the sensor's torque balances the weight's)

which is linear in ``x = [1/m; p_KCm; 1]`` (Eq. (38)) with::

    A_t = [[R_WK f_K, 0_3x3,    g_W   ],
           [0_3x1,   -[f_K x], -tau_K]]                                     (Eq. (37))

The rows of ``A_t x`` are in m/s^2 (the first three) and N m (the last three). A sensor whose
reading is the wrench the payload applies on it (the opposite sign) must be negated first.

Quasi-static: the formulation ignores the payload's acceleration, so samples should be taken while
the sensor moves slowly (the paper's §4.4 does the same).

Every public function and method raises ``IdentificationError`` (a ``ValueError``, see ``errors``)
with a one-line message for an argument of the wrong type, shape or value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from sustain_drake.identification.errors import (
    F64,
    MATRIX3,
    VECTOR3,
    is_rotation,
    not_a_rotation,
    out_array,
    real_array,
    real_number,
    rotation,
)
from sustain_drake.identification.observability import _judge_payload
from sustain_drake.identification.rotation import _skew
from sustain_drake.identification.sustainable_identifier import (
    ConvergenceCriteria,
    EigenSolution,
    FormulationIdentifier,
    IdentificationError,
    SolutionProperties,
    SustainableIdentifier,
    Verdict,
    judge,
)

N_UNKNOWNS = 5
M_ROWS = 6
STANDARD_GRAVITY_W = np.array([0.0, 0.0, -9.81])


def default_criteria() -> ConvergenceCriteria:
    """Defaults for the payload: expected RMS residual <= 0.3 (m/s^2 and N m rows together),
    gap >= 10, at least 10 samples. There is no rotation, so no SSD criterion."""
    return ConvergenceCriteria(max_expected_rms=0.3, min_gap_ratio=10.0, max_ssd=None, min_samples=10)


_WRENCH = (6,)
# Samples with a squared norm below this have entries below 1e100: A^T A cannot overflow.
_SMALL_SAMPLE = 1e200


def build_A(wrench_K: np.ndarray, R_WK: np.ndarray, g_W: np.ndarray, out=None) -> np.ndarray:
    """``A_t`` of Eq. (37) (6 x 5) for one wrench sample ``[tau_K; f_K]`` (written into ``out``, a
    float64 6 x 5 array, if given). IdentificationError unless ``wrench_K``, ``R_WK``, ``g_W`` are a
    real 6-vector, 3 x 3 matrix and 3-vector (NaN and inf are carried into ``A_t``)."""
    wrench_K = real_array("wrench_K", wrench_K, _WRENCH, finite=False)
    R_WK = real_array("R_WK", R_WK, MATRIX3, finite=False)
    g_W = real_array("g_W", g_W, VECTOR3, finite=False)
    out = out_array("out", out, (M_ROWS, N_UNKNOWNS))
    return _build_A(wrench_K, R_WK, g_W, out)


def _build_A(wrench_K: np.ndarray, R_WK: np.ndarray, g_W: np.ndarray, out=None) -> np.ndarray:
    A = np.zeros((M_ROWS, N_UNKNOWNS)) if out is None else out
    tau = wrench_K[0:3]
    f = wrench_K[3:6]
    A[0:3, 0] = R_WK @ f
    A[0:3, 4] = g_W
    A[3:6, 1:4] = -_skew(f)
    A[3:6, 4] = -tau
    return A


def posture_information(state: np.ndarray, R_WK_candidates, g_W: np.ndarray, samples: float):
    """The information ``M`` the statistic holds on the unknowns ``[1/m; p_KCm]`` and, for each
    candidate sensor orientation ``R_WK``, the information ``dM`` that ``samples`` quasi-static
    samples there add (``identification.excitation``; issue 25).

    ``state`` is a ``PayloadIdentifier``'s state ``[S (25) | n_eff | count]``; ``M`` is S's block
    over the unknowns. A candidate's samples are predicted at rest (Eq. (37) with ``f_K = -m R_WK^T
    g_W``) with the mass the statistic implies, ``m^2 = S[0, 0] / (n_eff |g_W|^2)`` (each
    quasi-static sample adds ``|R_WK f_K|^2 = m^2 |g_W|^2`` to ``S[0, 0]``), or 1 kg before any
    sample: only ``f_K``'s direction, ``R_WK^T g_W``, moves ``dM``, and its scale must match ``M``'s.
    The torque column is the measurement's, not an unknown's, so it needs no prediction.
    IdentificationError unless ``state`` is a real vector of 27, ``R_WK_candidates`` rotation
    matrices (k x 3 x 3), ``g_W`` a finite 3-vector and ``samples`` a number > 0."""
    n2 = N_UNKNOWNS * N_UNKNOWNS
    state = real_array("state", state, (n2 + 2,))
    rotations = real_array("R_WK_candidates", R_WK_candidates, (None, 3, 3),
                           what="rotation matrices (k x 3 x 3)")
    g_W = real_array("g_W", g_W, VECTOR3)
    samples = _positive_samples(samples)
    S = state[:n2].reshape(N_UNKNOWNS, N_UNKNOWNS)
    n_eff = float(state[n2])
    m = math.sqrt(S[0, 0] / (n_eff * float(g_W @ g_W))) if n_eff > 0 and S[0, 0] > 0 and g_W.any() else 1.0
    unknowns = slice(0, N_UNKNOWNS - 1)
    added = []
    for R_WK in rotations:
        R_WK = rotation("R_WK_candidates", R_WK)
        wrench = np.concatenate([np.zeros(3), -m * (R_WK.T @ g_W)])
        Phi = _build_A(wrench, R_WK, g_W)[:, unknowns]
        added.append(samples * (Phi.T @ Phi))
    return S[unknowns, unknowns].copy(), added


def _positive_samples(samples) -> float:
    samples = real_number("samples", samples, what="a number > 0")
    if not samples > 0:
        raise IdentificationError(f"samples must be a number > 0, got {samples}")
    return samples


@dataclass(frozen=True)
class PostureInformation:
    """``posture_information`` as a callable ``(state, R_WK_candidates) -> (M, [dM])`` for
    ``systems.ExcitingPostures``: gravity ``g_W`` (m/s^2) and the quasi-static ``samples`` a rest at
    a posture gives."""

    g_W: np.ndarray
    samples: float
    num_unknowns: ClassVar[int] = N_UNKNOWNS

    def __post_init__(self):
        object.__setattr__(self, "g_W", real_array("g_W", self.g_W, VECTOR3))
        object.__setattr__(self, "samples", _positive_samples(self.samples))

    def __call__(self, state, R_WK_candidates):
        return posture_information(state, R_WK_candidates, self.g_W, self.samples)


@dataclass(frozen=True, slots=True)
class PayloadSolution(SolutionProperties):
    """Everything one solve gives.

    Attributes:
        eigen: the eigen-decomposition of the conditioned statistic (None before any sample).
        mass: m in kg (``nan``-free: 0 when there is no estimate).
        p_KCm: the centre of mass in the sensor frame K, metres.
        x: ``[1/m; p_KCm; 1]``.
        expected_mse: ``a^2 lambda_N`` (Eq. (13)), in (m/s^2)^2 + (N m)^2 per sample.
        verdict: the convergence verdict.
        num_samples: samples behind this solution.
        covariance: the covariance (4 x 4) of ``(mass, p_KCm)`` in kg and m
            (``observability.payload_covariance``) when the one solving attached it, else None.
    """

    num_unknowns: ClassVar[int] = N_UNKNOWNS

    eigen: EigenSolution | None
    mass: float
    p_KCm: np.ndarray
    x: np.ndarray
    expected_mse: float
    verdict: Verdict
    num_samples: int
    covariance: np.ndarray | None = None

    @property
    def ssd(self) -> float:
        """No rotation in this formulation: always 0 (kept for a uniform solution interface)."""
        return 0.0

    @property
    def static_x(self) -> np.ndarray:
        """``x`` itself: ``[1/m; p_KCm; 1]`` (the dynamic solution has the same property)."""
        return self.x

    @property
    def bias(self) -> np.ndarray:
        """The wrench sensor's bias: zeros (this formulation has none; the dynamic one identifies it)."""
        return np.zeros(6)

    @property
    def mass_com_covariance(self) -> np.ndarray | None:
        """The covariance (4 x 4) of ``(mass, p_KCm)``: ``covariance``."""
        return self.covariance


class PayloadIdentifier(FormulationIdentifier):
    """The sustainable identifier with the static payload formulation.

    Args:
        gravity_W: gravity in the world frame, m/s^2.
        forgetting_factor: see ``SustainableIdentifier``.
        criteria: convergence criteria (``default_criteria()`` if None).

    Every method raises IdentificationError for an argument of the wrong type, shape or value.
    """

    def __init__(
        self,
        gravity_W: np.ndarray = STANDARD_GRAVITY_W,
        forgetting_factor: float = 1.0,
        criteria: ConvergenceCriteria | None = None,
    ):
        self.g_W = real_array("gravity_W", gravity_W, VECTOR3, what="a finite non-zero 3-vector").copy()
        if not self.g_W.any():
            raise IdentificationError("gravity_W must be a finite non-zero 3-vector, got zeros")
        super().__init__(N_UNKNOWNS, forgetting_factor, default_criteria() if criteria is None else criteria)
        self._A = np.zeros((M_ROWS, N_UNKNOWNS))
        self._small_gravity = float(self.g_W @ self.g_W) < _SMALL_SAMPLE

    def add(self, wrench_K: np.ndarray, R_WK: np.ndarray) -> None:
        """Adds one quasi-static sample: the wrench ``[tau_K; f_K]`` and the sensor orientation.

        Raises:
            IdentificationError: ``wrench_K`` is not a finite 6-vector (or so large that ``A^T A``
                overflows), or ``R_WK`` not a rotation matrix (``errors.ROTATION_TOLERANCE``). The
                state is then unchanged.
        """
        if type(wrench_K) is not np.ndarray or wrench_K.shape != _WRENCH or wrench_K.dtype is not F64:
            wrench_K = real_array("wrench_K", wrench_K, _WRENCH, finite=False)
        if type(R_WK) is not np.ndarray or R_WK.shape != MATRIX3 or R_WK.dtype is not F64:
            R_WK = real_array("R_WK", R_WK, MATRIX3, what="a 3 x 3 rotation matrix", finite=False)
        if not is_rotation(R_WK.tolist()):
            raise not_a_rotation("R_WK", R_WK)
        # Python floats: a wrench whose entries are below 1e100 (and gravity too) makes A_t's entries
        # so (|R_WK| <= 1), so A^T A cannot overflow: the core's fast path without its array checks.
        tx, ty, tz, fx, fy, fz = wrench_K.tolist()
        if tx * tx + ty * ty + tz * tz + fx * fx + fy * fy + fz * fz < _SMALL_SAMPLE and self._small_gravity:
            self._core._add_product(_build_A(wrench_K, R_WK, self.g_W, self._A))
            return
        with np.errstate(invalid="ignore", over="ignore"):  # an absurd wrench: the core refuses its A
            A = _build_A(wrench_K, R_WK, self.g_W, self._A)
        try:
            self._core.add(A)
        except IdentificationError:
            real_array("wrench_K", wrench_K, _WRENCH)  # NaN or inf: the error names the argument
            raise IdentificationError("wrench_K is too large: A_t^T A_t overflows") from None

    def sample_error(self, wrench_K: np.ndarray, R_WK: np.ndarray, x: np.ndarray) -> float:
        """``s_t = ||A_t x||^2`` (Eq. (2)) for a new sample under the estimate ``x``.
        IdentificationError unless ``wrench_K``, ``R_WK``, ``x`` are a real 6-vector, 3 x 3 matrix
        and 5-vector (NaN or inf give a non-finite error)."""
        x = real_array("x", x, (N_UNKNOWNS,), finite=False)
        return SustainableIdentifier.sample_error(build_A(wrench_K, R_WK, self.g_W), x)

    def solve(self) -> PayloadSolution:
        """Solves for ``[1/m; p_KCm; 1]``: ``v_N`` scaled so that its last entry is 1 (§3.4).

        Conditioning: the columns are equilibrated (``T = diag(1/sqrt(C_jj))``), so that the unit
        norm of TLS weighs the mass and the centre-of-mass unknowns alike.

        Lazy: the solution is computed at the first call after a change of the statistic (or of
        ``criteria``) and the same object is returned until the next one.
        """
        cache = self._cached()
        if cache is None:
            cache = self._cache = [self._core._revision, self.criteria, self._solve_tls(), None]
        return cache[2]

    def _solve_tls(self) -> PayloadSolution:
        core = self._core
        n = core.num_samples
        none = np.zeros(3)
        if n == 0:
            return PayloadSolution(None, 0.0, none, np.zeros(N_UNKNOWNS), math.inf,
                                   Verdict(False, "no samples"), 0)  # fmt: skip
        # Python floats: the same IEEE arithmetic as numpy's, in fewer calls. (A state set with a
        # zero weight has no eigen-solution: core.eigen returns None whatever T.)
        weight = core.weight or math.nan
        diag = [s_jj / weight for s_jj in core.S_view.diagonal().tolist()]
        T = np.diag([1.0 / math.sqrt(c_jj if c_jj > 0.0 else 1.0) for c_jj in diag])
        eigen = core.eigen(T)
        if eigen is None:
            return PayloadSolution(None, 0.0, none, np.zeros(N_UNKNOWNS), math.inf,
                                   Verdict(False, "statistic is not finite (overflow)"), n)  # fmt: skip
        direction = eigen.direction
        h = direction[4]
        problem = None
        if abs(h) <= 1e-12 * max(map(abs, direction.tolist())):
            problem = "the homogeneous entry of v_N is zero: no payload model explains the data"
            x = np.zeros(N_UNKNOWNS)
            mass, expected_mse = 0.0, math.inf
        else:
            a = 1.0 / h
            x = a * direction
            expected_mse = a * a * eigen.lambda_N
            if not x[0] > 0.0:
                problem = f"identified 1/m = {x[0]:.3g} is not positive: no payload or wrong wrench sign"
                mass = 0.0
            else:
                mass = 1.0 / x[0]
        verdict = judge(
            self.criteria,
            n,
            eigen,
            math.sqrt(expected_mse) if math.isfinite(expected_mse) else math.inf,
            problem,
        )
        verdict = _judge_payload(self.criteria, core.S_view, core.weight, n, eigen, x, self.g_W, verdict)
        return PayloadSolution(eigen, mass, x[1:4].copy(), x, expected_mse, verdict, n)
