"""Exporting identified models as Drake scenario snippets, and loading them back.

- The camera pose ``X_WC`` (eye-to-hand, §3.4) as a Drake ``CameraConfig`` YAML whose ``X_PB``
  is the pose of the camera body B in its parent frame (``world`` for a fixed camera). Drake's
  camera body frame is the optical frame the points were measured in (+z along the optical axis,
  +x right, +y down), so ``X_PB = X_WC``.
- The payload (§4.4) as a YAML spatial inertia about the sensor frame K's origin, in K: the mass,
  the centre of mass and the rotational inertia about the centre of mass. The dynamic
  identification (``identification.payload_dynamic``) identifies that inertia and it is written as
  identified; the static one gives the mass and the centre of mass only (static wrenches do not
  reveal the inertia), and the inertia is then written as zero (a point mass) unless the caller
  gives one (e.g. from the object's shape).

Everything written or loaded here is checked first: a pose must be a proper rigid transform
(finite, rotation orthonormal within ``ROTATION_TOLERANCE`` with determinant +1, last row
``[0 0 0 1]``), a camera config must meet Drake's ``CameraConfig`` preconditions, a payload must be
a physically valid spatial inertia. Anything else raises ``CalibrationExportError`` (a
``ValueError``) with a one-line message, so no value reaches a Drake internal check.
"""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import copy
import dataclasses
import math
from dataclasses import field

import numpy as np
import yaml
from pydrake.common.schema import Transform
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed
from pydrake.math import RigidTransform
from pydrake.multibody.tree import RotationalInertia, SpatialInertia
from pydrake.systems.sensors import CameraConfig

from sustain_drake.identification.payload_dynamic import inertia_matrix, physical_inertia_problem

# Largest |R^T R - I| entry accepted for a rotation matrix (the rotation is then re-orthonormalized).
ROTATION_TOLERANCE = 1e-6


class CalibrationExportError(ValueError):
    """A pose, camera config or payload that cannot be written or loaded (non-finite, not a proper
    rotation, out of range, unreadable YAML); the message is one line saying what is wrong."""


def camera_config_yaml(X_WC, name: str = "camera", parent_frame: str = "world",
                       base: CameraConfig | None = None) -> str:  # fmt: skip
    """A ``CameraConfig`` YAML with ``X_PB`` set to the identified pose.

    Args:
        X_WC: the camera pose (4 x 4 array or ``RigidTransform``) in ``parent_frame``.
        name: the camera's name.
        parent_frame: the frame ``X_WC`` is expressed in (``world`` for eye-to-hand).
        base: a camera config to start from (image size, intrinsics, rates); Drake's defaults if
            None. Only the fields that differ from Drake's defaults are written.

    Raises:
        CalibrationExportError: ``X_WC`` is not a rigid transform (NaN or inf, a rotation that is
            not orthonormal within ``ROTATION_TOLERANCE`` or is a reflection, a last row other than
            ``[0 0 0 1]``), a name is empty, or ``base`` breaks a ``CameraConfig`` precondition.
    """
    X = _pose_matrix(X_WC, "X_WC")
    for label, value in (("name", name), ("parent_frame", parent_frame)):
        if not isinstance(value, str) or not value:
            raise CalibrationExportError(f"the camera's {label} must be a non-empty string, got {value!r}")
    if base is not None and not isinstance(base, CameraConfig):
        raise CalibrationExportError(f"base must be a CameraConfig, got {type(base).__name__}")
    config = copy.deepcopy(base) if base is not None else CameraConfig()
    config.name = name
    config.X_PB = Transform(RigidTransform(X))
    config.X_PB.base_frame = parent_frame
    _check_camera_config(config, "base")
    return yaml_dump_typed(config, defaults=CameraConfig())


