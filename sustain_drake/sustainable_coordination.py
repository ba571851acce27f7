"""The whole sustainable sensory-motor coordination as one Diagram for any controller and any arm.

``make_sustainable_coordination`` combines the hand-eye loop (paper §3.4, Fig. 7: optical-flow
tracker -> Eq. (27) motion coincidence detector -> candidate eye-to-hand identifiers <->
identify/observe state machine) and the kinesthetic loop (§3.5: quasi-static gate -> payload
identifier, Eqs. (37)-(38) <-> its own state machine, and optionally the touch estimator on the
held object). ``add_hand_eye_loop`` and ``add_payload_loop`` are the wiring shared with the
experiments (``experiments.hand_eye``, ``experiments.kinesthetic``): one place for it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from drake import lcmt_force_torque, lcmt_iiwa_status, lcmt_image_array
from pydrake.common.value import AbstractValue
from pydrake.manipulation import IiwaStatusReceiver
from pydrake.math import RigidTransform
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.lcm import LcmInterfaceSystem, LcmScopeSystem, LcmSubscriberSystem
from pydrake.systems.sensors import LcmImageArrayToImages

from sustain_drake.experiments.body_detection_config import BodyDetectionConfig
from sustain_drake.experiments.hand_eye_config import HandEyeConfig
from sustain_drake.experiments.kinesthetic_config import KinestheticConfig
from sustain_drake.systems.camera_motion_detector import CameraMotionDetector
from sustain_drake.systems.candidate_identifiers import CandidateIdentifiers, FeatureRefiner
from sustain_drake.systems.coordination_state_machine import CoordinationStateMachine
from sustain_drake.systems.ground_truth import PoseToVector
from sustain_drake.systems.hand_pose_from_plant import HandPoseFromPlant
from sustain_drake.systems.identifying_motion import IdentifyingMotion
from sustain_drake.systems.lcm_converters import ForceTorqueToWrench, ImageArrayTime
from sustain_drake.systems.motion_coincidence_detector import MotionCoincidenceDetector
from sustain_drake.systems.optical_flow_tracker import OpticalFlowTracker
from sustain_drake.systems.quasi_static_gate import QuasiStaticGate
from sustain_drake.systems.sustainable_identifier_system import (
    EyeToHandFormulation,
    PayloadFormulation,
    SustainableIdentifierSystem,
)
from sustain_drake.systems.touch_estimator import TouchEstimator


@dataclass
class HandEyeLoop:
    tracker: OpticalFlowTracker
    detector: MotionCoincidenceDetector
    candidates: CandidateIdentifiers
    state_machine: CoordinationStateMachine
    refiner: FeatureRefiner | None = None
    camera_motion: CameraMotionDetector | None = None
    identifying_motion: IdentifyingMotion | None = None

    def image_inputs(self, name: str) -> list:
        """The input ports that take the camera's ``name`` (color_image, depth_image, image_time)."""
        systems = (self.tracker, self.refiner, self.candidates)  # the candidates' with the depth check
        return [s.GetInputPort(name) for s in systems if s is not None and s.HasInputPort(name)]

    def actuator_inputs(self) -> list:
        """The input ports that take the joint positions (the detector's, the camera-motion
        detector's, the identifying motion's)."""
        systems = (self.detector, self.camera_motion)
        ports = [s.GetInputPort("actuator_positions") for s in systems if s is not None]
        if self.identifying_motion is not None:
            ports.append(self.identifying_motion.GetInputPort("joint_positions"))
        return ports

    def motion_confirm(self):
        """The output port the motion generator's confirming requests come from: the detector's
        ``confirm`` (paper §3.3), through the identifying motion when there is one."""
        if self.identifying_motion is not None:
            return self.identifying_motion.GetOutputPort("confirm")
        return self.detector.GetOutputPort("confirm")


@dataclass
class PayloadLoop:
    identifier: SustainableIdentifierSystem
    state_machine: CoordinationStateMachine
    gate: QuasiStaticGate
    estimator: TouchEstimator | None


