"""The marker-free hand-eye loop (paper §3.4, Fig. 7): its settings as a scenario section and its
wiring: optical-flow tracker -> Eq. (27) motion coincidence detector -> candidate eye-to-hand
identifiers <-> identify/observe state machine, with the camera-motion detector and the identifying
motion beyond the paper."""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import dataclasses
from dataclasses import dataclass, field

import numpy as np

from sustain_drake.identification.candidates import CandidateParams
from sustain_drake.loops.body_detection import BodyDetectionConfig, add_body_detection
from sustain_drake.loops.identify_observe import CoordinationConfig, connect_identify_observe
from sustain_drake.perception.camera_motion import CameraMotionParams
from sustain_drake.perception.point_refinement import RefinementParams
from sustain_drake.systems.camera_motion_detector import CameraMotionDetector
from sustain_drake.systems.candidate_identifiers import CandidateIdentifiers, FeatureRefiner
from sustain_drake.systems.coordination_state_machine import CoordinationStateMachine
from sustain_drake.systems.identifying_motion import IdentifyingMotion
from sustain_drake.systems.motion_coincidence_detector import MotionCoincidenceDetector
from sustain_drake.systems.optical_flow_tracker import OpticalFlowTracker
from sustain_drake.systems.sustainable_identifier_system import EyeToHandFormulation


@dataclasses.dataclass
class CameraMotionConfig(CameraMotionParams):
    """The camera notices its own motion from the static scene (beyond the paper): the detector's
    thresholds (``perception.camera_motion.CameraMotionParams``) and whether it runs."""

    enabled: bool = False  # add a CameraMotionDetector whose camera moves are change detections

    def params(self) -> CameraMotionParams:
        """The detector's thresholds alone (raises ``ValueError`` with one line on bad values)."""
        return CameraMotionParams(**{f.name: getattr(self, f.name)
                                     for f in dataclasses.fields(CameraMotionParams)})


@dataclasses.dataclass
class HandEyeConfig:
    """Sustainable marker-free hand-eye coordination: identifiers per candidate body feature and
    the identify <-> observe state machine (paper §3.4, §4.3)."""

    enabled: bool = False  # run the hand-eye experiment on the scenario's world
    coordination: CoordinationConfig = field(default_factory=CoordinationConfig)  # convergence, observation
    candidates: CandidateParams = field(default_factory=CandidateParams)  # candidate tracked points (Fig. 7)
    camera_motion: CameraMotionConfig = field(default_factory=CameraMotionConfig)  # the camera's own motion
    # s; > 0: while identifying, a far posture is asked of the babbling when no confirming request
    # came for this long (systems.identifying_motion); 0: off.
    identifying_motion_interval: float = 0.0
    # s (>= the interval): after a first convergence, a far posture also comes when the arm has
    # stayed within 0.2 rad of one posture this long, however often the detector asks.
    identifying_motion_max_hold: float = 3.0
    # rad; > 0: while the candidates ask for more motion, the postures asked for lie within this
    # (max-norm) of the arm's posture when the ask began; 0: far postures over the whole ranges.
    identifying_motion_reach: float = 0.0
    refine_points: bool = True  # feed the candidates sub-pixel corners and robust depth (FeatureRefiner)
    refinement: RefinementParams = field(default_factory=RefinementParams)  # the FeatureRefiner's thresholds
    false_alarm_window: float = 2.0  # s; a detection with no disturbance this long before is a false alarm
    log_rate: float = 30.0  # samples per second of the logged signals (plots, metrics)


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
    # Copies with their values checked again: a scenario file or a user sets fields after construction.
    candidate_params = dataclasses.replace(hand_eye.candidates)
    refinement = dataclasses.replace(hand_eye.refinement)
    body = add_body_detection(builder, info, num_joints, fps, perception)
    tracker, detector, period = body.tracker, body.detector, 1.0 / fps
    formulation = EyeToHandFormulation(criteria, hand_eye.coordination.forgetting_factor)
    depth_check = info if candidate_params.free_space_radius > 0 else None
    candidates = builder.AddSystem(CandidateIdentifiers(formulation, candidate_params, period, depth_check))
    candidates.set_name("candidate_identifiers")
    machine = builder.AddSystem(CoordinationStateMachine(16, rule, period))
    machine.set_name("coordination_state_machine")
    features, refiner = tracker.GetOutputPort("tracked_features"), None
    if hand_eye.refine_points:  # drift-free points for the identifiers (the detector keeps the tracks)
        refiner = builder.AddSystem(FeatureRefiner(info, refinement))
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