def load_camera_config(text: str) -> CameraConfig:
    """The ``CameraConfig`` of a YAML text written by ``camera_config_yaml`` (or by hand).

    Raises:
        CalibrationExportError: the text is not YAML of a ``CameraConfig`` (a syntax error, an
            unknown or duplicate key, a wrong type), or a value breaks a precondition: ``width``,
            ``height`` > 0; ``fps`` finite > 0; ``0 < clipping_near < clipping_far`` and
            ``0 < z_near < z_far`` (finite); focal lengths finite > 0 (fields of view in (0, 180)
            deg); the principal point inside the image; ``capture_offset`` finite >= 0;
            ``0 <= output_delay < 1/fps``; ``X_PB``, ``X_BC``, ``X_BD`` fixed (not random), finite,
            proper rotations.
    """
    config = _load_yaml(text, CameraConfig, "camera config")
    _check_camera_config(config, "camera config")
    return config


@dataclasses.dataclass
class SpatialInertiaConfig:
    """A spatial inertia about a frame's origin, in that frame: ``mass`` (kg), the centre of mass
    ``p_BoBcm`` (m) and the rotational inertia about the centre of mass ``I_BBcm`` (kg m^2, the
    six moments and products ``[Ixx, Iyy, Izz, Ixy, Ixz, Iyz]``)."""

    frame: str = "sensor"
    mass: float = 0.0
    p_BoBcm: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    I_BBcm: list[float] = field(default_factory=lambda: [0.0] * 6)

    def validate(self) -> None:
        """Raises ``CalibrationExportError`` unless this is a physically valid spatial inertia: a
        non-empty ``frame``, ``mass`` finite > 0, ``p_BoBcm`` 3 finite values, ``I_BBcm`` 6 finite
        values: all zero (a point mass) or positive definite with each principal moment at most the
        sum of the other two (the triangle inequalities)."""
        if not isinstance(self.frame, str) or not self.frame:
            raise CalibrationExportError(f"payload frame must be a non-empty string, got {self.frame!r}")
        mass = _number(self.mass, "payload mass")
        if not mass > 0:
            raise CalibrationExportError(f"the payload mass must be a positive number, got {mass} kg")
        _vector(self.p_BoBcm, 3, "payload p_BoBcm")
        _rotational_inertia(self.I_BBcm)

    def spatial_inertia(self) -> SpatialInertia:
        """The pydrake ``SpatialInertia``; raises ``CalibrationExportError`` for a non-physical one
        (see ``validate``: e.g. a mass of 0, negative or NaN)."""
        self.validate()
        return SpatialInertia.MakeFromCentralInertia(
            float(self.mass), np.array(_vector(self.p_BoBcm, 3, "p_BoBcm")), _rotational_inertia(self.I_BBcm)
        )


def payload_yaml(mass: float, p_KCm, frame: str = "sensor", I_BBcm=None) -> str:
    """The identified payload as a ``SpatialInertiaConfig`` YAML (about K's origin, in K).

    ``I_BBcm`` is the rotational inertia about the centre of mass, in K (``[I_xx, I_yy, I_zz, I_xy,
    I_xz, I_yz]``, kg m^2): the dynamic identification's (``DynamicPayloadSolution.I_BBcm``), or
    None for a static one (written as zeros: a point mass).

    Raises:
        CalibrationExportError: the mass is not finite and positive, ``p_KCm`` is not 3 finite
            values, or ``I_BBcm`` is not 6 finite values of a physically valid inertia (positive
            definite, the triangle inequalities), checked before anything is written.
    """
    mass = _number(mass, "payload mass")
    if not mass > 0:
        raise CalibrationExportError(f"the payload mass must be a positive number, got {mass} kg")
    config = SpatialInertiaConfig(
        frame=frame, mass=mass, p_BoBcm=_vector(p_KCm, 3, "p_KCm"),
        I_BBcm=[0.0] * 6 if I_BBcm is None else _vector(I_BBcm, 6, "I_BBcm"),
    )  # fmt: skip
    config.validate()  # checked before anything is written
    return yaml_dump_typed(config)


