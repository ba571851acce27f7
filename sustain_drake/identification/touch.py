"""Touch estimation on a held object of known inertia and approximately known shape (paper §3.5,
§4.4), pure numpy.

With the payload identified (``m``, ``p_KCm``), the wrench the sensor must apply to hold it still
is predicted; what the sensor applies beyond that balances a contact. With the sign convention of
``identification.payload`` (the wrench applied BY the sensor ON the payload, in K)::

    f_c   = f_K - f_pred = -F_env              (F_env: the force the environment applies at P)
    tau_c = tau_K - tau_pred = p_KP x f_c       (a point contact exerts no torque about P)

so the contact point lies on the line of action ``p(t) = (f_c x tau_c)/|f_c|^2 + t f_c``, and on
the object's surface. Of the (usually two) intersections, the contact is where ``F_env`` pushes
INTO the surface: ``n_out . F_env < 0``, i.e. ``n_out . f_c > 0``.

Shapes are given in their own frame G (posed in K by ``X_KG``): a box centred on G with
half-extents, a cylinder along G's z axis centred on G, a sphere centred on G.

Every public function and shape raises ``IdentificationError`` (a ``ValueError``, see ``errors``)
with a one-line message for an argument of the wrong type, shape or value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sustain_drake.identification.errors import (
    VECTOR3,
    IdentificationError,
    homogeneous_transform,
    instance,
    real_array,
    real_number,
    rotation,
)


def _positive(name: str, value) -> float:
    x = real_number(name, value, what="a positive number")
    if not x > 0.0:
        raise IdentificationError(f"{name} must be a positive number, got {x}")
    return x


@dataclass(frozen=True)
class Box:
    """A box centred on its frame, with sizes along x, y, z in metres (positive, finite)."""

    size: tuple[float, float, float]

    def __post_init__(self):
        size = real_array("size", self.size, VECTOR3, what="three sizes")
        if not np.all(size > 0.0):
            raise IdentificationError(f"size must be three positive numbers, got {size.tolist()}")


@dataclass(frozen=True)
class Cylinder:
    """A cylinder along its frame's z axis, centred on it: radius and length in metres (positive,
    finite)."""

    radius: float
    length: float

    def __post_init__(self):
        _positive("radius", self.radius)
        _positive("length", self.length)


@dataclass(frozen=True)
class Sphere:
    """A sphere centred on its frame: radius in metres (positive, finite)."""

    radius: float

    def __post_init__(self):
        _positive("radius", self.radius)


Shape = Box | Cylinder | Sphere


def predicted_wrench(mass: float, p_KCm: np.ndarray, R_WK: np.ndarray, g_W: np.ndarray) -> np.ndarray:
    """``[tau; f]`` the sensor applies to hold the payload still at orientation ``R_WK``.
    IdentificationError unless ``mass`` is a finite number >= 0, ``p_KCm`` and ``g_W`` finite
    3-vectors and ``R_WK`` a rotation matrix."""
    mass = real_number("mass", mass, what="a number >= 0")
    if not mass >= 0.0:
        raise IdentificationError(f"mass must be a number >= 0, got {mass}")
    p_KCm, g_W = real_array("p_KCm", p_KCm, VECTOR3), real_array("g_W", g_W, VECTOR3)
    R_WK = rotation("R_WK", R_WK)
    f = -mass * (R_WK.T @ g_W)
    return np.concatenate([np.cross(p_KCm, f), f])


def line_of_action(f_c: np.ndarray, tau_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The point of the line nearest the origin and the unit direction of ``f_c``.
    IdentificationError unless ``f_c`` is a finite non-zero 3-vector and ``tau_c`` a finite
    3-vector."""
    f_c, tau_c = real_array("f_c", f_c, VECTOR3), real_array("tau_c", tau_c, VECTOR3)
    if not float(f_c @ f_c) > 0.0:
        raise IdentificationError("f_c must be a non-zero force (no line of action), got zeros")
    return _line_of_action(f_c, tau_c)