def add_hand_eye_loop(builder, info, num_joints: int, fps: float, hand_eye: HandEyeConfig,
                      perception: BodyDetectionConfig, joint_ranges=None, motion_seed: int = 0,
                      ) -> HandEyeLoop:  # fmt: skip
    """Adds the tracker, detector, candidate identifiers and state machine, connected to each other.
    With ``hand_eye.camera_motion.enabled``, a ``CameraMotionDetector`` feeds the state machine's
    ``camera_motion``; with ``hand_eye.identifying_motion_interval`` > 0, an ``IdentifyingMotion``
    (far postures within ``joint_ranges``, n x [lower, upper] rad, drawn from ``motion_seed``)
    forwards the detector's confirming requests and adds its own while identifying. Left for the
    caller: the images (``HandEyeLoop.image_inputs``: the tracker's, with
    ``hand_eye.refine_points`` the ``FeatureRefiner``'s, with ``free_space_radius`` the candidates'
    depth), the joint positions
    (``HandEyeLoop.actuator_inputs``), the candidates' ``X_WH``, and the uses of
    ``HandEyeLoop.motion_confirm()`` and ``state_machine.pause``. Raises ValueError on bad settings."""
    if hand_eye.identifying_motion_interval > 0:
        if joint_ranges is None:
            raise ValueError("hand_eye.identifying_motion_interval needs the babbling's joint_ranges "
                             "(the postures it may ask for)")  # fmt: skip
        if len(joint_ranges) != num_joints:
            raise ValueError(f"joint_ranges has {len(joint_ranges)} rows for num_joints = {num_joints}")
        if not (hand_eye.identifying_motion_reach >= 0 and np.isfinite(hand_eye.identifying_motion_reach)):
            raise ValueError("hand_eye.identifying_motion_reach must be >= 0 rad (0: off), got "
                             f"{hand_eye.identifying_motion_reach}")
    criteria, rule = hand_eye.coordination.criteria(), hand_eye.coordination.rule()
    candidate_params = hand_eye.candidates.params()
    coincidence_params = perception.coincidence_params()
    feature_params, tracker_params = perception.feature_params(), perception.tracker_params()
    period = 1.0 / fps
    # The tracker a quarter frame after the camera samples, the detector half a frame.
    tracker = builder.AddSystem(OpticalFlowTracker(
        info, (perception.grid_rows, perception.grid_cols), period=period, offset=0.25 * period,
        params=tracker_params))  # fmt: skip
    tracker.set_name("optical_flow_tracker")
    detector = builder.AddSystem(MotionCoincidenceDetector(
        num_joints, tracker.grid.num_cells, period=period, offset=0.5 * period,
        params=coincidence_params, feature_params=feature_params))  # fmt: skip
    detector.set_name("motion_coincidence_detector")
    formulation = EyeToHandFormulation(criteria, hand_eye.coordination.forgetting_factor)
    depth_check = info if candidate_params.free_space_radius > 0 else None
    candidates = builder.AddSystem(CandidateIdentifiers(formulation, candidate_params, period, depth_check))
    candidates.set_name("candidate_identifiers")
    machine = builder.AddSystem(CoordinationStateMachine(16, rule, period))
    machine.set_name("coordination_state_machine")
    builder.Connect(tracker.GetOutputPort("visual_change"), detector.GetInputPort("visual_change"))
    builder.Connect(tracker.GetOutputPort("tracked_features"), detector.GetInputPort("tracked_features"))
    features, refiner = tracker.GetOutputPort("tracked_features"), None
    if hand_eye.refine_points:  # drift-free points for the identifiers (the detector keeps the tracks)
        refiner = builder.AddSystem(FeatureRefiner(info, hand_eye.refinement.params()))
        refiner.set_name("feature_refiner")
        builder.Connect(features, refiner.GetInputPort("tracked_features"))
        features = refiner.GetOutputPort("tracked_features")
    builder.Connect(features, candidates.GetInputPort("tracked_features"))
    connect_identify_observe(builder, candidates, machine)
    builder.Connect(machine.GetOutputPort("allowable_error"), candidates.GetInputPort("allowable_error"))
    camera = None
    if not hand_eye.camera_motion.enabled:
        builder.Connect(detector.GetOutputPort("feature_on_body"), candidates.GetInputPort("feature_on_body"))
    else:  # the camera notices its own motion from the static scene
        camera = builder.AddSystem(CameraMotionDetector(
            num_joints, tracker.grid.num_cells, (info.width(), info.height()),
            hand_eye.camera_motion.params(), period=period, offset=0.75 * period,
            camera_info=info))  # fmt: skip
        camera.set_name("camera_motion_detector")
        builder.Connect(tracker.GetOutputPort("tracked_features"), camera.GetInputPort("tracked_features"))
        for name in ("feature_on_body", "body_feature_cells"):
            builder.Connect(detector.GetOutputPort(name), camera.GetInputPort(name))
        builder.Connect(camera.GetOutputPort("camera_motion"), machine.GetInputPort("camera_motion"))
        # The identifiers' candidates without the static scene's features (stale body cells).
        builder.Connect(camera.GetOutputPort("feature_on_body"), candidates.GetInputPort("feature_on_body"))
        if candidate_params.keep_tool_points:  # a camera turn re-found from the scene and the tool points
            builder.Connect(camera.GetOutputPort("scene_turn"), candidates.GetInputPort("scene_turn"))
        # A scene still since before a reset: the camera did not move, only the tool point is new.
        builder.Connect(camera.GetOutputPort("scene_still_since"),
                        candidates.GetInputPort("scene_still_since"))
    motion = None
    if hand_eye.identifying_motion_interval > 0:  # far postures while identifying (richer motion)
        motion = builder.AddSystem(IdentifyingMotion(
            joint_ranges, hand_eye.identifying_motion_interval, seed=motion_seed, period=period,
            max_hold=hand_eye.identifying_motion_max_hold,
            more_motion_reach=hand_eye.identifying_motion_reach or None))  # fmt: skip
        motion.set_name("identifying_motion")
        if perception.confirm:  # the detector's confirming requests first (body detection, §3.3)
            builder.Connect(detector.GetOutputPort("confirm"), motion.GetInputPort("detector_confirm"))
        builder.Connect(machine.GetOutputPort("mode"), motion.GetInputPort("mode"))
        # Points converged whose views do not pin the camera's rotation: far postures now.
        builder.Connect(candidates.GetOutputPort("more_motion"), motion.GetInputPort("more_motion"))
    return HandEyeLoop(tracker, detector, candidates, machine, refiner, camera, motion)


