"""A Meshcat overlay of the hand-eye estimates beside the truth (issue 28, item 4): the estimated
camera's frustum and followed point next to the true camera's and the point where the true camera
puts the followed feature, drawn live and into Meshcat's recording (the replay)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Rgba, Sphere
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem
from pydrake.systems.sensors import CameraInfo

from sustain_drake.systems.coordination_outputs import FOLLOWED_POINT_SIZE


@dataclass
class OverlayConfig:
    """How ``EstimateOverlay`` draws."""

    period: float = 1.0 / 15.0  # s between drawings (the replay's frames are 1/32 s apart)
    prefix: str = "/overlay"  # Meshcat path of the overlay's objects
    frustum_depth: float = 0.25  # m, the distance from the optical centre to the frustum's base
    point_radius: float = 0.008  # m, the estimated point's sphere (the true one is half as big)
    estimated: Rgba = field(default_factory=lambda: Rgba(1.0, 0.5, 0.0, 1.0))  # orange
    true: Rgba = field(default_factory=lambda: Rgba(0.9, 0.9, 0.9, 1.0))  # pale grey


def frustum_segments(camera_info: CameraInfo, depth: float) -> tuple[np.ndarray, np.ndarray]:
    """The start and end points (3 x 9 each, m, in the camera frame C: z out of the lens, x right, y
    down) of a camera's frustum cut at ``depth``: four edges from the optical centre to the image's
    corners, the four sides of the image rectangle, and a tick up from its top side (which way is up
    in the image)."""
    w, h = camera_info.width(), camera_info.height()
    fx, fy = camera_info.focal_x(), camera_info.focal_y()
    cx, cy = camera_info.center_x(), camera_info.center_y()
    corners = [np.array([(u - cx) / fx * depth, (v - cy) / fy * depth, depth])
               for u, v in ((0, 0), (w, 0), (w, h), (0, h))]  # fmt: skip
    top = (corners[0] + corners[1]) / 2.0
    tick = top + np.array([0.0, -0.2 * (h / fy) * depth, 0.0])
    starts = [np.zeros(3)] * 4 + corners + [top]
    ends = corners + corners[1:] + corners[:1] + [tick]
    return np.array(starts).T, np.array(ends).T


class EstimateOverlay(LeafSystem):
    """Draws, in Meshcat and its recording, the estimated camera and followed point beside the
    true ones (evaluation display only: a side effect, so a periodic publish event; no state).

    .. pydrake_system::

        name: EstimateOverlay
        input_ports:
        - X_WC
        - X_WC_valid
        - followed_point
        - followed_point_valid
        - X_WH
        - true_X_WC (optional)

    Inputs, as ``make_sustainable_coordination`` outputs them: ``X_WC`` (RigidTransform, the
    estimated camera), ``X_WC_valid`` (1), ``followed_point`` (9, ``[feature_id, u, v, p_CP,
    p_HP]``), ``followed_point_valid`` (1), ``X_WH`` (RigidTransform, the hand pose: its
    ``X_WH_used``); ``true_X_WC`` (RigidTransform, the true camera: a simulation's ground truth, or
    a reference calibration; unconnected, only the estimates are drawn).

    Paths under ``config.prefix`` (``/overlay``): ``estimated_camera`` (the frustum of ``camera_info``
    at ``X_WC``, orange; hidden while ``X_WC_valid`` is 0), ``true_camera`` (the same frustum at
    ``true_X_WC``, pale grey), ``estimated_point`` (an orange sphere at ``X_WH p_HP``, the point the
    model follows) and ``true_point`` (a small grey sphere at ``true_X_WC p_CP``, where the true
    camera puts the followed feature's measured point); both points are hidden while
    ``followed_point_valid`` is 0. Every ``config.period`` s (and on a forced publish) it sets their
    transforms and visibility at the context's time.
    """

    def __init__(self, meshcat, camera_info: CameraInfo, config: OverlayConfig | None = None):
        super().__init__()
        self._meshcat, self._config = meshcat, config or OverlayConfig()
        if not self._config.period > 0:
            raise ValueError(f"EstimateOverlay: config.period must be > 0 s, got {self._config.period}")
        self._X_WC = self.DeclareAbstractInputPort("X_WC", AbstractValue.Make(RigidTransform()))
        self._X_WC_valid = self.DeclareVectorInputPort("X_WC_valid", 1)
        self._point = self.DeclareVectorInputPort("followed_point", FOLLOWED_POINT_SIZE)
        self._point_valid = self.DeclareVectorInputPort("followed_point_valid", 1)
        self._X_WH = self.DeclareAbstractInputPort("X_WH", AbstractValue.Make(RigidTransform()))
        self._true_X_WC = self.DeclareAbstractInputPort("true_X_WC", AbstractValue.Make(RigidTransform()))
        c = self._config
        starts, ends = frustum_segments(camera_info, c.frustum_depth)
        meshcat.SetLineSegments(self.path("estimated_camera"), starts, ends, 2.0, c.estimated)
        meshcat.SetLineSegments(self.path("true_camera"), starts, ends, 1.0, c.true)
        meshcat.SetObject(self.path("estimated_point"), Sphere(c.point_radius), c.estimated)
        meshcat.SetObject(self.path("true_point"), Sphere(0.5 * c.point_radius), c.true)
        self.DeclarePeriodicPublishEvent(c.period, 0.0, self._publish)
        self.DeclareForcedPublishEvent(self._publish)

    def path(self, name: str) -> str:
        """The Meshcat path of ``name`` (``estimated_camera``, ``true_camera``, ``estimated_point``,
        ``true_point``)."""
        return f"{self._config.prefix}/{name}"

    def _show(self, name: str, X: RigidTransform | None, t: float) -> None:
        """``name`` at ``X`` at time ``t``; hidden when ``X`` is None."""
        self._meshcat.SetProperty(self.path(name), "visible", X is not None, t)
        if X is not None:
            self._meshcat.SetTransform(self.path(name), X, t)

    def _publish(self, context) -> None:
        t = context.get_time()
        has_truth = self._true_X_WC.HasValue(context)
        true_X_WC = self._true_X_WC.Eval(context) if has_truth else None
        X_WC = self._X_WC.Eval(context) if self._X_WC_valid.Eval(context)[0] > 0.5 else None
        self._show("estimated_camera", X_WC, t)
        self._show("true_camera", true_X_WC, t)
        estimated_point = true_point = None
        if self._point_valid.Eval(context)[0] > 0.5:
            point = self._point.Eval(context)
            estimated_point = RigidTransform(self._X_WH.Eval(context) @ point[6:9])  # X_WH p_HP
            if has_truth:
                true_point = RigidTransform(true_X_WC @ point[3:6])  # true X_WC p_CP
        self._show("estimated_point", estimated_point, t)
        self._show("true_point", true_point, t)
