"""Rotation helpers: the §3.2 projection of an identified 3 x 3 block onto SO(3) (Challis's method,
Eqs. (14)-(21)), and the small so(3) maps the Gauss-Newton refinement needs. Pure numpy.

Each public helper raises ``IdentificationError`` (a ``ValueError``, see ``errors``) for an argument
of the wrong type, shape or value; the identifiers' own calls go to unchecked twins (``_so3_exp``,
``_nearest_rotation``, ...) on arrays they built themselves."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack

from sustain_drake.identification.errors import MATRIX3, VECTOR3, all_finite, real_array, rotation

_E3 = np.eye(3)


def det3(X: np.ndarray) -> float:
    """Determinant of a 3 x 3 matrix (cofactor expansion: much cheaper than np.linalg.det).
    IdentificationError unless ``X`` is a real 3 x 3 matrix."""
    return _det3(real_array("X", X, MATRIX3, finite=False))


def _det3(X: np.ndarray) -> float:
    a, b, c, d, e, f, g, h, i = X.ravel().tolist()
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


def skew(w: np.ndarray) -> np.ndarray:
    """``[w x]``: the matrix with ``skew(w) @ v == np.cross(w, v)``. IdentificationError unless
    ``w`` is a real 3-vector."""
    return _skew(real_array("w", w, VECTOR3, finite=False))


def _skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def so3_exp(w: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: the rotation by ``|w|`` radians about ``w``. IdentificationError unless
    ``w`` is a finite 3-vector."""
    return _so3_exp(real_array("w", w, VECTOR3))


def _so3_exp(w: np.ndarray) -> np.ndarray:
    # R = E + sin(theta) K + (1 - cos(theta)) K^2 with K = [u x] for the unit axis u and K^2 = u u^T - E,
    # in Python floats (a fifth of the cost of the numpy expression, which the refinements evaluate
    # at every step); hypot keeps any finite w from overflowing.
    x, y, z = w.tolist()
    theta = math.hypot(x, y, z)
    if theta < 1e-8:  # second-order Taylor expansion; exact to round-off for such small angles
        a, b, t2 = 1.0, 0.5, x * x + y * y + z * z
    else:
        x, y, z = x / theta, y / theta, z / theta
        a, b, t2 = math.sin(theta), 1.0 - math.cos(theta), 1.0
    bxy, bxz, byz = b * x * y, b * x * z, b * y * z
    return np.array([[1.0 + b * (x * x - t2), bxy - a * z, bxz + a * y],
                     [bxy + a * z, 1.0 + b * (y * y - t2), byz - a * x],
                     [bxz - a * y, byz + a * x, 1.0 + b * (z * z - t2)]])  # fmt: skip


def rotation_angle(R: np.ndarray) -> float:
    """The angle of a rotation matrix in radians (robust near 0 and pi). IdentificationError
    unless ``R`` is a rotation matrix (``errors.ROTATION_TOLERANCE``)."""
    R = rotation("R", R)
    c = np.clip(0.5 * (np.trace(R) - 1.0), -1.0, 1.0)
    s = 0.5 * np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return float(np.arctan2(s, c))


@dataclass(frozen=True, slots=True)
class RotationProjection:
    """The result of §3.2 for ``X_hat = [x1 x2 x3]`` (the rotation block of ``v_N``).

    Attributes:
        R: the proper rotation (det +1) nearest ``X_hat`` (after the sign fix) up to scale.
        scale: ``a = (gamma^T x) / (x^T x)`` (Eq. (21)) including the sign, so that
            ``a X_hat ~ R`` for the ``X_hat`` given.
        ssd: the sum of squared differences of ``a R^T X_hat - E`` (closeness to a rotation).
        sign: +1 or -1, the sign applied to ``v_N`` so that ``det(X_hat) > 0``.
    """

    R: np.ndarray
    scale: float
    ssd: float
    sign: float