def load_payload(text: str) -> SpatialInertiaConfig:
    """The ``SpatialInertiaConfig`` of a YAML text written by ``payload_yaml``.

    Raises:
        CalibrationExportError: the text is not YAML of a ``SpatialInertiaConfig`` or the
            inertia is not physically valid (see ``SpatialInertiaConfig.validate``).
    """
    config = _load_yaml(text, SpatialInertiaConfig, "payload")
    config.validate()
    return config


def _load_yaml(text, schema, what: str):
    if not isinstance(text, str):
        raise CalibrationExportError(f"{what}: expected YAML text (a str), got {type(text).__name__}")
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)  # the node graph: any tag, nothing built
    except yaml.YAMLError as e:
        raise CalibrationExportError(f"{what}: not valid YAML: {_yaml_problem(e)}") from None
    if not isinstance(root, yaml.MappingNode):
        raise CalibrationExportError(f"{what}: expected a YAML mapping of {schema.__name__} fields")
    _refuse_duplicate_keys(root, what)
    try:
        return yaml_load_typed(schema=schema, data=text)
    except Exception as e:  # pydrake's loader raises many types (even AssertionError) for bad data
        detail = _one_line(e)
        if isinstance(e, AssertionError) or "incompatible function arguments" in detail:
            detail = "a value is empty, of the wrong kind or too large"
        raise CalibrationExportError(f"{what}: {detail}") from None


def _refuse_duplicate_keys(root, what: str) -> None:
    stack, seen = [root], set()
    while stack:
        node = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, yaml.MappingNode):
            keys = set()
            for key, value in node.value:
                if isinstance(key, yaml.ScalarNode):
                    if key.value in keys:
                        line = key.start_mark.line + 1
                        raise CalibrationExportError(f"{what}: line {line}: duplicate key '{key.value}'")
                    keys.add(key.value)
                stack += [key, value]
        elif isinstance(node, yaml.SequenceNode):
            stack += node.value


def _check_camera_config(config: CameraConfig, what: str) -> None:
    def fail(message):
        raise CalibrationExportError(f"{what}: {message}")

    if not isinstance(config.name, str) or not config.name:
        fail("name must not be empty")
    if config.width <= 0 or config.height <= 0:
        fail(f"the image size must be positive, got width {config.width}, height {config.height}")
    if not (math.isfinite(config.fps) and config.fps > 0):
        fail(f"fps must be a finite positive number, got {config.fps}")
    for near, far, label in ((config.clipping_near, config.clipping_far, "clipping"),
                             (config.z_near, config.z_far, "z")):  # fmt: skip
        if not (math.isfinite(near) and math.isfinite(far) and 0 < near < far):
            fail(f"need 0 < {label}_near < {label}_far (m), got {label}_near {near}, {label}_far {far}")
    focal = config.focal
    values = [v for v in (focal.x, focal.y) if v is not None]
    if not values:
        fail("focal needs an x or a y value")
    if isinstance(focal, CameraConfig.FovDegrees):
        if not all(math.isfinite(v) and 0 < v < 180 for v in values):
            fail(f"a field of view must be in (0, 180) deg, got {values}")
    elif not all(math.isfinite(v) and v > 0 for v in values):
        fail(f"a focal length must be a finite positive number of pixels, got {values}")
    for center, size, label in ((config.center_x, config.width, "center_x"),
                                (config.center_y, config.height, "center_y")):  # fmt: skip
        if center is not None and not (math.isfinite(center) and 0 < center < size):
            fail(f"{label} must be inside the image (0, {size}) px, got {center}")
    if not (math.isfinite(config.capture_offset) and config.capture_offset >= 0):
        fail(f"capture_offset must be finite and >= 0 s, got {config.capture_offset}")
    if not (math.isfinite(config.output_delay) and 0 <= config.output_delay < 1 / config.fps):
        fail(f"output_delay must be in [0, 1/fps) s, got {config.output_delay}")
    for label in ("X_PB", "X_BC", "X_BD"):
        transform = getattr(config, label)
        if not transform.IsDeterministic():
            fail(f"{label} must be a fixed pose, not a random one")
        try:
            X = transform.GetDeterministicValue()
        except (RuntimeError, ValueError) as e:
            fail(f"{label} is not a finite pose ({_one_line(e)})")
        _pose_matrix(X, f"{what}: {label}")
        if label != "X_PB" and transform.base_frame:
            fail(f"{label} must have no base_frame (it is relative to the camera body)")


