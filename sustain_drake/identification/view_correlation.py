"""How many independent samples a tracked point's samples are worth when part of its error repeats
with its view (beyond the paper, which takes every sample as independent; pure numpy).

A point's refined place and the depth fitted on its patch come out alike each time the camera sees
the patch alike, so samples taken from nearly one view share an error. The samples are grouped
into views (the caller's grouping, ``candidates.admission``), and each sample's Eq. (30) residual
``e = R_WC p_CP + p_WC - R_WH p_HP - p_WH`` is modelled as a one-way random effect: a draw per view
(variance ``sigma_b^2`` per axis) plus a draw per sample (``sigma_w^2``). The share of the variance
that repeats, ``rho = sigma_b^2 / (sigma_b^2 + sigma_w^2)``, is estimated from the point's own
residuals at the fitted camera (the analysis of variance between and within its views), and its
``n`` samples count as ``n / (1 + (m - 1) rho)`` independent ones (Kish's design effect; ``m =
sum n_v^2 / n``, the mean view size a sample sees). At a wrong camera the residuals follow the
view too, so the count falls further: the covariance cannot shrink by agreeing with itself.

A view's sums (``ViewSums`` rows, 16 numbers: the count ``n_v``, ``sum p_CP``, ``vec sum R_WH``
column-major, ``sum p_WH``) make its mean residual linear in the unknowns, so nothing per sample is
kept.
"""

from __future__ import annotations

import numpy as np

from sustain_drake.identification.errors import (
    VECTOR3,
    IdentificationError,
    describe,
    real_array,
    rotation,
)
from sustain_drake.identification.eye_to_hand import N_UNKNOWNS, _pack_x
from sustain_drake.identification.eye_to_hand_points import ROUND_OFF_VARIANCE

VIEW_ROW = 16  # a view's sums: n_v, sum p_CP (3), vec sum R_WH (9, column-major), sum p_WH (3)

# Fewest views, and fewest samples beyond one per view, for the shares between and within views
# to be told apart (two degrees of freedom each, per axis): with fewer, every view counts as one
# sample (rho = 1), the bound when the data cannot tell.
MIN_VIEWS = 3
MIN_REPEATS = 3


def view_row(p_CP, R_WH, p_WH) -> np.ndarray:
    """One sample's contribution to its view's sums (``VIEW_ROW`` numbers; add the rows of a view's
    samples), from the sample as ``EyeToHandIdentifier.add`` takes it (m, a rotation).
    IdentificationError for arguments of the wrong shape, not finite or not a rotation."""
    return _view_row(real_array("p_CP", p_CP, VECTOR3), rotation("R_WH", R_WH),
                     real_array("p_WH", p_WH, VECTOR3))


def _view_row(p_CP, R_WH, p_WH) -> np.ndarray:
    """``view_row`` unchecked, for a sample an identifier has taken (and so checked)."""
    R = np.asarray(R_WH, dtype=float).reshape(9, order="F")
    return np.concatenate([[1.0], np.asarray(p_CP, dtype=float), R, np.asarray(p_WH, dtype=float)])


def _view_residual_sums(views: np.ndarray, R_WC: np.ndarray, p_WC: np.ndarray, p_HP: np.ndarray):
    """Per view, the sum of its samples' Eq. (30) residuals (V x 3, m)."""
    n, p_C, R_WH, p_W = views[:, 0], views[:, 1:4], views[:, 4:13], views[:, 13:16]
    turned = np.einsum("vij,j->vi", R_WH.reshape(-1, 3, 3).transpose(0, 2, 1), p_HP)
    return p_C @ R_WC.T + n[:, None] * p_WC - turned - p_W


def repeated_share(views, S, R_WC, p_WC, p_HP) -> float:
    """``rho``: the share of a point's residual variance that repeats within a view, from its
    samples' raw statistic ``S`` (16 x 16, ``x^T S x`` the sum of squared residuals) and its
    views' sums (V x ``VIEW_ROW``, their counts summing to the statistic's samples) at the camera
    ``(R_WC, p_WC)`` and its ``p_HP``: the one-way analysis of variance (module docstring), clipped
    to [0, 1]; 1 with fewer than ``MIN_VIEWS`` views or ``MIN_REPEATS`` samples beyond one per
    view. IdentificationError for arguments of the wrong shape, not finite or not a rotation."""
    views, S, R_WC, p_WC, p_HP = _checked(views, S, R_WC, p_WC, p_HP)
    return _repeated_share(views, S, R_WC, p_WC, p_HP)


def _repeated_share(views, S, R_WC, p_WC, p_HP) -> float:
    counts = views[:, 0]
    n, V = float(counts.sum()), len(counts)
    if V < MIN_VIEWS or n - V < MIN_REPEATS:
        return 1.0
    x = _pack_x(R_WC, p_WC, p_HP)
    total = max(float(x @ S @ x), 0.0)
    sums = _view_residual_sums(views, R_WC, p_WC, p_HP)
    between = float(((sums**2).sum(axis=1) / np.maximum(counts, 1.0)).sum())
    within = max(total - between, 0.0) / (3.0 * (n - V))  # sigma_w^2
    size = (n - float((counts**2).sum()) / n) / (V - 1)  # n_0: the views' effective size
    repeated = max(between / (3.0 * (V - 1)) - within, 0.0) / size  # sigma_b^2
    if not repeated + within > ROUND_OFF_VARIANCE:
        return 0.0  # noise-free (round-off): nothing repeats
    return min(repeated / (repeated + within), 1.0)


def independent_samples(views, S, R_WC, p_WC, p_HP) -> float:
    """How many independent samples a point's samples count as: ``n / (1 + (m - 1) rho)`` with
    ``rho = repeated_share(...)`` and ``m = sum n_v^2 / n`` (module docstring); ``n`` when every
    sample is its own view, the number of views (about) when everything repeats; at least 1.
    Arguments as ``repeated_share``'s."""
    views, S, R_WC, p_WC, p_HP = _checked(views, S, R_WC, p_WC, p_HP)
    counts = views[:, 0]
    n = float(counts.sum())
    if not n > 0.0:
        return 1.0
    m = float((counts**2).sum()) / n
    return max(n / (1.0 + (m - 1.0) * _repeated_share(views, S, R_WC, p_WC, p_HP)), 1.0)


def _checked(views, S, R_WC, p_WC, p_HP):
    views = real_array("views", views, (None, VIEW_ROW),
                       what=f"a V x {VIEW_ROW} array of view sums (view_row)")
    if not np.all(views[:, 0] >= 0.0):
        raise IdentificationError(f"views must have counts (column 0) >= 0, got {describe(views)}")
    S = real_array("S", S, (N_UNKNOWNS, N_UNKNOWNS))
    p_WC, p_HP = real_array("p_WC", p_WC, VECTOR3), real_array("p_HP", p_HP, VECTOR3)
    return views, S, rotation("R_WC", R_WC), p_WC, p_HP