def _line_of_action(f_c: np.ndarray, tau_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ff = float(f_c @ f_c)
    return np.cross(f_c, tau_c) / ff, f_c / math.sqrt(ff)


def _box_hits(p: np.ndarray, u: np.ndarray, half: np.ndarray):
    """Entry and exit of the line through the box (slab method), with outward normals."""
    t_in, t_out = -math.inf, math.inf
    n_in = n_out = None
    for axis in range(3):
        if abs(u[axis]) < 1e-15:
            if abs(p[axis]) > half[axis]:
                return []
            continue
        t1, t2 = (-half[axis] - p[axis]) / u[axis], (half[axis] - p[axis]) / u[axis]
        s1, s2 = -1.0, 1.0  # the faces at -half and +half
        if t1 > t2:
            t1, t2, s1, s2 = t2, t1, s2, s1
        if t1 > t_in:
            t_in, n_in = t1, s1 * np.eye(3)[axis]
        if t2 < t_out:
            t_out, n_out = t2, s2 * np.eye(3)[axis]
    if t_in > t_out or n_in is None:
        return []
    return [(t_in, n_in), (t_out, n_out)]


def _sphere_hits(p: np.ndarray, u: np.ndarray, radius: float):
    b = float(p @ u)
    disc = b * b - (float(p @ p) - radius * radius)
    if disc < 0:
        return []
    root = math.sqrt(disc)
    return [(t, (p + t * u) / radius) for t in (-b - root, -b + root)]


def _cylinder_hits(p: np.ndarray, u: np.ndarray, radius: float, length: float):
    half = 0.5 * length
    hits = []
    a = u[0] ** 2 + u[1] ** 2
    if a > 1e-15:  # the curved side
        b = p[0] * u[0] + p[1] * u[1]
        c = p[0] ** 2 + p[1] ** 2 - radius * radius
        disc = b * b - a * c
        if disc >= 0:
            root = math.sqrt(disc)
            for t in ((-b - root) / a, (-b + root) / a):
                q = p + t * u
                if abs(q[2]) <= half:
                    hits.append((t, np.array([q[0], q[1], 0.0]) / radius))
    if abs(u[2]) > 1e-15:  # the flat caps
        for sign in (-1.0, 1.0):
            t = (sign * half - p[2]) / u[2]
            q = p + t * u
            if q[0] ** 2 + q[1] ** 2 <= radius * radius:
                hits.append((t, np.array([0.0, 0.0, sign])))
    return hits


@dataclass(frozen=True)
class TouchPoint:
    """A touch on the held object.

    Attributes:
        p_KP: the contact point in the sensor frame K, metres.
        n_K: the object's outward surface normal there, in K.
        f_env_K: the force the environment applies on the object, in K, newtons.
        distance: 0 when the line of action meets the surface; otherwise the line misses the
            shape and ``p_KP`` is the surface point nearest the line (``distance`` from it).
    """

    p_KP: np.ndarray
    n_K: np.ndarray
    f_env_K: np.ndarray
    distance: float


def locate_touch(residual_wrench: np.ndarray, shape: Shape, X_KG: np.ndarray) -> TouchPoint | None:
    """Intersects the residual wrench's line of action with the held object's surface.

    Args:
        residual_wrench: ``[tau_c; f_c]`` in K (the sensor's reading minus the payload's predicted
            wrench), N m and N.
        shape: the object's shape, in its frame G.
        X_KG: the 4 x 4 pose of G in K.

    Returns:
        The touch point, or None when the residual force is zero (no line of action).

    Raises:
        IdentificationError: ``residual_wrench`` is not a finite 6-vector, ``shape`` not a Box,
            Cylinder or Sphere, or ``X_KG`` not a 4 x 4 transform with a rotation block.
    """
    residual_wrench = real_array("residual_wrench", residual_wrench, (6,))
    instance("shape", shape, (Box, Cylinder, Sphere), "a Box, Cylinder or Sphere")
    X_KG = homogeneous_transform("X_KG", X_KG)
    tau_c, f_c = residual_wrench[0:3], residual_wrench[3:6]
    if not float(f_c @ f_c) > 1e-24:
        return None
    p_K, u_K = _line_of_action(f_c, tau_c)
    R_KG, p_KG = X_KG[:3, :3], X_KG[:3, 3]
    p, u = R_KG.T @ (p_K - p_KG), R_KG.T @ u_K  # the line in G
    if isinstance(shape, Box):
        hits = _box_hits(p, u, 0.5 * np.asarray(shape.size, dtype=float))
    elif isinstance(shape, Sphere):
        hits = _sphere_hits(p, u, shape.radius)
    elif isinstance(shape, Cylinder):
        hits = _cylinder_hits(p, u, shape.radius, shape.length)
    else:  # unreachable: checked above
        raise IdentificationError(f"unsupported shape {type(shape).__name__}: use Box, Cylinder or Sphere")
    # The contact is where the environment's force (-f_c, i.e. along -u) pushes into the surface.
    pushing = [(t, n) for t, n in hits if float(n @ u) > 0.0]
    if pushing:
        t, n = min(pushing, key=lambda hit: abs(hit[0]))
        distance = 0.0
        q = p + t * u
    else:
        q, n = _nearest_surface_point(p, u, shape)
        distance = float(np.linalg.norm(np.cross(q - p, u)))
    return TouchPoint(p_KP=R_KG @ q + p_KG, n_K=R_KG @ n, f_env_K=-f_c, distance=distance)


def _nearest_surface_point(p: np.ndarray, u: np.ndarray, shape: Shape):
    """The surface point nearest the line (for a line that misses the shape): the shape's
    centre's projection on the line, pushed out to the surface along the direction from it."""
    foot = p - (p @ u) * u  # the point of the line nearest the shape's centre
    d = foot / np.linalg.norm(foot) if np.linalg.norm(foot) > 1e-12 else np.array([1.0, 0.0, 0.0])
    if isinstance(shape, Sphere):
        return shape.radius * d, d
    if isinstance(shape, Box):
        half = 0.5 * np.asarray(shape.size, dtype=float)
        q = np.clip(foot, -half, half)
        axis = int(np.argmax(np.abs(q) / half))
        n = np.zeros(3)
        n[axis] = math.copysign(1.0, q[axis])
        q[axis] = n[axis] * half[axis]
        return q, n
    radial = np.array([d[0], d[1], 0.0])
    norm = np.linalg.norm(radial)
    radial = radial / norm if norm > 1e-12 else np.array([1.0, 0.0, 0.0])
    z = float(np.clip(foot[2], -0.5 * shape.length, 0.5 * shape.length))
    return np.array([shape.radius * radial[0], shape.radius * radial[1], z]), radial