def _pose_matrix(X, what: str) -> np.ndarray:
    """``X`` as a 4 x 4 rigid transform with an exactly orthonormal rotation, or an error."""
    if isinstance(X, RigidTransform):
        X = X.GetAsMatrix4()
    try:
        X = np.array(X, dtype=float)
    except (TypeError, ValueError):
        raise CalibrationExportError(f"{what} must be a 4 x 4 matrix of numbers") from None
    if X.shape != (4, 4):
        raise CalibrationExportError(f"{what} must be a 4 x 4 matrix, got shape {X.shape}")
    if not np.isfinite(X).all():
        raise CalibrationExportError(f"{what} has NaN or inf entries")
    if np.abs(X[3] - [0.0, 0.0, 0.0, 1.0]).max() > ROTATION_TOLERANCE:
        raise CalibrationExportError(f"{what}: the last row is {X[3].tolist()}, expected [0, 0, 0, 1]")
    R = X[:3, :3]
    error = np.abs(R.T @ R - np.eye(3)).max()
    if error > ROTATION_TOLERANCE:
        raise CalibrationExportError(
            f"{what}: the rotation is not orthonormal (largest |R^T R - I| entry {error:.3g} > "
            f"{ROTATION_TOLERANCE:g}): give a proper rotation matrix"
        )
    if np.linalg.det(R) < 0:
        raise CalibrationExportError(f"{what}: the rotation is a reflection (det R = -1): give a proper one")
    U, _, Vt = np.linalg.svd(R)
    X[:3, :3] = U @ Vt
    X[3] = [0.0, 0.0, 0.0, 1.0]
    return X


def _number(value, what: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise CalibrationExportError(f"the {what} must be a finite number, got {value!r}") from None
    if not math.isfinite(number):
        raise CalibrationExportError(f"the {what} must be a finite number, got {number}")
    return number


def _vector(values, n: int, what: str) -> list[float]:
    try:
        array = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise CalibrationExportError(f"{what} must be {n} numbers, got {values!r}") from None
    if array.shape != (n,):
        raise CalibrationExportError(f"{what} must be {n} numbers, got shape {array.shape}")
    if not np.isfinite(array).all():
        raise CalibrationExportError(f"{what} has NaN or inf: {array.tolist()}")
    return [float(v) for v in array]


def _rotational_inertia(values) -> RotationalInertia:
    """The ``RotationalInertia`` of 6 values: zeros (a point mass) or a rigid body's (positive
    definite, the triangle inequalities), else ``CalibrationExportError``."""
    moments_products = _vector(values, 6, "payload I_BBcm")
    if any(moments_products):
        problem = physical_inertia_problem(inertia_matrix(moments_products))
        if problem is not None:
            raise CalibrationExportError(
                f"payload I_BBcm {moments_products} is not physically valid: {problem}")
    return RotationalInertia(*moments_products)


def _yaml_problem(e: yaml.YAMLError) -> str:
    mark = getattr(e, "problem_mark", None)
    problem = getattr(e, "problem", None) or _one_line(e)
    return f"line {mark.line + 1}, column {mark.column + 1}: {problem}" if mark is not None else problem


def _one_line(e: BaseException) -> str:
    text = " ".join(str(e).split())
    return text if len(text) <= 300 else text[:297] + "..."
