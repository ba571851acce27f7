"""The whole sustainable sensory-motor coordination as one Diagram for any controller and any arm:
``make_sustainable_coordination`` combines the hand-eye loop and the payload loop behind documented
ports."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.sensors import CameraConfig, CameraInfo

from sustain_drake.loops.body_detection import BodyDetectionConfig
from sustain_drake.loops.hand_eye import HandEyeConfig, add_hand_eye_loop
from sustain_drake.loops.payload import KinestheticConfig, add_payload_loop
from sustain_drake.systems.hand_pose_from_plant import HandPoseFromPlant


class AdoptedEstimates(LeafSystem):
    """The adopted (converged and still observed) estimates of the two state machines as plain ports.

    .. pydrake_system::

        name: AdoptedEstimates
        input_ports:
        - hand_eye_solution
        - payload_solution
        output_ports:
        - X_WC
        - p_HP
        - payload_mass
        - p_KCm

    Inputs: the ``adopted_solution`` of the hand-eye and of the payload ``CoordinationStateMachine``
    (None before an adoption and after a detected change). Outputs: ``X_WC`` (RigidTransform, the
    camera pose), ``p_HP`` (3, m, the tool point in the hand frame), ``payload_mass`` (1, kg),
    ``p_KCm`` (3, m, the payload's centre of mass in the sensor frame). With nothing adopted they
    hold the identity, zeros and a zero mass (never NaN): read the ``*_mode`` outputs to know.
    """

    def __init__(self):
        super().__init__()
        self._hand_eye = self.DeclareAbstractInputPort("hand_eye_solution", AbstractValue.Make(object()))
        self._payload = self.DeclareAbstractInputPort("payload_solution", AbstractValue.Make(object()))
        self.DeclareAbstractOutputPort("X_WC", lambda: AbstractValue.Make(RigidTransform()), self._calc_X_WC)
        self.DeclareVectorOutputPort("p_HP", 3, self._calc_p_HP)
        self.DeclareVectorOutputPort("payload_mass", 1, self._calc_mass)
        self.DeclareVectorOutputPort("p_KCm", 3, self._calc_p_KCm)

    def _estimate(self, context):
        return getattr(self._hand_eye.Eval(context), "estimate", None)

    def _calc_X_WC(self, context, output) -> None:
        est = self._estimate(context)
        output.set_value(RigidTransform() if est is None else RigidTransform(est.X_WC))

    def _calc_p_HP(self, context, output) -> None:
        est = self._estimate(context)
        output.SetFromVector(np.zeros(3) if est is None else est.p_HP)

    def _calc_mass(self, context, output) -> None:
        solution = self._payload.Eval(context)
        output.SetAtIndex(0, 0.0 if solution is None else solution.mass)

    def _calc_p_KCm(self, context, output) -> None:
        solution = self._payload.Eval(context)
        output.SetFromVector(np.zeros(3) if solution is None else solution.p_KCm)


def camera_intrinsics(camera, argument: str = "camera_info") -> CameraInfo:
    """The intrinsics of ``camera``: a ``pydrake.systems.sensors.CameraInfo`` as it is, or those of
    a ``CameraConfig``'s colour camera (its width, height, focal lengths and principal point, as
    ``CameraConfig.MakeCameras`` makes them; the config's ``fps`` is not read). Any other type raises
    a one-line ``TypeError`` naming ``argument``."""
    if isinstance(camera, CameraInfo):
        return camera
    if isinstance(camera, CameraConfig):
        color_camera, _ = camera.MakeCameras()
        return color_camera.core().intrinsics()
    raise TypeError(f"{argument} must be a pydrake.systems.sensors.CameraInfo or CameraConfig, got "
                    f"{type(camera).__name__}")


def make_sustainable_coordination(camera_info, num_joints: int, *, fps: float = 30.0,
                                  hand_eye: HandEyeConfig | None = None,
                                  body_detection: BodyDetectionConfig | None = None,
                                  kinesthetic: KinestheticConfig | None = None,
                                  plant=None, hand_frame=None, sensor_frame=None, model_instance=None,
                                  held_shape=None, X_KG: RigidTransform | None = None,
                                  joint_ranges=None, motion_seed: int = 0,
                                  ) -> Diagram:  # fmt: skip
    """The sustainable coordination of an arm with ``num_joints`` joints, a depth camera with
    intrinsics ``camera_info`` (a ``pydrake.systems.sensors.CameraInfo``, or a ``CameraConfig`` whose
    intrinsics are taken, ``camera_intrinsics``; any other type raises ``TypeError``) at ``fps``
    frames per second (not read from a ``CameraConfig``), and a wrist force/torque sensor. Settings
    are the scenario sections' dataclasses (defaults if None). With ``plant`` (a finalized
    MultibodyPlant of the arm) and ``hand_frame`` the hand pose (and the sensor pose, at
    ``sensor_frame``, else the hand's) is computed from the joint positions
    (``HandPoseFromPlant``); else it is the ``X_WH`` input and the sensor frame K is the hand frame
    H. ``held_shape`` (the held object's ``pydrake.geometry`` shape at ``X_KG`` in K)
    adds the touch estimator. ``joint_ranges`` (n x [lower, upper], rad) are the postures the
    identifying motion may ask for (needed with ``hand_eye.identifying_motion_interval`` > 0, the
    default; with a plant and no ranges, its position limits narrowed by ``RANGE_MARGIN``; its
    draws come from ``motion_seed``).

    .. pydrake_system::

        name: SustainableCoordination
        input_ports:
        - color_image
        - depth_image
        - image_time (optional)
        - joint_positions
        - joint_velocities
        - X_WH (without plant)
        - wrench
        output_ports:
        - X_WC
        - p_HP
        - hand_eye_mode
        - hand_eye_events
        - hand_eye_allowable_error
        - camera_motion (with hand_eye.camera_motion.enabled)
        - payload_mass
        - p_KCm
        - payload_mode
        - payload_events
        - touch (with held_shape)
        - p_WP (with held_shape)
        - f_env_W (with held_shape)
        - motion_confirm
        - hand_eye_pause
        - payload_pause
        - X_WH_used
        - X_WK_used

    Inputs: ``color_image`` (ImageRgba8U), ``depth_image`` (ImageDepth32F, m), ``image_time`` (1, s,
    the capture time; unconnected: every frame is new), ``joint_positions`` and
    ``joint_velocities`` (``num_joints``; velocities gate the quasi-static wrench samples),
    ``X_WH`` (RigidTransform), ``wrench`` (6, ``[tau_K; f_K]`` applied by the wrist on the
    outboard side, N m and N, in K; see ``identification.payload``).

    Outputs: ``X_WC``, ``p_HP``, ``payload_mass``, ``p_KCm`` (adopted estimates, see
    ``AdoptedEstimates``); ``hand_eye_mode`` and ``payload_mode`` (1: 0 identify, 1 observe);
    ``*_events`` (the state machines' event lists); ``hand_eye_allowable_error`` (1, m^2);
    ``camera_motion`` (2, ``[moving, moves]``: the camera noticed its own motion from the static
    scene, ``CameraMotionDetector``; each new move is a hand-eye change detection);
    the touch estimator's ``touch``, ``p_WP``, ``f_env_W``; for the user's motion generator
    ``motion_confirm``, ``hand_eye_pause`` and ``payload_pause`` (below); ``X_WH_used``
    and ``X_WK_used`` (the hand and sensor poses the loops use).

    Which outputs mean something when: ``X_WC`` is the identity and ``p_HP`` zeros until the first
    hand-eye convergence (a ``converged`` event, ``hand_eye_mode`` 1); from then on they are the
    adopted camera and tool point. A camera move (a ``change_detected`` event "the camera moved")
    drops them (identity and zeros again until the next convergence); a failed observation (a
    ``change_detected`` event "... samples over the limit": the tool slipped) keeps the last adopted
    ones while ``hand_eye_mode`` is 0 and the loop identifies again: use them while
    ``hand_eye_mode`` is 1. ``hand_eye_allowable_error`` is 0 until the first convergence, then the
    last adoption's. ``payload_mass`` and ``p_KCm`` are zeros until ``payload_mode`` first turns 1.

    The motion interface (``systems.motion_generator.MotionGenerator`` answers it;
    docs/on_your_robot.md). Each request is edge-triggered by its ``request_id``: it is new when the
    id differs from the last one seen; the ids start at 0, which is no request, so hold the last id
    seen and never act on an unchanged one. ``motion_confirm`` and ``hand_eye_pause`` change at
    most once per camera frame (1 / ``fps``), ``payload_pause`` once per ``kinesthetic.period``.

    - ``motion_confirm`` (``2 + num_joints``: ``[request_id, joint, q_1..q_n]``, ``q`` in rad): stop
      smoothly, go to the posture ``q``, rest there still (``MotionGenerator``: ``confirm_hold``,
      0.5 s), then move again: only joint ``joint``
      (0-based) when ``joint >= 0``, a usual move when ``joint < 0``. The body detector's
      confirming request (paper §3.3: ``q`` is the posture at the onset of the move that coincided
      with candidate pixels' motion; the trial is the first move starting within
      ``body_detection.posture_tolerance``, 0.05 rad max-norm, of ``q`` after the whole arm rested
      0.1 s; unanswered for ``body_detection.confirm_timeout``, 5 s, it expires) and, while the
      hand-eye loop identifies, the identifying motion's far postures (drawn within
      ``joint_ranges``; ``joint`` -1). A new request replaces one not yet answered. Clip ``q`` to
      your arm's safe ranges.
    - ``hand_eye_pause``, ``payload_pause`` (2 each, ``[request_id, seconds]``): the state machine
      converged; brake smoothly, hold still for ``seconds`` (``coordination.pause_after_convergence``,
      3 s by default), then carry on.
    """
    camera_info = camera_intrinsics(camera_info)
    hand_eye = hand_eye or HandEyeConfig()
    body_detection = body_detection or BodyDetectionConfig()
    kinesthetic = kinesthetic or KinestheticConfig()
    if plant is not None and hand_frame is None:
        raise ValueError("make_sustainable_coordination: a plant needs its hand_frame")
    if plant is None and not (hand_frame is None and sensor_frame is None and model_instance is None):
        raise ValueError("make_sustainable_coordination: hand_frame, sensor_frame and model_instance "
                         "need a plant")  # fmt: skip
    if plant is not None:
        positions = plant.num_positions() if model_instance is None else plant.num_positions(model_instance)
        if positions != num_joints:
            raise ValueError(f"make_sustainable_coordination: the plant has {positions} positions for "
                             f"num_joints = {num_joints}")  # fmt: skip
        if joint_ranges is None:
            joint_ranges = joint_ranges_from_limits(plant, model_instance)
    builder = DiagramBuilder()
    try:
        vision = add_hand_eye_loop(builder, camera_info, num_joints, fps, hand_eye, body_detection,
                                   joint_ranges, motion_seed)  # fmt: skip
    except ValueError as e:
        raise ValueError(f"make_sustainable_coordination: {e}") from None
    touch = add_payload_loop(builder, num_joints, kinesthetic, held_shape, X_KG)

    for name in ("color_image", "depth_image", "image_time"):
        first, *others = vision.image_inputs(name)
        builder.ExportInput(first, name)
        for port in others:
            builder.ConnectInput(name, port)
    first, *others = vision.actuator_inputs()
    joint_positions = builder.ExportInput(first, "joint_positions")
    for port in others:
        builder.ConnectInput(joint_positions, port)
    builder.ExportInput(touch.gate.GetInputPort("joint_velocities"), "joint_velocities")
    if plant is not None:
        fk = builder.AddSystem(HandPoseFromPlant(plant, hand_frame, sensor_frame, model_instance))
        fk.set_name("hand_pose_from_plant")
        builder.ConnectInput(joint_positions, fk.get_input_port())
        X_WH, X_WK = fk.GetOutputPort("X_WH"), fk.GetOutputPort("X_WK")
    else:
        passthrough = builder.AddSystem(_PosePassThrough())
        builder.ExportInput(passthrough.get_input_port(), "X_WH")
        X_WH = X_WK = passthrough.get_output_port()
    builder.Connect(X_WH, vision.candidates.GetInputPort("X_WH"))
    consumers = [touch.identifier] + ([touch.estimator] if touch.estimator is not None else [])
    wrench = [system.GetInputPort("wrench") for system in consumers]
    builder.ExportInput(wrench[0], "wrench")
    for port in wrench[1:]:
        builder.ConnectInput("wrench", port)
    for system in consumers:
        builder.Connect(X_WK, system.GetInputPort("X_WK"))

    adopted = builder.AddSystem(AdoptedEstimates())
    adopted.set_name("adopted_estimates")
    for prefix, machine in (("hand_eye", vision.state_machine), ("payload", touch.state_machine)):
        builder.Connect(machine.GetOutputPort("adopted_solution"), adopted.GetInputPort(f"{prefix}_solution"))
    for name in ("X_WC", "p_HP", "payload_mass", "p_KCm"):
        builder.ExportOutput(adopted.GetOutputPort(name), name)
    for prefix, machine in (("hand_eye", vision.state_machine), ("payload", touch.state_machine)):
        builder.ExportOutput(machine.GetOutputPort("mode"), f"{prefix}_mode")
        builder.ExportOutput(machine.GetOutputPort("events"), f"{prefix}_events")
    builder.ExportOutput(vision.state_machine.GetOutputPort("allowable_error"), "hand_eye_allowable_error")
    if vision.camera_motion is not None:
        builder.ExportOutput(vision.camera_motion.GetOutputPort("camera_motion"), "camera_motion")
    if touch.estimator is not None:
        for name in ("touch", "p_WP", "f_env_W"):
            builder.ExportOutput(touch.estimator.GetOutputPort(name), name)
    builder.ExportOutput(vision.motion_confirm(), "motion_confirm")
    builder.ExportOutput(vision.state_machine.GetOutputPort("pause"), "hand_eye_pause")
    builder.ExportOutput(touch.state_machine.GetOutputPort("pause"), "payload_pause")
    builder.ExportOutput(X_WH, "X_WH_used")
    builder.ExportOutput(X_WK, "X_WK_used")
    diagram = builder.Build()
    diagram.set_name("sustainable_coordination")
    return diagram


# Fraction of a joint's limit range kept clear at each end when the ranges come from the limits:
# the identifying motion's postures stay off the limits' stops.
RANGE_MARGIN = 0.1


def joint_ranges_from_limits(plant, model_instance=None) -> np.ndarray:
    """``[lower, upper]`` (rad) per position of ``plant`` (of ``model_instance`` if given): its
    position limits narrowed by ``RANGE_MARGIN`` of their span at each end; a joint without finite
    limits turns within +-pi."""
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    if model_instance is not None:
        lower = plant.GetPositionsFromArray(model_instance, lower)
        upper = plant.GetPositionsFromArray(model_instance, upper)
    lower = np.where(np.isfinite(lower), lower, -np.pi)
    upper = np.where(np.isfinite(upper), upper, np.pi)
    margin = RANGE_MARGIN * (upper - lower)
    return np.column_stack([lower + margin, upper - margin])


class _PosePassThrough(LeafSystem):
    """One pose input fanned out inside the diagram (an exported input feeds several ports, and is
    also exported as an output)."""

    def __init__(self):
        super().__init__()
        port = self.DeclareAbstractInputPort("X_WH", AbstractValue.Make(RigidTransform()))
        self.DeclareAbstractOutputPort(
            "X_WH", lambda: AbstractValue.Make(RigidTransform()),
            lambda context, output: output.set_value(port.Eval(context)))  # fmt: skip