def connect_identify_observe(builder, identifier, machine) -> None:
    """Closes the identify <-> observe loop (§3.1, §4.3) between an identifier system
    (``SustainableIdentifierSystem`` or ``CandidateIdentifiers``) and a
    ``CoordinationStateMachine``: the solution and each sample's error go to the machine; the
    adopted estimate (under which the errors are computed) and the reset count come back."""
    builder.Connect(identifier.GetOutputPort("solution"), machine.GetInputPort("solution"))
    builder.Connect(identifier.GetOutputPort("observation"), machine.GetInputPort("observation"))
    builder.Connect(machine.GetOutputPort("adopted_x"), identifier.GetInputPort("reference_x"))
    builder.Connect(machine.GetOutputPort("reset"), identifier.GetInputPort("reset"))


def add_payload_loop(builder, num_joints: int, config: KinestheticConfig, shape=None,
                     X_KG: RigidTransform | None = None) -> PayloadLoop:  # fmt: skip
    """Adds the payload identifier, its state machine, the quasi-static gate and (if ``shape``, the
    held object's ``pydrake.geometry`` shape at ``X_KG`` in the sensor frame) the touch estimator,
    connected to each other. Left for the caller: ``wrench`` and ``X_WK`` of the identifier and
    the estimator, the gate's ``joint_velocities``, the use of ``state_machine.pause``."""
    c, qs = config.coordination, config.quasi_static
    ident = builder.AddSystem(SustainableIdentifierSystem(
        PayloadFormulation(criteria=c.criteria(has_rotation=False), forgetting_factor=c.forgetting_factor),
        period=config.period))  # fmt: skip
    ident.set_name("payload_identifier")
    sm = builder.AddSystem(CoordinationStateMachine(PayloadFormulation.num_unknowns, c.rule(), config.period))
    sm.set_name("payload_coordination")
    gate = builder.AddSystem(QuasiStaticGate(
        num_joints, config.period, qs.max_joint_speed, qs.max_joint_acceleration, qs.window, qs.touch_holdoff,
        qs.max_touch_duration))  # fmt: skip
    gate.set_name("quasi_static_gate")
    estimator = None
    if shape is not None:
        estimator = builder.AddSystem(TouchEstimator(shape, X_KG, min_force=config.min_touch_force))
        estimator.set_name("touch_estimator")
        # A touch keeps its samples out of the identifier (see QuasiStaticGate).
        builder.Connect(estimator.GetOutputPort("touch"), gate.GetInputPort("touch"))
        builder.Connect(sm.GetOutputPort("adopted_solution"), estimator.GetInputPort("payload"))
        builder.Connect(sm.GetOutputPort("allowable_error"), estimator.GetInputPort("allowable_error"))
    builder.Connect(gate.GetOutputPort("sample_valid"), ident.GetInputPort("sample_valid"))
    connect_identify_observe(builder, ident, sm)
    return PayloadLoop(ident, sm, gate, estimator)


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


