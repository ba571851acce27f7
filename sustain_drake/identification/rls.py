"""Recursive least squares with exponential forgetting: the baseline the dynamic payload identifier
is compared with (issue 26), pure numpy.

For a sample of ``M`` equations ``y_t = Y_t theta + e_t`` (``Y_t`` M x N) and a forgetting factor
``lambda`` in (0, 1] (the textbook form of exponentially weighted least squares)::

    K_t     = P_{t-1} Y_t^T (lambda I_M + Y_t P_{t-1} Y_t^T)^-1
    theta_t = theta_{t-1} + K_t (y_t - Y_t theta_{t-1})
    P_t     = (P_{t-1} - K_t Y_t P_{t-1}) / lambda

from ``theta_0 = 0`` and ``P_0 = initial_variance I``. ``P_t`` is the inverse of the forgetting-
weighted information ``lambda^t / P_0 + sum lambda^(t-k) Y_k^T Y_k``; the parameters' covariance is
``sigma^2 P_t``, ``sigma^2`` the residual variance per equation: the weighted least-squares cost of
``theta_t``, ``J_t = lambda J_{t-1} + e_t^T eps_t`` (``e_t`` the residuals before the update, ``eps_t``
after), over ``M n_eff - N``.

``DynamicPayloadRLS`` applies it to the dynamic payload: ``theta = [phi; b]`` (16) and
``[Y_t, I_6] theta = wrench_t`` with the regressor of ``payload_dynamic`` (torque rows divided by the
same torque length), so both identifiers see the same equations. Unlike the sustainable identifier,
RLS has no verdict of its own: ``DynamicPayloadRLS.identified`` applies the dynamic verdict's accuracy
(``dynamic_observability.accuracy_problem``: every 95 % region within its bound) to its covariance, and
nothing else.

Every public function and method raises ``IdentificationError`` (a ``ValueError``) with a one-line
message for an argument of the wrong type, shape or value.
"""

from __future__ import annotations

import math

import numpy as np

from sustain_drake.identification import payload_dynamic as dynamic
from sustain_drake.identification.dynamic_observability import accuracy_problem
from sustain_drake.identification.errors import IdentificationError, integer, real_array, real_number


class RecursiveLeastSquares:
    """The RLS recursion of the module docstring for ``num_unknowns`` parameters.

    Args:
        num_unknowns: N (>= 1).
        forgetting_factor: ``lambda`` in (0, 1]; 1 is plain least squares.
        initial_variance: ``P_0 = initial_variance I`` (> 0): the prior's variance of each parameter
            about 0 (large: a weak prior).
    """

    def __init__(self, num_unknowns: int, forgetting_factor: float = 1.0, initial_variance: float = 1e4):
        self._N = integer("num_unknowns", num_unknowns, 1)
        self._lambda = real_number("forgetting_factor", forgetting_factor, what="a number in (0, 1]")
        if not 0.0 < self._lambda <= 1.0:
            raise IdentificationError(f"forgetting_factor must be in (0, 1], got {self._lambda}")
        variance = real_number("initial_variance", initial_variance, what="a positive number")
        if not variance > 0.0:
            raise IdentificationError(f"initial_variance must be positive, got {variance}")
        self.theta = np.zeros(self._N)
        self.P = variance * np.eye(self._N)
        self.num_samples = 0
        self._equations = 0.0  # forgetting-weighted count of equations
        self._sse = 0.0  # forgetting-weighted sum of squared a-posteriori residuals

    def add(self, Y: np.ndarray, y: np.ndarray) -> None:
        """One sample: ``y`` (M) = ``Y`` (M x N) ``theta`` + noise. IdentificationError unless they
        are finite and of matching shapes."""
        Y = real_array("Y", Y, (None, self._N))
        y = real_array("y", y, (Y.shape[0],))
        PYt = self.P @ Y.T
        gain = np.linalg.solve(self._lambda * np.eye(Y.shape[0]) + Y @ PYt, PYt.T).T
        prior = y - Y @ self.theta
        self.theta = self.theta + gain @ prior
        P = (self.P - gain @ PYt.T) / self._lambda
        self.P = (P + P.T) / 2.0
        # The weighted least-squares cost's own recursion: J_t = lambda J_{t-1} + e_prior^T e_posterior.
        self._sse = self._lambda * self._sse + float(prior @ (y - Y @ self.theta))
        self._equations = self._lambda * self._equations + Y.shape[0]
        self.num_samples += 1

    @property
    def residual_variance(self) -> float:
        """``sigma^2``: the forgetting-weighted residual variance per equation (inf before more
        equations than unknowns)."""
        dof = self._equations - self._N
        return self._sse / dof if dof > 0.0 else math.inf

    @property
    def covariance(self) -> np.ndarray:
        """``sigma^2 P``: the parameters' covariance (inf before enough equations)."""
        return self.residual_variance * self.P


class DynamicPayloadRLS:
    """RLS on the dynamic payload's equations ``[Y_t, I_6] [phi; b] = wrench_t`` (module docstring).

    Args:
        forgetting_factor: ``lambda`` (per sample of 6 equations).
        initial_variance: ``P_0`` (parameters in kg, kg m, kg m^2, N m and N).
        torque_length: the torque rows are divided by it (as ``DynamicPayloadIdentifier``'s).
    """

    def __init__(self, forgetting_factor: float = 0.999, initial_variance: float = 1e4,
                 torque_length: float = dynamic.DEFAULT_TORQUE_LENGTH):  # fmt: skip
        self._rls = RecursiveLeastSquares(dynamic.N_UNKNOWNS - 1, forgetting_factor, initial_variance)
        self._A = np.zeros((dynamic.M_ROWS, dynamic.N_UNKNOWNS))
        self._length = dynamic.checked_torque_length(torque_length)

    def add(self, wrench_K: np.ndarray, kinematics_K: np.ndarray) -> None:
        """One sample, as ``DynamicPayloadIdentifier.add``."""
        A = dynamic.build_A(wrench_K, kinematics_K, self._length, self._A)
        self._rls.add(A[:, :-1], -A[:, -1])

    @property
    def num_samples(self) -> int:
        return self._rls.num_samples

    @property
    def phi(self) -> np.ndarray:
        """The inertial parameters' estimate (10)."""
        return self._rls.theta[: dynamic.N_INERTIAL].copy()

    @property
    def bias(self) -> np.ndarray:
        """The bias's estimate ``[b_tau; b_f]`` (6)."""
        return self._rls.theta[dynamic.N_INERTIAL :].copy()

    @property
    def covariance(self) -> np.ndarray:
        """The covariance (16 x 16) of ``[phi; b]``."""
        return self._rls.covariance

    def identified(self) -> bool:
        """Whether the estimate is physically valid and its 95 % regions lie within the dynamic
        verdict's accuracy (``dynamic_observability.accuracy_problem``): RLS's own "identified"."""
        theta, covariance = self._rls.theta, self._rls.covariance
        if not (theta[0] > 0.0 and np.isfinite(covariance).all() and np.isfinite(theta).all()):
            return False
        _, _, I_Cm = dynamic.central_inertia(theta[: dynamic.N_INERTIAL])
        if dynamic.physical_inertia_problem(I_Cm) is not None:
            return False
        return accuracy_problem(covariance, theta) is None
