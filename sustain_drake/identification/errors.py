"""``IdentificationError`` and the argument checks of the identification API (pure numpy).

The contract: every public function and method of ``sustain_drake.identification`` and its modules
(not the internal ``candidates`` package) raises ``IdentificationError``, a ``ValueError`` with a
one-line message that names the argument and says what is expected, for an argument of the wrong
type, shape or value (None, a list of the wrong length, a string, NaN or inf where a finite value
is needed, a matrix that is not a rotation where a rotation is needed); never an AttributeError,
TypeError or IndexError.

The streaming hot paths (``EyeToHandIdentifier.add``, the solves) test the usual case (a float64
array of the right shape) first and convert or diagnose only otherwise, so the checks cost them
nothing measurable.
"""

from __future__ import annotations

import math
import numbers

import numpy as np


class IdentificationError(ValueError):
    """A sample or an argument that cannot be used (wrong type or shape, NaN, inf, not a rotation).

    It is a ``ValueError`` with a one-line message meant for the user, naming the argument."""


# A rotation matrix R is accepted when the RMS of the entries of R^T R - I is at most this and
# det(R) > 0 (then det(R) = 1 to about 1.5 times this). Poses read from text files with ~7
# significant digits are orthonormal to ~1e-7.
ROTATION_TOLERANCE = 1e-5
_ROTATION_BOUND = 9.0 * ROTATION_TOLERANCE**2  # on ||R^T R - I||_F^2

F64 = np.dtype(np.float64)
VECTOR3 = (3,)
MATRIX3 = (3, 3)
_REAL_KINDS = "iuf"  # signed and unsigned integers, floats (not bool, complex, strings, objects)


def describe(value) -> str:
    """A short one-line description of a (bad) argument for an error message."""
    if value is None:
        return "None"
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} and dtype {value.dtype}"
    if isinstance(value, (str, bytes)):
        text = repr(value)
        return "the string " + (text if len(text) <= 40 else text[:36] + "...")
    if isinstance(value, (list, tuple)):
        try:
            shape = np.shape(value)
        except (TypeError, ValueError):  # ragged
            shape = (len(value),)
        size = f"length {len(value)}" if len(shape) <= 1 else f"shape {shape}"
        return f"a {type(value).__name__} of {size}"
    if isinstance(value, (bool, np.bool_)):
        return f"the bool {value}"
    if isinstance(value, numbers.Number):
        text = repr(value)
        return "the number " + (text if len(text) <= 40 else text[:36] + "...")
    return f"a {type(value).__name__}"


def shape_text(shape: tuple) -> str:
    """``(3,)`` -> "a 3-vector", ``(3, 3)`` -> "a 3 x 3 matrix", ``(None, 3)`` -> "an (n, 3) array"."""
    if len(shape) == 1 and shape[0] is not None:
        return f"a {shape[0]}-vector"
    if len(shape) == 2 and None not in shape:
        return f"a {shape[0]} x {shape[1]} matrix"
    inner = ", ".join("n" if s is None else str(s) for s in shape)
    return f"an ({inner}{',' if len(shape) == 1 else ''}) array"


def _is_real(value) -> bool:
    kind = type(value)
    if kind is float or kind is int:
        return True
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def to_float_array(name: str, value, what: str) -> np.ndarray:
    """``value`` as a float64 array if it holds real numbers (any shape), else IdentificationError."""
    try:
        a = np.asarray(value)
        if a.dtype.kind == "O":  # None, big integers, mixed objects: real numbers only
            if not all(_is_real(v) for v in a.flat):
                raise TypeError
            a = a.astype(F64)
    except (TypeError, ValueError, OverflowError):  # ragged lists, objects that are not numbers
        raise IdentificationError(f"{name} must be {what} of real numbers, got {describe(value)}") from None
    if a.dtype.kind not in _REAL_KINDS:
        raise IdentificationError(f"{name} must be {what} of real numbers, got {describe(value)}")
    return a if a.dtype is F64 else a.astype(F64)


def real_array(name: str, value, shape: tuple, *, finite: bool = True, what: str | None = None) -> np.ndarray:
    """``value`` as a float64 array of ``shape`` (``None`` entries: any length), else
    IdentificationError. A float64 array is returned as it is (no copy). ``finite``: NaN and inf
    are refused too."""
    if type(value) is np.ndarray and value.dtype is F64:
        a = value
    else:
        a = to_float_array(name, value, what or shape_text(shape))
    if a.shape != shape and (
        a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape, strict=True))
    ):
        raise IdentificationError(f"{name} must be {what or shape_text(shape)}, got {describe(value)}")
    if finite and not all_finite(a):
        check_finite(name, a)
    return a


def all_finite(a: np.ndarray) -> bool:
    """Whether a float array has no NaN or inf (Python floats for a few entries: faster)."""
    if a.size <= 9:
        return all(map(math.isfinite, a.ravel().tolist()))
    return bool(np.isfinite(a).all())


def check_finite(name: str, a: np.ndarray) -> None:
    """IdentificationError naming the first NaN or inf entry of the float array ``a``, if any."""
    if not np.isfinite(a).all():
        index = tuple(np.argwhere(~np.isfinite(a))[0].tolist())
        where = f" at index {index}" if index else ""
        raise IdentificationError(f"{name} must be finite, got NaN or inf{where}")


