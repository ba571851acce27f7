"""Dynamic payload identification from a wrist force/torque sensor during motion (beyond the paper's
static §4.4; issue 26): the ten inertial parameters and the sensor's six bias values, N = 17, M = 6.

Wrench sign convention: the one of ``payload`` (used throughout sustain_drake). A wrench sample is
``[tau_K; f_K]`` (N m, N; Drake's SpatialForce order), the torque and force APPLIED BY THE SENSOR
(the wrist) ON THE OUTBOARD BODY B (hand + held object), about the sensor frame K's origin Ko,
expressed in K; ``systems.wrench_sensor.WristWrenchSensor`` reads it off the weld's reaction
force ``F_CJc_Jc``. A sensor that reports the wrench the payload applies on it must be negated.

The sensor's kinematics, all expressed in K (``kinematics_K``, 9 values)::

    [w_WK_K; alpha_WK_K; a_WKo_K - g_K]

the angular velocity (rad/s) and angular acceleration (rad/s^2) of K in the world, and the
acceleration of Ko in the world minus gravity (m/s^2: what an accelerometer at Ko would read; at
rest it is ``-g_K``, pointing up).

Newton-Euler for the rigid outboard body B about the body-fixed point Ko (``h = m p_KCm`` its first
moment, ``I`` its rotational inertia about Ko, ``a = a_WKo_K - g_K``, ``w``, ``alpha`` as above)::

    f_K   = m a + (alpha x h) + w x (w x h)
    tau_K = I alpha + w x (I w) + h x a                                       (Newton-Euler)

At rest this is ``payload``'s ``R_WK f_K = -m g_W``, ``tau_K = p_KCm x f_K``. It is linear in the
inertial parameters ``phi = [m; h_x, h_y, h_z; I_xx, I_yy, I_zz, I_xy, I_xz, I_yz]`` (kg, kg m,
kg m^2; the products are the inertia matrix's entries, as in Drake's ``RotationalInertia``)::

    [tau_K; f_K] = Y(w, alpha, a) phi                            (the standard regressor, 6 x 10)

and the sensor reads ``wrench = Y phi + b`` with a constant bias ``b = [b_tau; b_f]`` (N m, N).

The form chosen: homogeneous, ``x = [phi; b; 1]`` (N = 17) and ``A_t = [Y_t, I_6, -wrench_t]``
(6 x 17), so that ``A_t x = 0``: the same §3.1 statistic, total least squares, verdict and
identify <-> observe rule as the static and eye-to-hand formulations (``v_N`` scaled so that its
last entry is 1; the expected mean squared error ``a^2 lambda_N``). The measured wrench is a column
of ``A_t`` like the kinematics, so noise in both is treated alike (on hardware the angular
acceleration comes from differentiated encoders and is as noisy as the wrench). The bias is in
the unknowns, not eliminated beforehand (e.g. by differencing samples): differencing doubles the
noise's variance and correlates successive rows (the statistic takes samples as independent), and
with the bias in ``x`` the observation rule compares each new sample with the whole model. The
torque rows are divided by a length ``torque_length`` (``DynamicPayloadIdentifier``), so every row
is in newtons, with equal noise; the expected RMS (criterion (a)) is in N per sample.

What the motion must do: the gravity direction in K must turn about two axes (else the mass and
the force bias, the first moment and the torque bias are confounded: ``observability``'s
``ONE_ORIENTATION``), and K must turn with angular accelerations about all three axes (else the
rotational inertia is unobservable: ``NO_ROTATION``, ``ONE_AXIS``). The verdict checks both from
the statistic, then the estimate's uncertainty (``dynamic_observability``).

Every public function and method raises ``IdentificationError`` (a ``ValueError``, see ``errors``)
with a one-line message for an argument of the wrong type, shape or value.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from sustain_drake.identification.dynamic_observability import _judge_dynamic_payload
from sustain_drake.identification.errors import F64, MATRIX3, VECTOR3, out_array, real_array, real_number
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

N_INERTIAL = 10
N_BIAS = 6
N_UNKNOWNS = N_INERTIAL + N_BIAS + 1
M_ROWS = 6
KINEMATICS = 9  # [w_WK_K; alpha_WK_K; a_WKo_K - g_K]
DEFAULT_TORQUE_LENGTH = 0.025  # m: the ATI Mini40's torque noise over its force noise
_WRENCH = (6,)
_KINEMATICS = (KINEMATICS,)
# Samples with a squared norm below this have entries below 1e60: A^T A cannot overflow.
_SMALL_SAMPLE = 1e120
# Inertia moments and products in the order of phi[4:10] (and of Drake's RotationalInertia).
_MOMENTS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


# Criterion (b) of the dynamic mode: a one-dimensional null space. How well the motion determines the
# payload is judged by the 95 % regions (``dynamic_observability.accuracy_problem``), not by the gap.
MIN_GAP_RATIO = 10.0


def default_criteria() -> ConvergenceCriteria:
    """Defaults for the dynamic payload: expected RMS residual <= 0.3 (N, the six rows together),
    gap >= ``MIN_GAP_RATIO``, at least 30 samples (17 unknowns). There is no rotation: no SSD criterion."""
    return ConvergenceCriteria(max_expected_rms=0.3, min_gap_ratio=MIN_GAP_RATIO, max_ssd=None,
                               min_samples=30)


def sensor_kinematics(R_WK, w_WK_W, alpha_WK_W, a_WKo_W, g_W) -> np.ndarray:
    """``kinematics_K = [w_WK_K; alpha_WK_K; a_WKo_K - g_K]`` (9) from the sensor frame's
    orientation ``R_WK`` and its angular velocity, angular acceleration, its origin's acceleration
    and gravity, all in the world (rad/s, rad/s^2, m/s^2)."""
    R_KW = real_array("R_WK", R_WK, MATRIX3).T
    vectors = [real_array(name, v, VECTOR3) for name, v in
               (("w_WK_W", w_WK_W), ("alpha_WK_W", alpha_WK_W), ("a_WKo_W", a_WKo_W), ("g_W", g_W))]
    w, alpha, a, g = vectors
    return np.concatenate([R_KW @ w, R_KW @ alpha, R_KW @ (a - g)])


def inertia_matrix(moments_products) -> np.ndarray:
    """The symmetric 3 x 3 matrix of ``[I_xx, I_yy, I_zz, I_xy, I_xz, I_yz]`` (kg m^2)."""
    xx, yy, zz, xy, xz, yz = real_array("moments_products", moments_products, (6,)).tolist()
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def moments_products(inertia: np.ndarray) -> np.ndarray:
    """``[I_xx, I_yy, I_zz, I_xy, I_xz, I_yz]`` of a 3 x 3 inertia matrix (its upper triangle)."""
    inertia = real_array("inertia", inertia, MATRIX3)
    return np.array([inertia[i, j] for i, j in _MOMENTS])


def inertial_parameters(mass: float, p_KCm, I_Cm_K) -> np.ndarray:
    """``phi`` (10) of a body of ``mass`` (kg) whose centre of mass is at ``p_KCm`` (m, in K) and
    whose rotational inertia about its centre of mass, expressed in K, is ``I_Cm_K`` (3 x 3, kg m^2):
    ``h = m p_KCm`` and the parallel-axis theorem ``I_Ko = I_Cm + m (|p|^2 I_3 - p p^T)``."""
    m = real_number("mass", mass)
    p = real_array("p_KCm", p_KCm, VECTOR3)
    I_Ko = real_array("I_Cm_K", I_Cm_K, MATRIX3) + m * (float(p @ p) * np.eye(3) - np.outer(p, p))
    return np.concatenate([[m], m * p, moments_products(I_Ko)])


def central_inertia(phi) -> tuple[float, np.ndarray, np.ndarray]:
    """``(mass, p_KCm, I_Cm_K)`` of the inertial parameters ``phi`` (the inverse of
    ``inertial_parameters``; IdentificationError unless the mass is positive)."""
    phi = real_array("phi", phi, (N_INERTIAL,))
    m = float(phi[0])
    if not m > 0.0:
        raise IdentificationError(f"phi's mass must be positive, got {m:.6g} kg")
    h = phi[1:4]
    return m, h / m, inertia_matrix(phi[4:10]) - (float(h @ h) * np.eye(3) - np.outer(h, h)) / m


def physical_inertia_problem(I_Cm: np.ndarray) -> str | None:
    """Why the rotational inertia about the centre of mass ``I_Cm`` (3 x 3) is not a rigid body's:
    its principal moments must be positive (positive definite) and each less than the sum of the
    other two (the triangle inequalities). None if it is one."""
    moments = np.linalg.eigvalsh((I_Cm + I_Cm.T) / 2.0)
    if not np.isfinite(moments).all():
        return "the rotational inertia is not finite"
    text = ", ".join(f"{v:.3g}" for v in moments)
    if not moments[0] > 0.0:
        return f"the rotational inertia is not positive definite (principal moments {text} kg m^2)"
    if not moments[2] <= moments[0] + moments[1]:
        return f"the rotational inertia breaks the triangle inequality (principal moments {text} kg m^2)"
    return None


def regressor(kinematics_K, out=None) -> np.ndarray:
    """``Y(w, alpha, a)`` (6 x 10) of the Newton-Euler equations (module docstring) for the
    sensor's ``kinematics_K = [w; alpha; a - g]`` (written into ``out``, a float64 6 x 10 array, if
    given): ``[tau_K; f_K] = Y phi``. IdentificationError unless ``kinematics_K`` is a real
    9-vector (NaN and inf are carried into ``Y``)."""
    kinematics_K = real_array("kinematics_K", kinematics_K, _KINEMATICS, finite=False)
    out = out_array("out", out, (M_ROWS, N_INERTIAL))
    return _regressor(kinematics_K.tolist(), np.zeros((M_ROWS, N_INERTIAL)) if out is None else out)


def _regressor(k: list, Y: np.ndarray) -> np.ndarray:
    """``regressor`` into ``Y`` from the 9 kinematics as Python floats (every entry written)."""
    wx, wy, wz, ax, ay, az, sx, sy, sz = k  # w, alpha, s = a - g
    # Torque rows: h x s = -[s x] h; I alpha = L(alpha) iota; w x (I w) = [w x] L(w) iota, with
    # L(v) iota = I v for iota = [I_xx, I_yy, I_zz, I_xy, I_xz, I_yz].
    # Force rows: m s; (alpha x h) + w x (w x h) = ([alpha x] + [w x]^2) h.
    Y[:] = (
        (0.0, 0.0, sz, -sy, ax, -wy * wz, wy * wz, ay - wx * wz, az + wx * wy, wy * wy - wz * wz),
        (0.0, -sz, 0.0, sx, wx * wz, ay, -wx * wz, ax + wy * wz, wz * wz - wx * wx, az - wx * wy),
        (0.0, sy, -sx, 0.0, -wx * wy, wx * wy, az, wx * wx - wy * wy, ax - wy * wz, ay + wx * wz),
        (sx, -wy * wy - wz * wz, wx * wy - az, wx * wz + ay, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        (sy, wx * wy + az, -wx * wx - wz * wz, wy * wz - ax, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        (sz, wx * wz - ay, wy * wz + ax, -wx * wx - wy * wy, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    )  # fmt: skip
    return Y


def predicted_wrench(phi, bias, kinematics_K) -> np.ndarray:
    """The reading ``Y(kinematics_K) phi + bias`` (6: ``[tau_K; f_K]``, N m and N) of a body of
    inertial parameters ``phi`` on a sensor of ``bias``."""
    phi = real_array("phi", phi, (N_INERTIAL,))
    bias = real_array("bias", bias, _WRENCH)
    return regressor(real_array("kinematics_K", kinematics_K, _KINEMATICS)) @ phi + bias


def build_A(wrench_K, kinematics_K, torque_length: float = DEFAULT_TORQUE_LENGTH, out=None) -> np.ndarray:
    """``A_t = [Y_t, I_6, -wrench_t]`` (6 x 17) for one sample, its torque rows divided by
    ``torque_length`` (m; see ``DynamicPayloadIdentifier``), written into ``out`` (a float64 6 x 17
    array) if given. IdentificationError unless ``wrench_K`` and ``kinematics_K`` are a real
    6-vector and 9-vector (NaN and inf are carried into ``A_t``) and ``torque_length`` positive."""
    wrench_K = real_array("wrench_K", wrench_K, _WRENCH, finite=False)
    kinematics_K = real_array("kinematics_K", kinematics_K, _KINEMATICS, finite=False)
    inverse = 1.0 / checked_torque_length(torque_length)
    out = out_array("out", out, (M_ROWS, N_UNKNOWNS))
    A = _fresh_A(inverse) if out is None else out
    if out is not None:
        A[:, N_INERTIAL : N_INERTIAL + N_BIAS] = _fresh_A(inverse)[:, N_INERTIAL : N_INERTIAL + N_BIAS]
    return _build_A(wrench_K, kinematics_K.tolist(), A, inverse)


def _build_A(wrench_K: np.ndarray, k: list, A: np.ndarray, inverse_length: float) -> np.ndarray:
    """``build_A`` into ``A``, whose bias block already holds ``diag(1/l, 1/l, 1/l, 1, 1, 1)``
    (``_fresh_A``); ``inverse_length`` is ``1/l``."""
    _regressor(k, A[:, :N_INERTIAL])
    A[:3, :N_INERTIAL] *= inverse_length
    np.negative(wrench_K, out=A[:, N_UNKNOWNS - 1])
    A[:3, N_UNKNOWNS - 1] *= inverse_length
    return A


def _fresh_A(inverse_length: float) -> np.ndarray:
    A = np.zeros((M_ROWS, N_UNKNOWNS))
    A[:, N_INERTIAL : N_INERTIAL + N_BIAS] = np.diag([inverse_length] * 3 + [1.0] * 3)
    return A


def checked_torque_length(torque_length) -> float:
    """``torque_length`` as a float, IdentificationError unless it is a positive number (m)."""
    length = real_number("torque_length", torque_length, what="a positive number of metres")
    if not length > 0.0:
        raise IdentificationError(f"torque_length must be a positive number of metres, got {length}")
    return length


@dataclass(frozen=True, slots=True)
class DynamicPayloadSolution(SolutionProperties):
    """Everything one solve gives.

    Attributes:
        eigen: the eigen-decomposition of the conditioned statistic (None before any sample).
        phi: the inertial parameters ``[m; m p_KCm; I_xx, I_yy, I_zz, I_xy, I_xz, I_yz]`` about Ko
            in K (kg, kg m, kg m^2; zeros when there is no estimate).
        bias: the sensor's bias ``[b_tau; b_f]`` (N m, N).
        mass: m in kg (0 when there is no estimate).
        p_KCm: the centre of mass in K, metres.
        I_Cm_K: the rotational inertia about the centre of mass, expressed in K (3 x 3, kg m^2).
        x: ``[phi; bias; 1]``.
        expected_mse: ``a^2 lambda_N`` (Eq. (13)), in N^2 per sample (the torque rows divided by
            the identifier's ``torque_length``).
        verdict: the convergence verdict.
        num_samples: samples behind this solution.
        covariance: the covariance (16 x 16) of ``[phi; bias]``
            (``observability.dynamic_payload_covariance``) when the one solving attached it.
    """

    num_unknowns: ClassVar[int] = N_UNKNOWNS

    eigen: EigenSolution | None
    phi: np.ndarray
    bias: np.ndarray
    mass: float
    p_KCm: np.ndarray
    I_Cm_K: np.ndarray
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
    def I_BBcm(self) -> np.ndarray:
        """``[I_xx, I_yy, I_zz, I_xy, I_xz, I_yz]`` of ``I_Cm_K`` (the payload YAML's ``I_BBcm``)."""
        return moments_products(self.I_Cm_K)

    @property
    def mass_com_covariance(self) -> np.ndarray | None:
        """The covariance (4 x 4) of ``(mass, p_KCm)`` (kg, m) from ``covariance`` to first order
        (``p_KCm = h / m``), None without one."""
        if self.covariance is None or not self.mass > 0.0:
            return None
        h, m = self.phi[1:4], self.mass
        J = np.zeros((4, 4))
        J[0, 0] = 1.0
        J[1:, 0] = -h / (m * m)
        J[1:, 1:] = np.eye(3) / m
        return J @ self.covariance[:4, :4] @ J.T

    @property
    def static_x(self) -> np.ndarray:
        """``[1/m; p_KCm; 1]``: this payload in the static formulation's unknowns (zeros without a
        mass), for the quasi-static touch estimator."""
        if not self.mass > 0.0:
            return np.zeros(5)
        return np.concatenate([[1.0 / self.mass], self.p_KCm, [1.0]])


def _empty_solution(reason: str, num_samples: int, eigen=None) -> DynamicPayloadSolution:
    return DynamicPayloadSolution(eigen, np.zeros(N_INERTIAL), np.zeros(N_BIAS), 0.0, np.zeros(3),
                                  np.zeros((3, 3)), np.zeros(N_UNKNOWNS), math.inf, Verdict(False, reason),
                                  num_samples)  # fmt: skip


def move_information(state: np.ndarray, moves, samples, torque_length: float = DEFAULT_TORQUE_LENGTH):
    """The information ``M`` the statistic holds on the unknowns ``[phi; b]`` (16) and, for each
    candidate move, the information ``dM`` its samples add (``identification.excitation``; issues 25
    and 26): ``moves[i]`` is the sensor's kinematics ``[w; alpha; a - g]`` in K (m x 9) at points
    along the move, each standing for ``samples[i]`` samples. The unknowns' columns of ``A_t`` are the
    regressor and the bias's identity, which the kinematics alone give; the wrench column is the
    measurement's, not an unknown's. ``state`` is a ``DynamicPayloadIdentifier``'s state
    ``[S (289) | n_eff | count]``. IdentificationError unless ``state`` is a real vector of 291,
    every move a finite (m x 9) array and ``samples`` one number > 0 per move."""
    n2 = N_UNKNOWNS * N_UNKNOWNS
    state = real_array("state", state, (n2 + 2,))
    samples = real_array("samples", samples, (None,))
    if samples.size != len(moves) or not np.all(samples > 0.0):
        raise IdentificationError(f"samples must be one number > 0 per move ({len(moves)}), got {samples}")
    inverse_length = 1.0 / checked_torque_length(torque_length)
    unknowns = slice(0, N_UNKNOWNS - 1)
    added, A = [], _fresh_A(inverse_length)
    for move, weight in zip(moves, samples.tolist(), strict=True):
        dM = np.zeros((N_UNKNOWNS - 1, N_UNKNOWNS - 1))
        for k in real_array("moves[i]", move, (None, KINEMATICS)).tolist():
            Phi = _build_A(np.zeros(6), k, A, inverse_length)[:, unknowns]
            dM += Phi.T @ Phi
        added.append(weight * dM)
    return state[:n2].reshape(N_UNKNOWNS, N_UNKNOWNS)[unknowns, unknowns].copy(), added


@dataclass(frozen=True)
class MoveInformation:
    """``move_information`` as a callable ``(state, moves, samples) -> (M, [dM])`` for
    ``systems.ExcitingPostures``, which gives it the sensor's kinematics along each candidate move
    (``along_move``) with the samples each point stands for."""

    torque_length: float = DEFAULT_TORQUE_LENGTH
    num_unknowns: ClassVar[int] = N_UNKNOWNS
    along_move: ClassVar[bool] = True

    def __call__(self, state, moves, samples):
        return move_information(state, moves, samples, self.torque_length)


class DynamicPayloadIdentifier(FormulationIdentifier):
    """The sustainable identifier with the dynamic payload formulation (module docstring).

    Args:
        forgetting_factor: see ``SustainableIdentifier``.
        criteria: convergence criteria (``default_criteria()`` if None).
        torque_length: ``l`` (m): the torque rows of ``A_t`` are divided by it, so that every row is
            in newtons. With ``l`` the ratio of the sensor's torque noise to its force noise (per
            axis) every row has the same noise, the weighting under which total least squares is
            efficient and the verdict's covariance (one residual variance for all rows) is right;
            with ``l = 1`` a sensor whose torque noise is 40 times smaller than its force noise in
            N m would have its torque rows drowned in the force rows' noise. The default, 0.025 m,
            is the ATI Mini40's 0.0005 N m over 0.02 N (small 6-axis sensors: 0.005-0.05 m).

    Every method raises IdentificationError for an argument of the wrong type, shape or value.
    """

    def __init__(self, forgetting_factor: float = 1.0, criteria: ConvergenceCriteria | None = None,
                 torque_length: float = DEFAULT_TORQUE_LENGTH):  # fmt: skip
        super().__init__(N_UNKNOWNS, forgetting_factor, default_criteria() if criteria is None else criteria)
        self.torque_length = checked_torque_length(torque_length)
        self._inverse_length = 1.0 / self.torque_length
        self._A = _fresh_A(self._inverse_length)

    def add(self, wrench_K: np.ndarray, kinematics_K: np.ndarray) -> None:
        """Adds one sample: the wrench ``[tau_K; f_K]`` and the sensor's ``[w; alpha; a - g]`` in K,
        taken at the same instant.

        Raises:
            IdentificationError: ``wrench_K`` is not a finite 6-vector or ``kinematics_K`` not a
                finite 9-vector (or so large that ``A^T A`` overflows). The state is then unchanged.
        """
        if type(wrench_K) is not np.ndarray or wrench_K.shape != _WRENCH or wrench_K.dtype is not F64:
            wrench_K = real_array("wrench_K", wrench_K, _WRENCH, finite=False)
        k_K = kinematics_K
        if type(k_K) is not np.ndarray or k_K.shape != _KINEMATICS or k_K.dtype is not F64:
            kinematics_K = real_array("kinematics_K", kinematics_K, _KINEMATICS, finite=False)
        k = kinematics_K.tolist()
        # Python floats: entries below 1e60 make A_t's below 1e120, so A^T A cannot overflow (NaN
        # fails the test): the core's fast path without its array checks.
        size = sum(v * v for v in k) + float(wrench_K @ wrench_K)
        if size < _SMALL_SAMPLE:
            self._core._add_product(_build_A(wrench_K, k, self._A, self._inverse_length))
            return
        real_array("wrench_K", wrench_K, _WRENCH)  # NaN or inf: the error names the argument
        real_array("kinematics_K", kinematics_K, _KINEMATICS)
        raise IdentificationError("the sample is too large: A_t^T A_t overflows")

    def sample_error(self, wrench_K: np.ndarray, kinematics_K: np.ndarray, x: np.ndarray) -> float:
        """``s_t = ||A_t x||^2`` (Eq. (2), N^2) for a new sample under the estimate ``x`` (17)."""
        x = real_array("x", x, (N_UNKNOWNS,), finite=False)
        return SustainableIdentifier.sample_error(build_A(wrench_K, kinematics_K, self.torque_length), x)

    def solve(self) -> DynamicPayloadSolution:
        """Solves for ``[phi; b; 1]``: ``v_N`` scaled so that its last entry is 1 (§3.4).

        Conditioning: the columns are equilibrated (``T = diag(1/sqrt(C_jj))``), so that the unit
        norm of TLS weighs kilograms, kg m^2 and newtons alike. Lazy, like ``PayloadIdentifier``.
        """
        cache = self._cached()
        if cache is None:
            cache = self._cache = [self._core._revision, self.criteria, self._solve_tls(), None]
        return cache[2]

    def _solve_tls(self) -> DynamicPayloadSolution:
        core = self._core
        n = core.num_samples
        if n == 0:
            return _empty_solution("no samples", 0)
        weight = core.weight or math.nan
        diag = [s_jj / weight for s_jj in core.S_view.diagonal().tolist()]
        T = np.diag([1.0 / math.sqrt(c_jj if c_jj > 0.0 else 1.0) for c_jj in diag])
        eigen = core.eigen(T)
        if eigen is None:
            return _empty_solution("statistic is not finite (overflow)", n)
        direction = eigen.direction
        h = float(direction[-1])
        if abs(h) <= 1e-12 * max(map(abs, direction.tolist())):
            problem = "the homogeneous entry of v_N is zero: no payload model explains the data"
            return self._judged(_empty_solution(problem, n, eigen), eigen)
        return self._judged(_solution(eigen, direction / h, eigen.lambda_N / (h * h), n), eigen)

    def _judged(self, solution: DynamicPayloadSolution, eigen: EigenSolution) -> DynamicPayloadSolution:
        """``solution`` with the verdict of criteria (a)-(c) and ``observability``'s checks."""
        core, n = self._core, solution.num_samples
        problem = None if solution.verdict.converged else solution.verdict.reason
        rms = math.sqrt(solution.expected_mse) if math.isfinite(solution.expected_mse) else math.inf
        verdict = judge(self.criteria, n, eigen, rms, problem, None, " N")
        verdict = _judge_dynamic_payload(self.criteria, core.S_view, core.weight, n, eigen, solution.x,
                                         verdict)  # fmt: skip
        return dataclasses.replace(solution, verdict=verdict)


def _solution(eigen: EigenSolution, x: np.ndarray, expected_mse: float, n: int) -> DynamicPayloadSolution:
    """The solution of the scaled ``x = [phi; b; 1]``; its verdict says converged unless the
    constraint (c) fails: a positive mass and a physically valid rotational inertia."""
    phi, bias = x[:N_INERTIAL].copy(), x[N_INERTIAL : N_INERTIAL + N_BIAS].copy()
    mass = float(phi[0])
    if not mass > 0.0:
        problem = f"identified mass {mass:.3g} kg is not positive: no payload or wrong wrench sign"
        return DynamicPayloadSolution(eigen, phi, bias, 0.0, np.zeros(3), np.zeros((3, 3)), x, expected_mse,
                                      Verdict(False, problem), n)  # fmt: skip
    _, p_KCm, I_Cm_K = central_inertia(phi)
    problem = physical_inertia_problem(I_Cm_K)
    verdict = Verdict(True, "converged") if problem is None else Verdict(False, f"(c) {problem}")
    return DynamicPayloadSolution(eigen, phi, bias, mass, p_KCm, I_Cm_K, x, expected_mse, verdict, n)
