"""``CameraMotionDetector``: the camera notices its own motion from the static scene (beyond the
paper). A thin Drake wrapper around :func:`sustain_drake.perception.camera_motion.step`."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem
from pydrake.systems.sensors import CameraInfo

from sustain_drake.perception import camera_motion
from sustain_drake.perception.camera_motion import CameraMotionParams, CameraMotionState, SceneTurn
from sustain_drake.perception.optical_flow import TrackedFeatures
from sustain_drake.systems.motion_coincidence_detector import FeatureBodyFlags
from sustain_drake.systems.optical_flow_tracker import intrinsics_from_camera_info


@dataclass(frozen=True)
class _DetectorState:
    """The detector's state and the actuator positions (and time) of the previous update."""

    motion: CameraMotionState = field(default_factory=CameraMotionState)
    q: np.ndarray | None = None
    t: float = 0.0

    def __deepcopy__(self, memo):
        # Immutable (an update stores a new one, q a new array), so a copy shares it: Drake
        # copies abstract state twice per update, and on every context clone.
        return self


class CameraMotionDetector(LeafSystem):
    """Declares a camera move when the static scene moves coherently in the image
    (:mod:`sustain_drake.perception.camera_motion` documents the rule and its thresholds).

    .. pydrake_system::

        name: CameraMotionDetector
        input_ports:
        - tracked_features
        - feature_on_body
        - body_feature_cells (optional)
        - actuator_positions
        - gray_image (optional)
        output_ports:
        - camera_motion
        - accumulated_displacement
        - feature_on_body
        - scene_turn
        - scene_still_since
        - move_start

    Inputs: ``tracked_features`` (``TrackedFeatures`` of the ``OpticalFlowTracker``: the tracks'
    own pixels and flows), ``feature_on_body`` (``FeatureBodyFlags`` of the
    ``MotionCoincidenceDetector`` for the same features: a body feature or one in a body cell is
    the robot's), ``body_feature_cells`` (the detector's cells holding a body feature now, size
    ``num_cells``; unconnected: not used), ``actuator_positions`` (rad, size ``num_actuators``: a
    joint moves when its speed over the last period exceeds ``params.arm_speed``), ``gray_image``
    (the tracker's ``gray_image``, the frame of ``tracked_features``; with ``camera_info``, the
    still scene's look is remembered and a move the tracks missed is found by it,
    ``perception.scene_reference``; unconnected: not).

    Outputs: ``camera_motion`` (2, ``[moving, moves]``: 1 while a scene-motion episode lasts, and
    the number of camera moves declared so far; connect to ``CoordinationStateMachine``'s
    ``camera_motion``), ``accumulated_displacement`` (1, px: the current or last episode's
    composed image displacement), ``feature_on_body`` (the input's ``FeatureBodyFlags`` with
    ``on_body`` and ``in_body_cell`` cleared for the static scene's features,
    ``camera_motion.static_features``, when ``params.exclude_static``: connect to the
    ``CandidateIdentifiers``' ``feature_on_body``; unconnected flags: none on the body),
    ``scene_turn`` (``camera_motion.SceneTurn``: the static scene's correspondences across the last
    camera move, ``move`` 0 before any; formed ``params.turn_frames`` still frames after the move,
    only with ``camera_info``, the camera's intrinsics, and the tracked features' 3-D points;
    connect to the ``CandidateIdentifiers``' ``scene_turn``), ``scene_still_since`` (1, s: since
    when the still scene shows the camera has not moved: the frames judged still, joined across a
    gap (a person in front, too few anchors) that the still scene's reference, matched after it,
    showed no move in; inf while moving or while such a gap is not yet checked
    (``CameraMotionState.unmoved_since``): connect to the ``CandidateIdentifiers``'
    ``scene_still_since``), ``move_start``
    (1, s: when the last declared camera move began, -inf before any; connect to the
    ``CoordinationStateMachine``'s ``camera_move_start``, so that a move found late, after the
    observation rule's reset for it, is not declared a second change).

    Every ``period`` s (offset ``offset``: after the coincidence detector's update of the same
    frame) a periodic unrestricted update runs one step on a new frame (a frame time not newer
    than the last is skipped). State: one abstract value (the rule's ``CameraMotionState`` and the
    previous actuator positions).
    """

    def __init__(self, num_actuators: int, num_cells: int, image_size: tuple[int, int],
                 params: CameraMotionParams | None = None, period: float = 1.0 / 30.0,
                 offset: float = 0.0, camera_info: CameraInfo | None = None):  # fmt: skip
        super().__init__()
        if not (np.isfinite(period) and period > 0):
            raise ValueError(f"period must be positive, got {period}")
        self._params = params or CameraMotionParams()
        self._size = (int(image_size[0]), int(image_size[1]))
        self._intrinsics = None if camera_info is None else intrinsics_from_camera_info(camera_info)
        if camera_info is not None and (camera_info.width(), camera_info.height()) != self._size:
            raise ValueError(f"camera_info is {camera_info.width()}x{camera_info.height()} but the image is "
                             f"{self._size[0]}x{self._size[1]}")
        self._n_c = int(num_cells)
        self._features = self.DeclareAbstractInputPort(
            "tracked_features", AbstractValue.Make(TrackedFeatures()))
        self._flags = self.DeclareAbstractInputPort("feature_on_body", AbstractValue.Make(FeatureBodyFlags()))
        self._cells = self.DeclareVectorInputPort("body_feature_cells", self._n_c)
        self._q = self.DeclareVectorInputPort("actuator_positions", int(num_actuators))
        self._gray = self.DeclareAbstractInputPort("gray_image",
                                                   AbstractValue.Make(np.zeros((0, 0), np.uint8)))
        self._state = self.DeclareAbstractState(AbstractValue.Make(_DetectorState()))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, offset, self._update)
        state = {self.all_state_ticket()}
        self.DeclareVectorOutputPort("camera_motion", 2, lambda c, o: o.SetFromVector(
            self.motion_state(c).output()[:2]), prerequisites_of_calc=state)  # fmt: skip
        self.DeclareVectorOutputPort("accumulated_displacement", 1, lambda c, o: o.SetAtIndex(
            0, self.motion_state(c).accumulated_px), prerequisites_of_calc=state)  # fmt: skip
        self.DeclareAbstractOutputPort(
            "feature_on_body", lambda: AbstractValue.Make(FeatureBodyFlags()), self._calc_flags,
            prerequisites_of_calc={self.all_state_ticket(), self._flags.ticket()})  # fmt: skip
        self.DeclareVectorOutputPort("scene_still_since", 1, lambda c, o: o.SetAtIndex(
            0, self.motion_state(c).scene_still_since()), prerequisites_of_calc=state)  # fmt: skip
        self.DeclareVectorOutputPort("move_start", 1, lambda c, o: o.SetAtIndex(
            0, self.motion_state(c).move_start), prerequisites_of_calc=state)  # fmt: skip
        self.DeclareAbstractOutputPort(
            "scene_turn", lambda: AbstractValue.Make(SceneTurn()),
            lambda c, o: o.set_value(self.motion_state(c).turn), prerequisites_of_calc=state)  # fmt: skip

    @property
    def params(self) -> CameraMotionParams:
        return self._params

    def motion_state(self, context) -> CameraMotionState:
        """The rule's state in ``context`` (read only)."""
        return context.get_abstract_state(self._state).get_value().motion

    def _update(self, context, state) -> None:
        old = context.get_abstract_state(self._state).get_value()
        t, q = context.get_time(), np.array(self._q.Eval(context), float)
        joints_moving = np.zeros(q.size, bool)
        if old.q is not None and old.q.size == q.size and t > old.t:
            joints_moving = np.abs(q - old.q) / (t - old.t) > self._params.arm_speed
        new = replace(old, q=q, t=t)
        if self._features.HasValue(context):
            f = self._features.Eval(context)
            robot = self._robot(context, f)
            gray = self._gray.Eval(context) if self._gray.HasValue(context) else None
            if gray is not None and np.size(gray) == 0:
                gray = None  # no frame yet
            elif gray is not None and np.shape(gray) != (self._size[1], self._size[0]):
                raise ValueError(f"CameraMotionDetector: gray_image is {np.shape(gray)}, expected "
                                 f"{(self._size[1], self._size[0])} (height, width) uint8")
            new = replace(new, motion=camera_motion.step(
                old.motion, f, robot, joints_moving, self._params, self._size, self._intrinsics, gray))
        state.get_mutable_abstract_state(self._state).set_value(new)

    def _calc_flags(self, context, output) -> None:
        if not self._flags.HasValue(context):
            output.set_value(FeatureBodyFlags())
            return
        flags = self._flags.Eval(context)
        if not self._params.exclude_static:
            output.set_value(flags)
            return
        static = camera_motion.static_features(self.motion_state(context), flags.ids, self._params)
        output.set_value(replace(flags, on_body=np.asarray(flags.on_body, bool) & ~static,
                                 in_body_cell=np.asarray(flags.in_body_cell, bool) & ~static))

    def _robot(self, context, f: TrackedFeatures) -> np.ndarray:
        """Per feature: a body feature, in a body cell or in a cell holding a body feature."""
        robot = np.zeros(len(f), bool)
        if self._flags.HasValue(context):
            flags = self._flags.Eval(context)
            if not np.array_equal(flags.ids, f.ids):
                raise ValueError("CameraMotionDetector: feature_on_body is not for the tracked_features "
                                 "input (connect both to the same tracker)")
            robot |= np.asarray(flags.on_body, bool) | np.asarray(flags.in_body_cell, bool)
        if self._cells.HasValue(context):
            cells = np.asarray(self._cells.Eval(context)) > 0.5
            cell = np.asarray(f.cell, np.int64)
            inside = (cell >= 0) & (cell < self._n_c)
            robot[inside] |= cells[cell[inside]]
        return robot