def real_number(name: str, value, *, finite: bool = True, what: str = "a real number") -> float:
    """``value`` (an int or float, numpy's too; not bool) as a float, else IdentificationError."""
    if not _is_real(value):
        raise IdentificationError(f"{name} must be {what}, got {describe(value)}")
    try:
        x = float(value)
    except OverflowError:
        raise IdentificationError(f"{name} must be {what}, got a number too large for a float") from None
    if finite and not math.isfinite(x):
        raise IdentificationError(f"{name} must be finite, got {x}")
    return x


def integer(name: str, value, minimum: int, maximum: int | None = None) -> int:
    """``value`` (an int, or a float with an integral value; not bool) as an int in
    [minimum, maximum], else IdentificationError."""
    what = f"an integer >= {minimum}" + (f" and <= {maximum}" if maximum is not None else "")
    if not _is_real(value) or (not isinstance(value, numbers.Integral) and not float(value).is_integer()):
        raise IdentificationError(f"{name} must be {what}, got {describe(value)}")
    n = int(value)
    if n < minimum or (maximum is not None and n > maximum):
        raise IdentificationError(f"{name} must be {what}, got {n}")
    return n


def flag(name: str, value) -> bool:
    """``value`` (a bool, numpy's too) as a bool, else IdentificationError."""
    if type(value) is bool:
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    raise IdentificationError(f"{name} must be True or False, got {describe(value)}")


def instance(name: str, value, kind, what: str, *, optional: bool = False):
    """``value`` if it is an instance of ``kind`` (or None when ``optional``), else
    IdentificationError."""
    if isinstance(value, kind) or (optional and value is None):
        return value
    raise IdentificationError(f"{name} must be {what}, got {describe(value)}")


def is_rotation(rows, det_sign: float = 1.0) -> bool:
    """Whether the 3 x 3 matrix with rows ``rows`` (Python floats, e.g. ``R.tolist()``) is a proper
    rotation: the RMS of the entries of ``R^T R - I`` at most ROTATION_TOLERANCE and ``det(R) > 0``.
    ``det_sign`` -1: the rows are those of ``-R``. NaN and inf entries are never a rotation."""
    (a, b, c), (d, e, f), (g, h, i) = rows
    n0 = a * a + d * d + g * g - 1.0
    n1 = b * b + e * e + h * h - 1.0
    n2 = c * c + f * f + i * i - 1.0
    o01 = a * b + d * e + g * h
    o02 = a * c + d * f + g * i
    o12 = b * c + e * f + h * i
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    return (n0 * n0 + n1 * n1 + n2 * n2 + 2.0 * (o01 * o01 + o02 * o02 + o12 * o12) <= _ROTATION_BOUND
            and det * det_sign > 0.0)  # fmt: skip


def rotation(name: str, value) -> np.ndarray:
    """``value`` as a float64 3 x 3 proper rotation matrix (``is_rotation``), else
    IdentificationError."""
    R = real_array(name, value, MATRIX3, what="a 3 x 3 rotation matrix")
    if not is_rotation(R.tolist()):
        raise IdentificationError(rotation_problem(name, R))
    return R


def rotation_problem(name: str, R: np.ndarray) -> str:
    """The one-line message for a finite 3 x 3 ``R`` that ``is_rotation`` refuses."""
    with np.errstate(all="ignore"):
        rms = float(np.sqrt(np.mean((R.T @ R - np.eye(3)) ** 2)))
        det = float(np.linalg.det(R)) if np.isfinite(R).all() else math.nan
    return (f"{name} must be a rotation matrix (R^T R = I within {ROTATION_TOLERANCE:g} RMS, det +1), "
            f"got RMS(R^T R - I) = {rms:.3g}, det = {det:.3g}")


def not_a_rotation(name: str, value) -> IdentificationError:
    """The IdentificationError for an argument ``is_rotation`` refused: raises the one for its shape
    or a NaN/inf if that is the problem, else returns one with ``rotation_problem``."""
    R = real_array(name, value, MATRIX3, what="a 3 x 3 rotation matrix")
    return IdentificationError(rotation_problem(name, R))


def homogeneous_transform(name: str, value, *, rotation_block: bool = True) -> np.ndarray:
    """``value`` as a finite float64 4 x 4 homogeneous transform (last row 0 0 0 1; with
    ``rotation_block``, its 3 x 3 block a rotation), else IdentificationError."""
    X = real_array(name, value, (4, 4), what="a 4 x 4 homogeneous transform")
    if np.abs(X[3] - (0.0, 0.0, 0.0, 1.0)).max() > 1e-9:
        raise IdentificationError(f"{name} must be a 4 x 4 homogeneous transform: last row is not 0 0 0 1")
    if rotation_block and not is_rotation(X[:3, :3].tolist()):
        raise IdentificationError(rotation_problem(f"{name}[:3, :3]", X[:3, :3]))
    return X


def out_array(name: str, out, shape: tuple):
    """``out`` if it is None or a writable float64 array of ``shape`` (a buffer to write a result
    into), else IdentificationError."""
    if out is None or (type(out) is np.ndarray and out.dtype is F64 and out.shape == shape
                       and out.flags.writeable):  # fmt: skip
        return out
    what = " x ".join(map(str, shape))
    raise IdentificationError(f"{name} must be None or a writable float64 {what} array, got {describe(out)}")
