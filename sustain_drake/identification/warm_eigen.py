"""The smallest eigenpair of a symmetric PSD matrix from a warm start, certified (issue 24).

A streaming identifier that solves after every sample eigen-decomposes a statistic that one sample
has barely changed. Instead of a full ``dsyev``, ``WarmEigen.smallest`` refines the previous solve's
``v_N`` by inverse iteration and proves the result good enough, or returns None (the caller then
runs ``dsyev``). For ``C`` (N x N, symmetric PSD, eigenvalues ``l_1 <= l_2 <= ... <= l_N`` here,
ascending) and a start ``v``:

1. Inverse iteration (up to ``WARM_STEPS`` steps, until 2. accepts): ``y = C^-1 v`` through one
   Cholesky factor of ``C`` (``dpotrf`` once, then ``dpotrs`` and a normalisation per step); each
   step shrinks the error of ``v`` by ``l_1 / l_2`` (the inverse of the gap ratio: 1/10 or less
   where the verdict's criterion (b) holds).
2. Rayleigh quotient and residual: ``theta = v^T C v``, ``r = C v - theta v``.
3. The certificate (Cauchy interlacing for a rank-one PSD update): ``C + alpha v v^T`` with
   ``alpha >= 0`` has its smallest eigenvalue at most ``l_2``, whatever ``v``; so if the Cholesky
   factorisation of ``D = C + trace(C) v v^T - tau I`` succeeds, ``l_2 > tau`` (less the
   factorisation's backward error, ``CERTIFICATE_ATOL``, which ``tau`` includes).
4. Accuracy (backward error): ``v`` is an exact eigenvector of ``C + E`` with
   ``E = -(r v^T + v r^T)``, ``|E| <= 2 |r|``. The result is accepted when
   ``|r| <= RESIDUAL_RTOL trace(C)``, a small multiple of ``dsyev``'s own backward error
   (``p(N) eps |C|``): both are exact for a matrix that close to ``C``, so both are within
   ``|E| / (l_2 - l_1)`` of the true eigenvector (Davis-Kahan) and within ``|E|`` of ``l_1``
   (Weyl), and ``theta`` is an upper bound of ``l_1`` (the Rayleigh quotient).
   With ``l_2 > tau`` from 3., the pair is the smallest one (Kato-Temple:
   ``theta - |r|^2 / (tau - theta) <= l_1 <= theta``). ``tau`` is ``min_gap_ratio`` times ``theta``
   (so ``l_2 / l_1 > min_gap_ratio``: criterion (b) holds exactly as ``dsyev``'s eigenvalues would
   judge it) and at least ``NULL_FLOOR`` times the trace (so ``l_2`` is not zero to round-off: the
   null space is one-dimensional).

Pure numpy/scipy (no pydrake).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import blas, lapack

_EPS = float(np.finfo(float).eps)

# At most this many inverse-iteration steps, the residual judged after each: k steps shrink the
# warm start's error by the gap ratio to the k-th power (at least 10^k where criterion (b) holds).
WARM_STEPS = 4
# The accepted residual |C v - theta v| over trace(C): about 450 eps, a few times the round-off of
# C v itself for N up to a few tens (N eps |C|), and the order of dsyev's own backward error.
RESIDUAL_RTOL = 1e-13
# The backward error of the certificate's Cholesky factorisation of D (|D| <= 2 trace(C)), bounded
# generously: 2 N eps |D| for N up to 64; tau carries it so that the proof holds in floating point.
CERTIFICATE_ATOL = 256.0 * _EPS
# l_2 must exceed this fraction of the trace (twice sustainable_identifier.NULL_EIGENVALUE_RTOL,
# whose count of zero eigenvalues it then makes 1 for dsyev's eigenvalues too).
NULL_FLOOR = 2e-12
# theta must be this far above round-off (times eps trace(C)) for the relative bounds to mean
# anything: a noise-free statistic's l_1 is round-off, and dsyev judges it.
MIN_THETA = 1e3 * _EPS
# tau's relative margin above min_gap_ratio * theta, against dsyev's rounding of l_1 and l_2.
GAP_MARGIN = 1e-8


class WarmEigen:
    """The buffers of ``smallest`` for N x N matrices (one per identifier: no allocation of the
    factors per solve). Its calls are BLAS/LAPACK's own (``scipy.linalg.blas``/``lapack``): on
    vectors of 16 they cost a fifth of numpy's dispatch."""

    def __init__(self, num_unknowns: int):
        n = self._n = num_unknowns
        self._F = np.empty((n, n))  # the Cholesky factor of C
        self._D = np.empty((n, n))  # the certificate's matrix, then its factor
        self._F_flat, self._D_flat = self._F.reshape(-1), self._D.reshape(-1)
        self._ones = np.ones(n)

    def smallest(self, C: np.ndarray, v: np.ndarray, min_gap_ratio: float) -> tuple[float, np.ndarray] | None:
        """``(l_1, v_1)`` of the symmetric PSD ``C`` (C-contiguous float64 N x N, not modified) from
        the unit start ``v``, certified as the module docstring states with
        ``l_2 / l_1 > min_gap_ratio``; None when it cannot be (the gap is not open, the start is too
        far, ``C`` is singular or not finite): the caller then runs the full eigen-solve. ``v_1`` is
        a new array."""
        n, F, D = self._n, self._F, self._D
        np.copyto(F, C)
        trace = blas.dasum(self._F_flat, n=n, incx=n + 1)  # C's diagonal is >= 0 (PSD)
        if not 0.0 < trace < math.inf:
            return None
        # C is symmetric: its transpose is the same matrix in Fortran order (LAPACK's).
        _, info = lapack.dpotrf(F.T, overwrite_a=1, clean=0)
        if info != 0:  # l_1 zero to round-off (or not finite): dsyev decides
            return None
        tolerance = RESIDUAL_RTOL * trace
        y = v
        for _ in range(WARM_STEPS):
            y, _ = lapack.dpotrs(F.T, y)  # y = C^-1 y
            size = blas.dnrm2(y)
            if not 0.0 < size < math.inf:
                return None
            y = blas.dscal(1.0 / size, y)
            Cy = blas.dsymv(1.0, C, y)
            theta = blas.ddot(y, Cy)
            if blas.dnrm2(blas.daxpy(y, Cy, a=-theta)) <= tolerance:  # |C y - theta y|
                break
        else:
            return None
        if not theta >= MIN_THETA * trace:
            return None
        # The certificate: D = C + trace(C) y y^T - tau I positive definite proves l_2 > tau.
        tau = max(min_gap_ratio * theta * (1.0 + GAP_MARGIN), NULL_FLOOR * trace)
        tau += (min_gap_ratio + 1.0) * CERTIFICATE_ATOL * trace
        np.copyto(D, C)
        blas.daxpy(self._ones, self._D_flat, n=n, a=-tau, incy=n + 1)  # D's diagonal -= tau
        blas.dsyr(trace, y, a=D.T, overwrite_a=1)  # the triangle of D.T that dpotrf reads
        _, info = lapack.dpotrf(D.T, overwrite_a=1, clean=0)
        if info != 0:
            return None
        return theta, y