def make_sustainable_coordination(camera_info, num_joints: int, *, fps: float = 30.0,
                                  hand_eye: HandEyeConfig | None = None,
                                  body_detection: BodyDetectionConfig | None = None,
                                  kinesthetic: KinestheticConfig | None = None,
                                  plant=None, hand_frame=None, sensor_frame=None, model_instance=None,
                                  held_shape=None, X_KG: RigidTransform | None = None,
                                  joint_ranges=None, motion_seed: int = 0,
                                  ) -> Diagram:  # fmt: skip
    """The sustainable coordination of an arm with ``num_joints`` joints, a depth camera with
    intrinsics ``camera_info`` (``pydrake.systems.sensors.CameraInfo``) at ``fps`` frames per
    second, and a wrist force/torque sensor. Settings are the scenario sections' dataclasses
    (defaults if None). With ``plant`` (a finalized MultibodyPlant of the arm) and ``hand_frame``
    the hand pose (and the sensor pose, at ``sensor_frame``, else the hand's) is computed from the
    joint positions (``HandPoseFromPlant``); else it is the ``X_WH`` input and the sensor frame K is
    the hand frame H. ``held_shape`` (the held object's ``pydrake.geometry`` shape at ``X_KG`` in K)
    adds the touch estimator. ``joint_ranges`` (n x [lower, upper], rad) are the postures the
    identifying motion may ask for (needed with ``hand_eye.identifying_motion_interval`` > 0; its
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
    ``motion_confirm`` (the detector's confirming-motion request, paper §3.3, and with
    ``hand_eye.identifying_motion_interval`` the identifying motion's far postures) and
    ``hand_eye_pause`` and ``payload_pause`` (2 each, ``[request_id, seconds]``: each state
    machine asks the motion to stop after a convergence; a new id is a new request); ``X_WH_used``
    and ``X_WK_used`` (the hand and sensor poses the loops use).
    """
    hand_eye = hand_eye or HandEyeConfig()
    body_detection = body_detection or BodyDetectionConfig()
    kinesthetic = kinesthetic or KinestheticConfig()
    if plant is not None and hand_frame is None:
        raise ValueError("make_sustainable_coordination: a plant needs its hand_frame")
    if plant is None and not (hand_frame is None and sensor_frame is None and model_instance is None):
        raise ValueError("make_sustainable_coordination: hand_frame, sensor_frame and model_instance "
                         "need a plant")  # fmt: skip
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
        if fk.get_input_port().size() != num_joints:
            raise ValueError(f"make_sustainable_coordination: the plant has {fk.get_input_port().size()} "
                             f"positions for num_joints = {num_joints}")  # fmt: skip
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


class _PosePassThrough(LeafSystem):
    """One pose input fanned out inside the diagram (an exported input feeds several ports, and is
    also exported as an output)."""

    def __init__(self):
        super().__init__()
        port = self.DeclareAbstractInputPort("X_WH", AbstractValue.Make(RigidTransform()))
        self.DeclareAbstractOutputPort(
            "X_WH", lambda: AbstractValue.Make(RigidTransform()),
            lambda context, output: output.set_value(port.Eval(context)))  # fmt: skip



# Default LCM channels of the bridge: the sensors it reads, the estimates it publishes (lcmt_scope).
LCM_INPUT_CHANNELS = {"status": "SUSTAIN_ARM_STATUS", "force_torque": "SUSTAIN_FORCE_TORQUE",
                      "images": "SUSTAIN_RGBD"}  # fmt: skip
LCM_OUTPUT_CHANNELS = {
    "X_WC": "SUSTAIN_X_WC", "p_HP": "SUSTAIN_P_HP", "hand_eye_mode": "SUSTAIN_HAND_EYE_MODE",
    "hand_eye_pause": "SUSTAIN_HAND_EYE_PAUSE", "motion_confirm": "SUSTAIN_MOTION_CONFIRM",
    "payload_mass": "SUSTAIN_PAYLOAD_MASS", "p_KCm": "SUSTAIN_P_KCM", "payload_mode": "SUSTAIN_PAYLOAD_MODE",
    "payload_pause": "SUSTAIN_PAYLOAD_PAUSE", "touch": "SUSTAIN_TOUCH", "p_WP": "SUSTAIN_P_WP",
    "f_env_W": "SUSTAIN_F_ENV_W",
}  # fmt: skip


