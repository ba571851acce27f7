"""``OpticalFlowTracker``: the optical-flow front end of body detection (paper §4.2, Fig. 7).

A thin Drake wrapper around :func:`sustain_drake.perception.optical_flow.track_frame`; all the
tracker's memory (previous image, features and their ids) is abstract state in the context.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem
from pydrake.systems.sensors import CameraInfo, ImageDepth32F, ImageRgba8U

from sustain_drake.perception.optical_flow import (
    CellGrid,
    PinholeIntrinsics,
    TrackedFeatures,
    TrackerParams,
    TrackerState,
    track_frame,
)
from sustain_drake.systems.shared_state import Shared


def intrinsics_from_camera_info(camera_info: CameraInfo) -> PinholeIntrinsics:
    """The pinhole intrinsics of a Drake ``CameraInfo``."""
    return PinholeIntrinsics(
        width=camera_info.width(), height=camera_info.height(), fx=camera_info.focal_x(),
        fy=camera_info.focal_y(), cx=camera_info.center_x(), cy=camera_info.center_y())


class OpticalFlowTracker(LeafSystem):
    """Tracks Shi–Tomasi corners with pyramidal Lucas–Kanade at a fixed period and reports the
    per-cell visual change ``ṡ_j`` of Eq. (27) and the tracked features.

    .. pydrake_system::

        name: OpticalFlowTracker
        input_ports:
        - color_image
        - depth_image
        - image_time
        output_ports:
        - visual_change
        - tracked_features
        - gray_image

    Input ports:

    - ``color_image``: ``ImageRgba8U`` (as from ``RgbdSensor``). An empty 0x0 image (what
      ``RgbdSensorAsync`` gives before its first capture) or a black image is skipped.
    - ``depth_image`` (optional): ``ImageDepth32F``, metres, same size as the color image.
      Unconnected: every feature's 3-D point is invalid.
    - ``image_time`` (optional, size 1): capture time of the image, s (``RgbdSensorAsync``'s
      ``image_time``). When connected, a frame not newer than the last processed one is skipped
      (the async sensor repeats its last image between captures); unconnected, the context time
      is used.

    Output ports (both depend on state only, so the tracker never closes an algebraic loop):

    - ``visual_change``: ``ṡ_j`` in pixels per second, one entry per grid cell, cell
      ``j = row * cols + col``; the sum of the flow norms of the features in the cell over the
      last frame interval (flows under ``TrackerParams.min_flow_px`` count as 0).
    - ``tracked_features``: :class:`~sustain_drake.perception.optical_flow.TrackedFeatures`
      (id, pixel, flow in pixels since the previous frame, ``p_CP`` in metres in the camera
      frame C, ``valid`` for depth, cell index).
    - ``gray_image``: the last processed frame in grey (``numpy`` H x W uint8; 0 x 0 before the
      first), the image the tracks were found in; read only.

    A track ends when it no longer shows the same surface (``TrackerParams.ncc_min``,
    ``depth_jump_m``: its patch's appearance or its depth changed between frames; see
    :mod:`sustain_drake.perception.optical_flow`), so a feature's id and ``p_CP`` stay on one
    physical point when something passes it.

    The camera intrinsics are a constructor argument (a ``CameraInfo``): they are fixed for a
    camera, and the image size fixes the grid and so the size of ``visual_change``. Skipped
    frames leave the state untouched, so the outputs hold their last values.
    """

    def __init__(self, camera_info: CameraInfo, grid_shape: tuple[int, int] = (12, 16),
                 period: float = 1.0 / 30.0, offset: float = 0.0,
                 params: TrackerParams | None = None):
        super().__init__()
        if not (np.isfinite(period) and period > 0):
            raise ValueError(f"period must be positive, got {period}")
        self._intrinsics = intrinsics_from_camera_info(camera_info)
        self._grid = CellGrid(self._intrinsics.width, self._intrinsics.height, *grid_shape)
        self._params = TrackerParams() if params is None else params

        self._color = self.DeclareAbstractInputPort(
            "color_image", AbstractValue.Make(ImageRgba8U()))
        self._depth = self.DeclareAbstractInputPort(
            "depth_image", AbstractValue.Make(ImageDepth32F()))
        self._time = self.DeclareVectorInputPort("image_time", 1)
        # Shared: track_frame returns a new state and never modifies its input.
        self._state_index = self.DeclareAbstractState(
            AbstractValue.Make(Shared(TrackerState.initial(self._grid))))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, offset, self._update)
        self.DeclareVectorOutputPort(
            "visual_change", BasicVector(self._grid.num_cells), self._calc_visual_change,
            prerequisites_of_calc={self.all_state_ticket()})
        self.DeclareAbstractOutputPort(
            "tracked_features", lambda: AbstractValue.Make(TrackedFeatures()),
            self._calc_features, prerequisites_of_calc={self.all_state_ticket()})
        # The state's own array (a new one every frame, never written to): no copy per frame.
        self.DeclareAbstractOutputPort(
            "gray_image", lambda: AbstractValue.Make(np.zeros((0, 0), np.uint8)),
            lambda context, output: output.set_value(self.tracker_state(context).prev_gray),
            prerequisites_of_calc={self.all_state_ticket()})  # fmt: skip

    @property
    def grid(self) -> CellGrid:
        return self._grid

    @property
    def params(self) -> TrackerParams:
        return self._params

    @property
    def intrinsics(self) -> PinholeIntrinsics:
        return self._intrinsics

    def tracker_state(self, context) -> TrackerState:
        """The tracker's state in ``context`` (read only)."""
        return context.get_abstract_state(self._state_index).get_value().value

    def _update(self, context, state):
        color = self._color.Eval(context)
        depth = self._depth.Eval(context).data if self._depth.HasValue(context) else None
        if self._time.HasValue(context):
            t = float(self._time.Eval(context)[0])
        else:
            t = context.get_time()
        new = track_frame(self.tracker_state(context), color.data, depth, t, self._intrinsics,
                          self._grid, self._params)
        state.get_mutable_abstract_state(self._state_index).set_value(Shared(new))

    def _calc_visual_change(self, context, output):
        output.SetFromVector(self.tracker_state(context).sdot)

    def _calc_features(self, context, output):
        output.set_value(self.tracker_state(context).features.copy())
