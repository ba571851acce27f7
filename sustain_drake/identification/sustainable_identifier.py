"""The sustainable identifier of the paper's §3.1 (Eqs. (1)-(13)), for any linear formulation.

Every measurement gives a linear constraint ``A_t x = 0`` (``A_t`` is M x N). Only the N x N
second-moment statistic is kept::

    S_t = sum_t w_t A_t^T A_t,    n_t = sum_t w_t,    C_t = S_t / n_t           (Eq. (3))

so memory and time per sample are O(N^2) however many samples arrive. (With a forgetting
factor ``f`` in (0, 1], older samples are down-weighted, ``w_t = f^(age)``; ``f = 1`` is the paper.)
The model is the eigenvector ``v_N`` of the smallest eigenvalue ``lambda_N`` of ``C`` (total least
squares, Eqs. (7)-(12)); scaled by a constraint, ``x = a v_N``, its expected mean squared error is
``a^2 lambda_N`` (Eq. (13)).

Conditioning. TLS is not invariant to the scale and offset of the data, so formulations give a
conditioning transform ``T`` at solve time (``x = T x'``); the eigen-problem is solved on
``C' = T^T C T`` (the raw statistic is kept, so memory stays constant). The eigenvalues reported
are those of ``C'``; ``x = a T v'_N`` and the expected mean squared error is still ``a^2 lambda'_N``.

All state lives in one flat float64 vector (``state``), so that a Drake system can keep it in its
context and contexts can be cloned.

Bad arguments raise ``IdentificationError`` (a ``ValueError``, see ``errors``) with a one-line
message naming the argument.

This module is pure numpy/scipy (no pydrake).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack

from sustain_drake.identification.errors import (
    F64,
    IdentificationError,
    check_finite,
    describe,
    instance,
    integer,
    real_array,
    real_number,
    to_float_array,
)

# Eigenvalues below this fraction of lambda_1 are taken as exactly zero (round-off of a 16 x 16
# symmetric eigen-solver in float64 is ~1e-16 lambda_1).
NULL_EIGENVALUE_RTOL = 1e-12

# The largest N a SustainableIdentifier accepts (its state is N^2 + 2 floats; the formulations
# have 16 and 5).
MAX_UNKNOWNS = 1000


@dataclass(frozen=True)
class ConvergenceCriteria:
    """The paper's three reliability criteria (§3.1 (a), (b), (c)) plus a sample count.

    Attributes:
        max_expected_rms: (a) the identification's expected per-sample RMS error
            ``sqrt(a^2 lambda_N)`` must not exceed this, in the formulation's residual units
            (metres for eye-to-hand). This is the physical form of the paper's
            ``lambda_16 < 5e-5``: it does not depend on how ``v_N`` is normalised.
        min_gap_ratio: (b) ``lambda_{N-1} / lambda_N`` must be at least this (the null space is
            one-dimensional: the motion was rich enough).
        max_ssd: (c) for formulations with a rotation, the Challis SSD of §3.2 must not exceed
            this (paper: 0.1). ``None`` for formulations without a rotation.
        min_samples: fewer samples than this is never converged (with exactly as many equations
            as unknowns the fit is exact whatever the noise, and ``lambda_N = 0`` says nothing).

    Raises IdentificationError for a setting of the wrong type or out of its range.
    """

    max_expected_rms: float
    min_gap_ratio: float = 10.0
    max_ssd: float | None = 0.1
    min_samples: int = 10

    def __post_init__(self):
        rms = real_number("max_expected_rms", self.max_expected_rms, what="a positive number")
        if not rms > 0:
            raise IdentificationError(f"max_expected_rms must be positive, got {rms}")
        gap = real_number("min_gap_ratio", self.min_gap_ratio, finite=False, what="a number >= 1")
        if not gap >= 1:
            raise IdentificationError(f"min_gap_ratio must be >= 1, got {gap}")
        if self.max_ssd is not None:
            ssd = real_number("max_ssd", self.max_ssd, finite=False, what="a positive number or None")
            if not ssd > 0:
                raise IdentificationError(f"max_ssd must be positive or None, got {ssd}")
        integer("min_samples", self.min_samples, 1)


@dataclass(frozen=True, slots=True)
class Verdict:
    """Whether an identification has converged, and if not, the first reason why not."""

    converged: bool
    reason: str

    def __bool__(self) -> bool:
        return self.converged

    def __str__(self) -> str:
        return "converged" if self.converged else f"not converged: {self.reason}"


@dataclass(frozen=True, slots=True)
class EigenSolution:
    """The eigen-decomposition of the (conditioned) statistic, Eqs. (7)-(12).

    Attributes:
        eigenvalues: ``lambda_1 >= ... >= lambda_N >= 0`` of ``C' = T^T C T``.
        v_N: the unit eigenvector of ``lambda_N``, in the conditioned coordinates ``x'``.
        direction: ``T v_N``, the same direction in the raw parameters ``x`` (not unit).
        num_null: how many eigenvalues are zero to round-off (>= 2 means the motion was not
            rich enough: the null space is more than one-dimensional). It is 1 both when only
            ``lambda_N`` is zero and when none is; the count is exact when it is 2 or more.
    """

    eigenvalues: np.ndarray
    v_N: np.ndarray
    direction: np.ndarray
    num_null: int

    @property
    def lambda_N(self) -> float:
        return float(self.eigenvalues[-1])

    @property
    def lambda_N_minus_1(self) -> float:
        return float(self.eigenvalues[-2])

    @property
    def gap_ratio(self) -> float:
        """``lambda_{N-1} / lambda_N`` (inf when ``lambda_N`` is zero and ``lambda_{N-1}`` is not)."""
        if self.num_null >= 2:
            return 1.0
        lambda_N_minus_1, lambda_N = self.eigenvalues[-2:].tolist()
        if lambda_N <= 0.0:
            return math.inf
        return lambda_N_minus_1 / lambda_N


def judge(
    criteria: ConvergenceCriteria,
    num_samples: int,
    eigen: EigenSolution | None,
    expected_rms: float,
    constraint_problem: str | None,
    ssd: float | None = None,
    rms_unit: str = "",
) -> Verdict:
    """Applies the paper's criteria (a), (b), (c) in an order that gives the most useful reason.

    Never judges from ``lambda_N`` alone: with too few or too similar samples ``lambda_N`` is 0
    because the null space has several dimensions, and that is "not converged". Raises
    IdentificationError for an argument of the wrong type.
    """
    if not (type(criteria) is ConvergenceCriteria and type(num_samples) is int
            and (eigen is None or type(eigen) is EigenSolution) and type(expected_rms) is float
            and (constraint_problem is None or type(constraint_problem) is str)
            and (ssd is None or type(ssd) is float) and type(rms_unit) is str):  # fmt: skip
        # Not the solves' own types: numpy numbers and subclasses pass, anything else is an error.
        _check_judge_arguments(criteria, num_samples, eigen, expected_rms, constraint_problem, ssd, rms_unit)
    return _judge(criteria, num_samples, eigen, expected_rms, constraint_problem, ssd, rms_unit)


def _judge(criteria, num_samples, eigen, expected_rms, constraint_problem, ssd, rms_unit) -> Verdict:
    if eigen is None:
        return Verdict(False, "no samples")
    if num_samples < criteria.min_samples:
        return Verdict(False, f"too few samples: {num_samples} < {criteria.min_samples}")
    if eigen.num_null >= 2:
        return Verdict(
            False,
            f"motion not rich enough: the null space is {eigen.num_null}-dimensional "
            "(e.g. pure translation of the hand, or too few distinct samples)",
        )
    if eigen.gap_ratio < criteria.min_gap_ratio:
        return Verdict(
            False,
            f"eigenvalue gap too small: lambda_N-1/lambda_N = {eigen.gap_ratio:.3g} < "
            f"{criteria.min_gap_ratio:.3g} (motion not rich enough yet)",
        )
    if constraint_problem is not None:
        return Verdict(False, constraint_problem)
    if criteria.max_ssd is not None and ssd is not None and not ssd <= criteria.max_ssd:
        return Verdict(False, f"not a rotation: SSD {ssd:.3g} > {criteria.max_ssd:.3g}")
    if not expected_rms <= criteria.max_expected_rms:
        return Verdict(
            False,
            f"expected RMS error {expected_rms:.3g}{rms_unit} > {criteria.max_expected_rms:.3g}{rms_unit}",
        )
    return Verdict(True, "converged")


def _check_judge_arguments(criteria, num_samples, eigen, expected_rms, constraint_problem, ssd, rms_unit):
    """IdentificationError naming the first argument of ``judge`` of the wrong type."""
    instance("criteria", criteria, ConvergenceCriteria, "a ConvergenceCriteria")
    integer("num_samples", num_samples, 0)
    instance("eigen", eigen, EigenSolution, "an EigenSolution or None", optional=True)
    real_number("expected_rms", expected_rms, finite=False)
    instance("constraint_problem", constraint_problem, str, "a string or None", optional=True)
    if ssd is not None:
        real_number("ssd", ssd, finite=False, what="a real number or None")
    instance("rms_unit", rms_unit, str, "a string")


class SustainableIdentifier:
    """Accumulates ``S = sum w A_t^T A_t`` in O(N^2) per sample and solves it at any time (§3.1).

    Formulations (eye-to-hand, payload) build ``A_t`` and compute their conditioning transform
    from the statistic itself (its entries hold the running sums they need).

    Args:
        num_unknowns: N (2 to ``MAX_UNKNOWNS``).
        forgetting_factor: ``f`` in (0, 1]; each new sample first multiplies the statistic by
            ``f``. 1 (the default) is the paper's plain mean.

    Every method raises IdentificationError for an argument of the wrong type, shape or value.
    """

    def __init__(self, num_unknowns: int, forgetting_factor: float = 1.0):
        self._N = integer("num_unknowns", num_unknowns, 2, MAX_UNKNOWNS)
        forgetting = real_number("forgetting_factor", forgetting_factor, what="a number in (0, 1]")
        if not 0.0 < forgetting <= 1.0:
            raise IdentificationError(f"forgetting_factor must be in (0, 1], got {forgetting}")
        self._forgetting = forgetting
        # Layout: [S (N*N, row-major) | n_eff | count]. Everything but the count is scaled by the
        # forgetting factor, so it is one contiguous slice.
        n2 = self._N * self._N
        self._n_index = n2
        self._state = np.zeros(n2 + 2)
        self._S = self._state[:n2].reshape(self._N, self._N)
        self._weighted = self._state[:-1]
        # One sample's increment in the same layout, [A^T A | 1 | 1]: ``add`` is one vector sum.
        self._increment = np.zeros(n2 + 2)
        self._increment[n2:] = 1.0
        self._AtA = self._increment[:n2].reshape(self._N, self._N)
        self._TtS = np.empty((self._N, self._N))  # scratch for T^T S
        self._revision = 0

    # ---- state ----------------------------------------------------------------------------
    @property
    def num_unknowns(self) -> int:
        return self._N

    @property
    def forgetting_factor(self) -> float:
        return self._forgetting

    @property
    def state(self) -> np.ndarray:
        """A copy of the whole state as one flat vector (constant size, whatever the samples)."""
        return self._state.copy()

    def set_state(self, state: np.ndarray) -> None:
        """Replaces the whole state (``state``'s layout). Raises IdentificationError unless ``state``
        is a real vector of ``state_size`` (NaN and inf pass: an overflowed statistic round-trips)."""
        array = state if type(state) is np.ndarray and state.dtype is F64 else to_float_array(
            "state", state, "a vector")
        if array.shape != self._state.shape:
            raise IdentificationError(f"state must have shape {self._state.shape}, got {describe(state)}")
        self._state[:] = array
        self._revision += 1

    @property
    def state_size(self) -> int:
        return self._state.size

    def reset(self) -> None:
        """Forgets every sample (the paper's "renew C at the beginning of each identification")."""
        self._state[:] = 0.0
        self._revision += 1

    @property
    def revision(self) -> int:
        """Counts the changes of the state (``add``, ``set_state``, ``reset``): a result computed
        at one revision is stale at any other."""
        return self._revision

    @property
    def num_samples(self) -> int:
        """Samples added since the last reset (not down-weighted by forgetting)."""
        return round(float(self._state[-1]))

    @property
    def weight(self) -> float:
        """``n_t``: the (forgetting-weighted) number of samples."""
        return float(self._state[self._n_index])

    @property
    def S(self) -> np.ndarray:
        """``n_t C_t``: the weighted sum of ``A_t^T A_t`` (a copy)."""
        return self._S.copy()

    @property
    def S_view(self) -> np.ndarray:
        """``S`` without a copy (read-only use: it changes with the next sample)."""
        return self._S

    @property
    def C(self) -> np.ndarray:
        """``C_t = S_t / n_t``, Eq. (3) (zeros before any sample)."""
        n = self.weight
        return self._S / n if n > 0 else np.zeros_like(self._S)

    # ---- samples --------------------------------------------------------------------------
    def add(self, A: np.ndarray) -> None:
        """Adds one sample's ``A_t`` (M x N, M >= 1). O(N^2) time, no growth.

        Raises:
            IdentificationError: ``A`` is not a real M x N matrix, or it is not finite (or
                ``A^T A`` overflows). The state is then unchanged.
        """
        AtA = self._AtA
        try:
            # Entries this small cannot make A^T A or its sum overflow (NaN and inf fail the test),
            # so the usual sample needs neither numpy's error state nor a check of the product.
            largest = float(np.abs(A).max())
            small = largest * largest * A.shape[0] * AtA.size < 1e300
            if small:
                np.dot(A.T, A, out=AtA)  # float64 with N columns: straight into the buffer
        except (ValueError, TypeError, AttributeError, IndexError):  # another type, dtype, shape: checked
            small = False
        if not small:
            A = self._checked_sample(A)
            # One scalar check catches NaN, inf and overflow in A^T A (a NaN or inf makes the sum
            # non-finite), before anything is committed to the state; numpy's warnings are
            # replaced by that one clear error.
            with np.errstate(over="ignore", invalid="ignore"):
                try:
                    np.dot(A.T, A, out=AtA)
                except ValueError:  # another dtype: the general product
                    AtA[...] = A.T @ A
                total = AtA.sum()
            if not math.isfinite(total):
                raise IdentificationError("sample is not finite (NaN, inf or overflow)")
        self._commit()

    def _checked_sample(self, A) -> np.ndarray:
        """``A`` as a real array with N columns and a row at least (an array of integers or floats
        is kept as it is), else IdentificationError."""
        what = f"an M x {self._N} matrix (M >= 1 rows, {self._N} columns)"
        if not (isinstance(A, np.ndarray) and A.dtype.kind in "iuf"):
            A = to_float_array("A_t", A, what)
        if A.ndim != 2 or A.shape[1] != self._N or A.shape[0] == 0:
            raise IdentificationError(f"A_t must be {what}, got shape {A.shape}")
        return A

    def _add_product(self, A: np.ndarray) -> None:
        """``add`` for a float64 M x N ``A`` whose entries the caller has checked to be finite and
        below 1e100 in size (``add``'s fast path without its check)."""
        np.dot(A.T, A, out=self._AtA)
        self._commit()

    def _commit(self) -> None:
        """Adds the increment ``[A^T A | 1 | 1]`` to the state (after forgetting)."""
        if self._forgetting != 1.0:
            self._weighted *= self._forgetting
        self._state += self._increment  # S += A^T A, n_t += 1, count += 1
        self._revision += 1

    # ---- solving --------------------------------------------------------------------------
    def eigen(self, T: np.ndarray | None = None) -> EigenSolution | None:
        """Eigen-decomposes ``C' = T^T C T`` (``T``, the conditioning transform with
        ``x = T x'``, defaults to the identity).

        Returns None before any sample, or when the statistic is not finite (overflow). Raises
        IdentificationError unless ``T`` is None or a real N x N matrix, finite when the statistic
        is (checked only when the solve fails, so it costs the formulations' solves nothing).
        """
        if T is not None and not (type(T) is np.ndarray and T.dtype is F64 and T.shape == self._S.shape):
            T = real_array("T", T, self._S.shape, finite=False)
        n = float(self._state[self._n_index])
        if n <= 0.0:
            return None
        eigen = self._eigen(n, T)
        if eigen is None and T is not None and np.isfinite(self._S).all():
            check_finite("T", T)
        return eigen

    def _eigen(self, n: float, T: np.ndarray | None) -> EigenSolution | None:
        """``eigen`` after its checks, with ``n > 0`` the weight."""
        if T is None:
            C, overwrite = self._S, 0
        else:
            try:
                C = np.dot(np.dot(T.T, self._S, out=self._TtS), T)  # the same products as T.T @ S @ T
            except ValueError:  # T not C-contiguous float64 (a view): the general product
                C = T.T @ self._S @ T
            overwrite = 1
        # C is symmetric PSD, so a symmetric eigen-solver is the right tool, not a general SVD.
        # (LAPACK's partial solvers dsyevr/dsyevx for the few smallest are no faster at N = 16.)
        # C is symmetric, so its transpose is the same matrix in Fortran order: no copy for LAPACK.
        w, V, info = lapack.dsyev(C.T, overwrite_a=overwrite)
        if info != 0:
            return None
        # Eigenvalues come ascending; NaN anywhere (from a non-finite statistic) reaches the sum.
        ascending = w.tolist()
        if not math.isfinite(sum(ascending)):
            return None
        scale = 1.0 / n
        w = w[::-1] * scale  # of C = S/n, descending: lambda_1 >= ... >= lambda_N
        lambda_1, lambda_N_minus_1 = ascending[-1] * scale, ascending[1] * scale
        if ascending[0] * scale < 0.0:
            w = np.maximum(w, 0.0)  # clip round-off below zero (C is PSD)
            lambda_1, lambda_N_minus_1 = max(lambda_1, 0.0), max(lambda_N_minus_1, 0.0)
        v_N = V[:, 0]
        tol = NULL_EIGENVALUE_RTOL * lambda_1
        num_null = 1 if lambda_N_minus_1 > tol else int((w <= tol).sum())
        direction = v_N if T is None else np.dot(T, v_N)
        return EigenSolution(w, v_N, direction, num_null)

    @staticmethod
    def sample_error(A: np.ndarray, x: np.ndarray) -> float:
        """``s_t = ||A_t x||^2``, Eq. (2): the error of one sample under an estimate ``x``.

        Raises IdentificationError unless ``A`` is a real M x N matrix and ``x`` a real N-vector
        (NaN or inf entries give a non-finite error, not an exception)."""
        if not (type(A) is np.ndarray and type(x) is np.ndarray and A.dtype is F64 and x.dtype is F64
                and A.ndim == 2 and x.ndim == 1 and A.shape[1] == x.shape[0]):  # fmt: skip
            A = real_array("A", A, (None, None), finite=False, what="an M x N matrix")
            x = real_array("x", x, (A.shape[1],), finite=False)
        r = A @ x
        return float(r @ r)

    def mean_squared_error(self, x: np.ndarray) -> float:
        """``S_t = x^T C_t x``, Eq. (3): the mean of ``s_t`` over the accumulated samples.

        Raises IdentificationError before any sample, or unless ``x`` is a real N-vector (NaN or
        inf entries give a non-finite result)."""
        x = real_array("x", x, (self._N,), finite=False)
        n = self.weight
        if n <= 0.0:
            raise IdentificationError("no samples to compute a mean squared error from")
        return float(x @ self._S @ x) / n


class FormulationIdentifier:
    """Base of the formulations' identifiers: owns a ``SustainableIdentifier`` (``core``) and
    forwards its state handling, so a formulation only adds how a sample becomes ``A_t`` and how
    ``v_N`` is scaled.

    Solving is lazy: ``add`` only updates the statistic, and ``solve`` computes a solution on the
    first call after a change and returns that same object until the core's ``revision`` or
    ``criteria`` changes (treat it as read-only). A caller that adds many samples and reads once
    pays one eigen-solve."""

    def __init__(self, num_unknowns: int, forgetting_factor: float, criteria: ConvergenceCriteria):
        self._core = SustainableIdentifier(num_unknowns, forgetting_factor)
        self.criteria = instance("criteria", criteria, ConvergenceCriteria, "a ConvergenceCriteria or None")
        # [core revision, criteria, solution, refined solution or None] of the last solve.
        self._cache: list | None = None

    def _cached(self) -> list | None:
        """The cache entry if it is still current, else None."""
        cache = self._cache
        if cache is not None and cache[0] == self._core._revision and cache[1] is self.criteria:
            return cache
        return None

    @property
    def core(self) -> SustainableIdentifier:
        return self._core

    @property
    def num_samples(self) -> int:
        return self._core.num_samples

    @property
    def state(self) -> np.ndarray:
        """The whole state as one flat vector (a copy)."""
        return self._core.state

    def set_state(self, state: np.ndarray) -> None:
        """The core's ``set_state`` (IdentificationError unless ``state`` is a real vector of its size)."""
        self._core.set_state(state)

    def reset(self) -> None:
        self._core.reset()


class SolutionProperties:
    """Properties shared by the formulations' solution dataclasses, which have the fields
    ``eigen`` (``EigenSolution`` or None) and ``expected_mse``, and a class constant
    ``num_unknowns``."""

    __slots__ = ()

    @property
    def eigenvalues(self) -> np.ndarray:
        """``lambda_1 >= ... >= lambda_N`` (zeros before any sample)."""
        return self.eigen.eigenvalues if self.eigen is not None else np.zeros(self.num_unknowns)

    @property
    def expected_rms(self) -> float:
        """``sqrt(a^2 lambda_N)``, the identification's own per-sample RMS error prediction."""
        return math.sqrt(max(self.expected_mse, 0.0))