def make_lcm_bridge(lcm, camera_info, num_joints: int, *, plant, hand_frame, publish_period: float = 0.1,
                    wrench_sign: float = 1.0, input_channels: dict | None = None,
                    output_channels: dict | None = None, **coordination_kwargs) -> Diagram:  # fmt: skip
    """The coordination on a robot that speaks Drake's LCM messages: a Diagram (no ports) that
    subscribes, runs ``make_sustainable_coordination`` and publishes the estimates. Simulate it
    (e.g. ``Simulator`` with ``set_target_realtime_rate(1)``) to run it against hardware.

    Reads (on ``lcm``, a ``DrakeLcmInterface``; channels ``LCM_INPUT_CHANNELS`` updated by
    ``input_channels``): ``status`` ``lcmt_iiwa_status`` (Drake's joint status for any
    ``num_joints``: ``joint_position_measured``, ``joint_velocity_estimated``; read by
    ``IiwaStatusReceiver``), ``force_torque`` ``lcmt_force_torque`` (``wrench_sign``: see
    ``ForceTorqueToWrench``), ``images`` ``lcmt_image_array`` (a color and a depth image, as
    ``ImageToLcmImageArrayT`` writes them; decoded by ``LcmImageArrayToImages``; ``header.utime``
    is the capture time). The hand and sensor poses come from ``plant`` and ``hand_frame``
    (``sensor_frame`` etc. go to ``make_sustainable_coordination`` in ``coordination_kwargs``).

    Publishes every ``publish_period`` s, as ``lcmt_scope`` (Drake's vector message; channels
    ``LCM_OUTPUT_CHANNELS`` updated by ``output_channels``) the vector outputs of the
    coordination and ``X_WC`` as its 4x4 matrix, row-major (16 values).
    """
    inputs = {**LCM_INPUT_CHANNELS, **(input_channels or {})}
    outputs = {**LCM_OUTPUT_CHANNELS, **(output_channels or {})}
    if set(inputs) != set(LCM_INPUT_CHANNELS) or set(outputs) != set(LCM_OUTPUT_CHANNELS):
        raise ValueError(f"make_lcm_bridge: unknown channel keys; inputs {sorted(LCM_INPUT_CHANNELS)}, "
                         f"outputs {sorted(LCM_OUTPUT_CHANNELS)}")  # fmt: skip
    builder = DiagramBuilder()
    bus = builder.AddSystem(LcmInterfaceSystem(lcm))
    coordination = builder.AddSystem(make_sustainable_coordination(
        camera_info, num_joints, plant=plant, hand_frame=hand_frame, **coordination_kwargs))  # fmt: skip

    def subscribe(key, lcm_type, cpp, suffix=""):
        sub = builder.AddSystem(LcmSubscriberSystem.Make(inputs[key], lcm_type, bus, use_cpp_serializer=cpp))
        sub.set_name(f"lcm_subscriber_{key}{suffix}")
        return sub.get_output_port()

    status = builder.AddSystem(IiwaStatusReceiver(num_joints))
    builder.Connect(subscribe("status", lcmt_iiwa_status, True), status.get_input_port())
    builder.Connect(status.GetOutputPort("position_measured"), coordination.GetInputPort("joint_positions"))
    builder.Connect(status.GetOutputPort("velocity_estimated"), coordination.GetInputPort("joint_velocities"))
    wrench = builder.AddSystem(ForceTorqueToWrench(wrench_sign))
    builder.Connect(subscribe("force_torque", lcmt_force_torque, False), wrench.get_input_port())
    builder.Connect(wrench.get_output_port(), coordination.GetInputPort("wrench"))
    images = builder.AddSystem(LcmImageArrayToImages())
    images.set_name("lcm_image_array_to_images")
    builder.Connect(subscribe("images", lcmt_image_array, True), images.get_input_port())
    for name in ("color_image", "depth_image"):
        builder.Connect(images.GetOutputPort(name), coordination.GetInputPort(name))
    # The C++ message is opaque to Python: a second (Python) subscription reads the capture time.
    image_time = builder.AddSystem(ImageArrayTime())
    builder.Connect(subscribe("images", lcmt_image_array, False, "_time"), image_time.get_input_port())
    builder.Connect(image_time.get_output_port(), coordination.GetInputPort("image_time"))

    for key, channel in outputs.items():
        if not coordination.HasOutputPort(key):
            continue  # the touch outputs exist only with a held shape
        port = coordination.GetOutputPort(key)
        if key == "X_WC":
            matrix = builder.AddSystem(PoseToVector())
            builder.Connect(port, matrix.get_input_port())
            port = matrix.get_output_port()
        LcmScopeSystem.AddToBuilder(builder, lcm, port, channel, publish_period)
    diagram = builder.Build()
    diagram.set_name("sustainable_coordination_lcm_bridge")
    return diagram