def project_to_rotation(x9: np.ndarray) -> RotationProjection:
    """§3.2, with the two fixes the paper omits: the sign of ``v_N`` and a proper rotation.

    ``x9`` holds the columns of ``X_hat`` stacked (``x9[0:3]`` is the first column). With the SVD
    ``X_hat = U S V^T``, Challis's nearest rotation is ``U V^T`` (Eqs. (18)-(19)). ``v_N`` is only
    defined up to sign, and ``det(-X) = -det(X)`` for 3 x 3 matrices, so the sign
    ``d = det(U) det(V)`` (the sign of ``det(X_hat)``) is applied first: then ``R = d U V^T`` is a
    proper rotation (det +1) and ``trace(R^T d X_hat) = s_1 + s_2 + s_3``. Hence Eq. (21) and the
    SSD follow from the singular values alone::

        a = sum(s) / sum(s^2),    SSD = ||a R^T X_hat - E||_F^2 = 3 - sum(s)^2 / sum(s^2).

    IdentificationError unless ``x9`` is a real 9-vector (NaN or inf give the identity with scale 0
    and SSD inf).
    """
    return RotationProjection(*projection_parts(x9))


def projection_parts(x9: np.ndarray) -> tuple[np.ndarray, float, float, float]:
    """``project_to_rotation``'s ``(R, scale, ssd, sign)`` as a tuple. IdentificationError unless
    ``x9`` is a real 9-vector."""
    x9 = real_array("x9", x9, (9,), finite=False)
    if not all_finite(x9):  # LAPACK's dgesvd never returns on a NaN
        return _E3.copy(), 0.0, float("inf"), 1.0
    return _projection_parts(x9)


def _projection_parts(x9: np.ndarray) -> tuple[np.ndarray, float, float, float]:
    """``projection_parts`` unchecked, for a finite ``x9`` (it runs at every solve of the streaming
    identifier, so it makes as few Python calls as it can)."""
    U, sv, Vt, info = lapack.dgesvd(x9.reshape(3, 3, order="F"))
    if info != 0:  # only for non-finite input; keep the contract "R is a rotation"
        return _E3.copy(), 0.0, float("inf"), 1.0
    R = np.dot(U, Vt)
    if _det3(U) * _det3(Vt) > 0.0:
        sign = 1.0
    else:
        sign = -1.0
        R = -R
    s1, s2, s3 = sv.tolist()
    ssum = s1 + s2 + s3
    ssq = s1 * s1 + s2 * s2 + s3 * s3
    if ssq <= 0.0:
        return R, 0.0, float("inf"), sign
    return R, sign * ssum / ssq, max(3.0 - ssum * ssum / ssq, 0.0), sign


def _rotation_jacobian(R: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``d vec(R exp([omega x])) / d omega`` at ``omega = 0`` (``vec`` stacks the columns), written
    into ``out[0:9, 0:3]`` (the rotation block of the refinements' Jacobians): ``vec(R [e_k x])``,
    i.e. the columns ``[0; r3; -r2]``, ``[-r3; 0; r1]``, ``[r2; -r1; 0]`` with ``r_j`` the columns of
    ``R``."""
    out[0:9, 0:3] = R.T.ravel()[_JACOBIAN_SOURCE] * _JACOBIAN_SIGN
    return out


# ``_rotation_jacobian``'s entries: an index into ``[r1; r2; r3]`` and a sign, per row and column.
_JACOBIAN_SOURCE = np.array([[0, 6, 3], [0, 7, 4], [0, 8, 5], [6, 0, 0], [7, 0, 1], [8, 0, 2],
                             [3, 0, 0], [4, 1, 0], [5, 2, 0]])  # fmt: skip
_JACOBIAN_SIGN = np.array([[0.0, -1.0, 1.0]] * 3 + [[1.0, 0.0, -1.0]] * 3 + [[-1.0, 1.0, 0.0]] * 3)


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    """The proper rotation ``R`` maximising ``trace(R^T M)`` (orthogonal Procrustes, Kabsch's
    determinant fix): for ``M = sum_i a_i b_i^T`` the rotation taking the ``b_i`` nearest the
    ``a_i``; for ``M`` near a rotation, its re-orthonormalisation. IdentificationError unless ``M``
    is a finite 3 x 3 matrix."""
    return _nearest_rotation(real_array("M", M, MATRIX3))


def _nearest_rotation(M: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(M)
    return U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
