"""Exporting identified models as Drake scenario snippets, and loading them back.

- The camera pose ``X_WC`` (eye-to-hand, §3.4) as a Drake ``CameraConfig`` YAML whose ``X_PB``
  is the pose of the camera body B in its parent frame (``world`` for a fixed camera). Drake's
  camera body frame is the optical frame the points were measured in (+z along the optical axis,
  +x right, +y down), so ``X_PB = X_WC``.
- The payload (§4.4) as a YAML spatial inertia about the sensor frame K's origin, in K. A static
  identification gives the mass and the centre of mass only; the rotational inertia about the
  centre of mass is not observable from static wrenches, so it is written as zero (a point mass)
  unless the caller gives one (e.g. from the object's shape).
"""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import copy
import dataclasses
from dataclasses import field

import numpy as np
from pydrake.common.schema import Transform
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed
from pydrake.math import RigidTransform
from pydrake.multibody.tree import RotationalInertia, SpatialInertia
from pydrake.systems.sensors import CameraConfig


def camera_config_yaml(X_WC, name: str = "camera", parent_frame: str = "world",
                       base: CameraConfig | None = None) -> str:  # fmt: skip
    """A ``CameraConfig`` YAML with ``X_PB`` set to the identified pose.

    Args:
        X_WC: the camera pose (4 x 4 array or ``RigidTransform``) in ``parent_frame``.
        name: the camera's name.
        parent_frame: the frame ``X_WC`` is expressed in (``world`` for eye-to-hand).
        base: a camera config to start from (image size, intrinsics, rates); Drake's defaults if
            None. Only the fields that differ from Drake's defaults are written.
    """
    config = copy.deepcopy(base) if base is not None else CameraConfig()
    config.name = name
    X = X_WC if isinstance(X_WC, RigidTransform) else RigidTransform(np.asarray(X_WC, dtype=float))
    config.X_PB = Transform(X)
    config.X_PB.base_frame = parent_frame
    return yaml_dump_typed(config, defaults=CameraConfig())


def load_camera_config(text: str) -> CameraConfig:
    """The ``CameraConfig`` of a YAML text written by ``camera_config_yaml`` (or by hand)."""
    return yaml_load_typed(schema=CameraConfig, data=text)


@dataclasses.dataclass
class SpatialInertiaConfig:
    """A spatial inertia about a frame's origin, in that frame: ``mass`` (kg), the centre of mass
    ``p_BoBcm`` (m) and the rotational inertia about the centre of mass ``I_BBcm`` (kg m^2, the
    six moments and products ``[Ixx, Iyy, Izz, Ixy, Ixz, Iyz]``)."""

    frame: str = "sensor"
    mass: float = 0.0
    p_BoBcm: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    I_BBcm: list[float] = field(default_factory=lambda: [0.0] * 6)

    def spatial_inertia(self) -> SpatialInertia:
        """The pydrake ``SpatialInertia`` (raises for a non-physical one, e.g. a negative mass)."""
        Ixx, Iyy, Izz, Ixy, Ixz, Iyz = self.I_BBcm
        return SpatialInertia.MakeFromCentralInertia(
            self.mass, np.asarray(self.p_BoBcm, dtype=float), RotationalInertia(Ixx, Iyy, Izz, Ixy, Ixz, Iyz)
        )


def payload_yaml(mass: float, p_KCm, frame: str = "sensor", I_BBcm=None) -> str:
    """The identified payload as a ``SpatialInertiaConfig`` YAML (about K's origin, in K)."""
    if not (np.isfinite(mass) and mass > 0):
        raise ValueError(f"the payload mass must be a positive number, got {mass}")
    config = SpatialInertiaConfig(
        frame=frame, mass=float(mass), p_BoBcm=[float(v) for v in p_KCm],
        I_BBcm=[0.0] * 6 if I_BBcm is None else [float(v) for v in I_BBcm],
    )  # fmt: skip
    config.spatial_inertia()  # checks it is physically valid before anything is written
    return yaml_dump_typed(config)


def load_payload(text: str) -> SpatialInertiaConfig:
    """The ``SpatialInertiaConfig`` of a YAML text written by ``payload_yaml``."""
    return yaml_load_typed(schema=SpatialInertiaConfig, data=text)
