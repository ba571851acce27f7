"""The marker-free hand-eye loop (paper §3.4, Fig. 7): its settings as a scenario section and its
wiring: optical-flow tracker -> Eq. (27) motion coincidence detector -> candidate eye-to-hand
identifiers <-> identify/observe state machine, with the camera-motion detector and the identifying
motion beyond the paper."""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from sustain_drake.identification.candidates import CandidateParams
from sustain_drake.loops.body_detection import BodyDetectionConfig, add_body_detection
from sustain_drake.loops.identify_observe import CoordinationConfig, connect_identify_observe
from sustain_drake.loops.payload import KinestheticConfig, PayloadLoop
from sustain_drake.loops.pixel_scale import RAD_PER_PX_MEASURED, pixel_scale, scaled
from sustain_drake.perception.camera_motion import CameraMotionParams
from sustain_drake.perception.point_refinement import SADDLE_SYMMETRY, RefinementParams
from sustain_drake.systems.camera_motion_detector import CameraMotionDetector
from sustain_drake.systems.candidate_identifiers import CandidateIdentifiers, FeatureRefiner
from sustain_drake.systems.coordination_state_machine import CoordinationStateMachine
from sustain_drake.systems.depth_noise import DepthNoiseModel
from sustain_drake.systems.exciting_postures import HandEyePostures, HandKinematics
from sustain_drake.systems.identifying_motion import IdentifyingMotion
from sustain_drake.systems.motion_coincidence_detector import MotionCoincidenceDetector
from sustain_drake.systems.optical_flow_tracker import OpticalFlowTracker
from sustain_drake.systems.sustainable_identifier_system import EyeToHandFormulation

# m: the depth at which the depth noise sets the allowable error's floor (``noise_rms``): the
# nearest the held tool comes to the camera in the measured scene, where its noise is the smallest
NOISE_FLOOR_DEPTH = 0.6
# m: the floor is the sensor's sigma there rounded up to this (1.2 + 0.08 mm -> 1.3 mm)
NOISE_FLOOR_STEP = 1e-4


@dataclass
class HandEyeConfig:
    """Sustainable marker-free hand-eye coordination: identifiers per candidate body feature and
    the identify <-> observe state machine (paper §3.4, §4.3). The scenario's ``hand_eye`` section:
    the robot's and tool's sizes, the sensor's noise model, the paper's rule and which steps beyond
    the paper run. Every other threshold is a constant of the loop (``hand_eye_parts``), stated with
    its reason where it is defined. The defaults are the configuration the results were measured
    with (docs/results.md)."""

    enabled: bool = False  # run the hand-eye experiment on the scenario's world
    # the depth sensor's noise sigma(z), m: the allowable error's floor, how closely a point must be pinned
    depth_noise: DepthNoiseModel = field(default_factory=DepthNoiseModel)
    max_hand_radius: float = 0.6  # m: farthest a tracked point on the hand or its tool lies from the hand
    tool_radius: float = 0.1  # m: points this near the tool point in H are the tool's (a slip moves them)
    # count: samples before a point's identifier may converge (8.3 s at 30 Hz: views from several sides)
    min_samples: int = 250
    max_expected_rms: float = 0.005  # m, criterion (a): the physical form of lambda_16 < 5e-5
    allowable_error_factor: float = 100.0  # sigma = factor * max(a^2 lambda_16, noise_rms^2), the paper's
    max_consecutive_violations: int = 10  # count: samples over sigma in a row that are a change, the paper's
    pause_after_convergence: float = 3.0  # s the motion pauses after a convergence, the paper's
    max_candidates: int = 8  # count: identifiers run at a time, one per candidate point (the cost per frame)
    camera_motion: bool = True  # the camera notices its own motion from the static scene (needs one in view)
    # s without a confirming request before a far posture is asked for while identifying; 0: off
    identifying_motion_interval: float = 1.0
    # s (>= the interval) the arm may hold within 0.2 rad of one posture before a far one is asked for
    identifying_motion_max_hold: float = 3.0
    # rad (max-norm) from the arm's posture that the postures asked for more motion keep to; 0: anywhere
    identifying_motion_reach: float = 0.1
    # the postures asked for are those whose moves add the most to the statistic of the point wanting
    # motion, with it kept in view (needs the arm's plant; issue 25); off: the farthest (no sooner)
    excite: bool = False
    refine_points: bool = True  # feed the candidates fixed points and robust depth (FeatureRefiner)
    # the wrist wrench's payload identification (dynamic mode) watches the held tool: its change
    # detection is a slip, found while no tracked point shows it (needs a wrist force/torque sensor)
    slip_from_wrench: bool = True
    false_alarm_window: float = 2.0  # s; a detection with no disturbance this long before is a false alarm
    log_rate: float = 30.0  # samples per second of the logged signals (plots, metrics)


@dataclass
class CameraMotionConfig:
    """The camera notices its own motion from the static scene (beyond the paper,
    ``perception.camera_motion``). Image thresholds are angles (rad), turned into pixels with the
    camera's focal length; the detector's other constants are ``CameraMotionParams``' defaults."""

    enabled: bool = True  # add a CameraMotionDetector whose camera moves are change detections
    min_background: int = 20  # count: still scene features (anchors) needed to judge a frame
    anchor_time: float = 0.5  # s a feature stays still before it is an anchor
    # rad of composed image motion that make an episode a camera move: a turn by a moves points at
    # depth z by z a, and sqrt(allowable error) ~ 13 mm at the tool's <= 0.9 m is 14 mrad, so
    # 10.4 mrad (6 px at the measured camera) counts every move the observation rule could see
    move_angle: float = 6.0 * RAD_PER_PX_MEASURED
    # rad: a feature within this of the scene's fitted motion is a RANSAC inlier (2 px measured)
    inlier_angle: float = 2.0 * RAD_PER_PX_MEASURED
    # rad per frame at or below which the scene is not moving (1 px measured)
    still_angle: float = 1.0 * RAD_PER_PX_MEASURED
    # rad a still feature may wander and stay an anchor (1 px measured)
    feature_still_angle: float = 1.0 * RAD_PER_PX_MEASURED
    # rad per frame: a frame moving at most this adds to the still scene's view (0.2 px measured)
    view_still_angle: float = 0.2 * RAD_PER_PX_MEASURED
    exclude_static: bool = True  # features still through 0.5 s of arm motion are no hand candidates

    def params(self, focal_px: float) -> CameraMotionParams:
        """The detector's thresholds in px for a camera of focal length ``focal_px`` (raises
        ``ValueError`` with one line on bad values)."""
        return CameraMotionParams(
            min_background=self.min_background, anchor_time=self.anchor_time,
            move_px=self.move_angle * focal_px, inlier_px=self.inlier_angle * focal_px,
            still_px=self.still_angle * focal_px, feature_still_px=self.feature_still_angle * focal_px,
            view_still_px=self.view_still_angle * focal_px, exclude_static=self.exclude_static)


@dataclass(frozen=True)
class HandEyeParts:
    """Every setting of the hand-eye loop: a ``HandEyeConfig`` (the user's) and the math layer's
    parameter objects made from it (``hand_eye_parts``). ``add_hand_eye_loop`` takes either; a
    study that varies a constant passes parts with it changed (``dataclasses.replace``)."""

    config: HandEyeConfig
    coordination: CoordinationConfig  # convergence criteria and the observation rule
    candidates: CandidateParams  # the candidate identifiers' rules (Fig. 7 and beyond)
    refinement: RefinementParams  # the FeatureRefiner's thresholds at the measured camera
    camera_motion: CameraMotionConfig  # the camera-motion detector's (enabled from the config)


def noise_floor(depth_noise: DepthNoiseModel) -> float:
    """``noise_rms`` (m): the per-sample RMS residual of the sensor's noise alone, the floor under
    the allowable error: ``sigma(NOISE_FLOOR_DEPTH)`` rounded up to ``NOISE_FLOOR_STEP``."""
    steps = math.ceil(float(depth_noise.sigma(NOISE_FLOOR_DEPTH)) / NOISE_FLOOR_STEP - 1e-9)
    return steps / round(1.0 / NOISE_FLOOR_STEP)  # 13 / 10000 is the double nearest 0.0013


def hand_eye_parts(config: HandEyeConfig) -> HandEyeParts:
    """The loop's parameter objects from the user's settings. The constants below are the measured
    configuration (docs/results.md); each rule they turn on is described at its field
    (``CandidateParams``, ``RefinementParams``, ``CoordinationConfig``) and in docs/hand_eye.md."""
    coordination = CoordinationConfig(
        max_expected_rms=config.max_expected_rms,
        min_gap_ratio=30.0,  # criterion (b): lambda_15 / lambda_16
        max_ssd=0.1,  # criterion (c), the paper's
        min_samples=config.min_samples,
        allowable_error_factor=config.allowable_error_factor,
        noise_rms=noise_floor(config.depth_noise),
        max_consecutive_violations=config.max_consecutive_violations,
        pause_after_convergence=config.pause_after_convergence,
    )  # fmt: skip
    candidates = CandidateParams(
        max_candidates=config.max_candidates, max_hand_radius=config.max_hand_radius,
        observe_radius=config.tool_radius,
        motion_min_samples=30, max_unconverged_time=30.0,
        joint=True, joint_consistency=2.0, joint_weighted=True, max_observers=4,
        observe_min_samples=100,
        reacquire_radius=0.004,  # m, three times the depth noise
        min_rotation_spread=0.05, keep_allowable_error=True,
        # rad between a point's distinct views: half the view distance beyond which a track's
        # errors no longer correlate (0.16 rad, bench/bench_view_correlation.py), so the views'
        # errors are nearly independent of each other
        view_angle=0.08,
        free_space_radius=0.005,  # m around the adopted tool point: the smallest depth seen behind it
        keep_tool_points=True, turn_admit_known=True,
        # after a slip with the scene still, only p_HP is new (3 unknowns): 1.7 s at 30 Hz
        keep_camera_min_samples=50,
        # the camera's 95 % region within the hand-eye targets (2 mm, 0.2 deg) before adoption
        camera_accuracy=0.002, camera_rotation_accuracy=math.radians(0.2),
    )  # fmt: skip
    # Centrally symmetric corners first (cornerSubPix with a 9 x 9 window: Shi-Tomasi's 7 px block
    # puts a corner ~2.5 px inside it), then points anchored on a 17 x 17 patch where their track
    # began; the depth on the face's fitted plane (docs/hand_eye.md, "The points")
    refinement = RefinementParams(corner_window_px=4, max_shift_px=4.0, symmetry_window_px=3,
                                  min_symmetry=SADDLE_SYMMETRY, depth_plane=True, anchor_window_px=8)
    return HandEyeParts(config, coordination, candidates, refinement,
                        CameraMotionConfig(enabled=config.camera_motion))


@dataclass
class HandEyeLoop:
    tracker: OpticalFlowTracker
    detector: MotionCoincidenceDetector
    candidates: CandidateIdentifiers
    state_machine: CoordinationStateMachine
    refiner: FeatureRefiner | None = None
    camera_motion: CameraMotionDetector | None = None
    identifying_motion: IdentifyingMotion | None = None
    # the payload loop watching the held tool (``slip_from_wrench``), added by the caller that has
    # the wrench and linked by ``connect_wrench_watch``
    wrench_watch: PayloadLoop | None = None

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

    def candidate_features(self):
        """The output port of the tracked features the candidates are fed (the refiner's, else the
        tracker's)."""
        return (self.refiner or self.tracker).GetOutputPort("tracked_features")

    def motion_confirm(self):
        """The output port the motion generator's confirming requests come from: the detector's
        ``confirm`` (paper §3.3), through the identifying motion when there is one."""
        if self.identifying_motion is not None:
            return self.identifying_motion.GetOutputPort("confirm")
        return self.detector.GetOutputPort("confirm")


def add_hand_eye_loop(builder, info, num_joints: int, fps: float, hand_eye: HandEyeConfig | HandEyeParts,
                      perception: BodyDetectionConfig, joint_ranges=None, motion_seed: int = 0, *,
                      kinematics: HandKinematics | None = None) -> HandEyeLoop:  # fmt: skip
    """Adds the tracker, detector, candidate identifiers and state machine, connected to each other.
    ``hand_eye`` is the user's ``HandEyeConfig`` or every setting (``HandEyeParts``).
    With ``hand_eye.camera_motion``, a ``CameraMotionDetector`` feeds the state machine's
    ``camera_motion``; with ``hand_eye.identifying_motion_interval`` > 0, an ``IdentifyingMotion``
    (far postures within ``joint_ranges``, n x [lower, upper] rad, drawn from ``motion_seed``)
    forwards the detector's confirming requests and adds its own while identifying; with
    ``kinematics`` (``systems.exciting_postures.HandKinematics``: the arm's plant, hand frame, joints
    and pace) it asks for the posture that adds the most to the statistic of the candidate wanting
    more motion (``HandEyePostures``; issue 25), else the farthest. Left for the
    caller: the images (``HandEyeLoop.image_inputs``: the tracker's, with
    ``hand_eye.refine_points`` the ``FeatureRefiner``'s, with ``free_space_radius`` the candidates'
    depth), the joint positions
    (``HandEyeLoop.actuator_inputs``), the candidates' ``X_WH``, and the uses of
    ``HandEyeLoop.motion_confirm()`` and ``state_machine.pause``. Raises ValueError on bad settings."""
    parts = hand_eye if isinstance(hand_eye, HandEyeParts) else hand_eye_parts(hand_eye)
    hand_eye = parts.config
    if hand_eye.identifying_motion_interval > 0:
        if joint_ranges is None:
            raise ValueError("the identifying motion needs joint_ranges (n x [lower, upper] rad, the "
                             "postures it may ask for) or a plant to take them from; or set "
                             "hand_eye.identifying_motion_interval = 0")  # fmt: skip
        if len(joint_ranges) != num_joints:
            raise ValueError(f"joint_ranges has {len(joint_ranges)} rows for num_joints = {num_joints}")
        if not (hand_eye.identifying_motion_reach >= 0 and np.isfinite(hand_eye.identifying_motion_reach)):
            raise ValueError("hand_eye.identifying_motion_reach must be >= 0 rad (0: off), got "
                             f"{hand_eye.identifying_motion_reach}")
    criteria, rule = parts.coordination.criteria(), parts.coordination.rule()
    # Copies with their values checked again: a user may set fields after construction.
    candidate_params = dataclasses.replace(parts.candidates)
    # The refiner's windows scaled to the camera (loops.pixel_scale).
    refinement = scaled(dataclasses.replace(parts.refinement), pixel_scale(info),
                        lengths=("max_shift_px",),
                        windows=("corner_window_px", "depth_window_px", "blob_window_px",
                                 "symmetry_window_px", "anchor_window_px"))
    body = add_body_detection(builder, info, num_joints, fps, perception)
    tracker, detector, period = body.tracker, body.detector, 1.0 / fps
    formulation = EyeToHandFormulation(criteria, parts.coordination.forgetting_factor)
    depth_check = info if candidate_params.free_space_radius > 0 else None
    candidates = builder.AddSystem(CandidateIdentifiers(formulation, candidate_params, period, depth_check))
    candidates.set_name("candidate_identifiers")
    machine = builder.AddSystem(CoordinationStateMachine(16, rule, period))
    machine.set_name("coordination_state_machine")
    features, refiner = tracker.GetOutputPort("tracked_features"), None
    if hand_eye.refine_points:  # drift-free points for the identifiers (the detector keeps the tracks)
        # its update between the tracker's (a quarter frame) and the candidates' (the next frame)
        refiner = builder.AddSystem(FeatureRefiner(info, refinement, hand_eye.depth_noise, period,
                                                   offset=0.5 * period))
        refiner.set_name("feature_refiner")
        builder.Connect(features, refiner.GetInputPort("tracked_features"))
        features = refiner.GetOutputPort("tracked_features")
    builder.Connect(features, candidates.GetInputPort("tracked_features"))
    connect_identify_observe(builder, candidates, machine)
    builder.Connect(machine.GetOutputPort("allowable_error"), candidates.GetInputPort("allowable_error"))
    camera = None
    if not parts.camera_motion.enabled:
        builder.Connect(detector.GetOutputPort("feature_on_body"), candidates.GetInputPort("feature_on_body"))
    else:  # the camera notices its own motion from the static scene
        camera = builder.AddSystem(CameraMotionDetector(
            num_joints, tracker.grid.num_cells, (info.width(), info.height()),
            parts.camera_motion.params(info.focal_x()), period=period, offset=0.75 * period,
            camera_info=info))  # fmt: skip
        camera.set_name("camera_motion_detector")
        builder.Connect(tracker.GetOutputPort("tracked_features"), camera.GetInputPort("tracked_features"))
        builder.Connect(tracker.GetOutputPort("gray_image"), camera.GetInputPort("gray_image"))
        for name in ("feature_on_body", "body_feature_cells"):
            builder.Connect(detector.GetOutputPort(name), camera.GetInputPort(name))
        builder.Connect(camera.GetOutputPort("camera_motion"), machine.GetInputPort("camera_motion"))
        # A move found after the observation's reset for it is that reset's change, not a second one.
        builder.Connect(camera.GetOutputPort("move_start"), machine.GetInputPort("camera_move_start"))
        # The identifiers' candidates without the static scene's features (stale body cells).
        builder.Connect(camera.GetOutputPort("feature_on_body"), candidates.GetInputPort("feature_on_body"))
        if candidate_params.keep_tool_points:  # a camera turn re-found from the scene and the tool points
            builder.Connect(camera.GetOutputPort("scene_turn"), candidates.GetInputPort("scene_turn"))
        # A scene still since before a reset: the camera did not move, only the tool point is new.
        builder.Connect(camera.GetOutputPort("scene_still_since"),
                        candidates.GetInputPort("scene_still_since"))
    motion = None
    if hand_eye.identifying_motion_interval > 0:  # far postures while identifying (richer motion)
        # The chooser keeps the point half a tracker window inside the image.
        postures = None if kinematics is None else HandEyePostures(
            kinematics, info, fps, margin_px=0.5 * tracker.params.lk_window_px)  # fmt: skip
        motion = builder.AddSystem(IdentifyingMotion(
            joint_ranges, hand_eye.identifying_motion_interval, seed=motion_seed, period=period,
            max_hold=hand_eye.identifying_motion_max_hold,
            more_motion_reach=hand_eye.identifying_motion_reach or None, postures=postures))  # fmt: skip
        motion.set_name("identifying_motion")
        if postures is not None:
            builder.Connect(candidates.GetOutputPort("motion_statistic"), motion.GetInputPort("statistic"))
        if perception.confirm:  # the detector's confirming requests first (body detection, §3.3)
            builder.Connect(detector.GetOutputPort("confirm"), motion.GetInputPort("detector_confirm"))
        builder.Connect(machine.GetOutputPort("mode"), motion.GetInputPort("mode"))
        # Points converged whose views do not pin the camera's rotation: far postures now.
        builder.Connect(candidates.GetOutputPort("more_motion"), motion.GetInputPort("more_motion"))
    return HandEyeLoop(tracker, detector, candidates, machine, refiner, camera, motion)


def wrench_watch_config() -> KinestheticConfig:
    """The payload loop that watches the held tool for ``slip_from_wrench``: the dynamic mode (every
    sample counts, moving or not: the babbling need not rest) with ``KinestheticConfig``'s defaults."""
    return KinestheticConfig(enabled=True, mode="dynamic")


def connect_wrench_watch(builder, machine: CoordinationStateMachine, payload: PayloadLoop) -> None:
    """``slip_from_wrench``: each change detection of the payload loop ``payload`` (its state
    machine's ``reset`` count) is reported to the hand-eye state machine ``machine``
    (``body_changes``: unless the camera's observation rule sees the change first, it is a slip, the
    camera kept and the tool point identified again). The payload loop's ``pause`` is left unused:
    the hand-eye loop pauses the arm."""
    builder.Connect(payload.state_machine.GetOutputPort("reset"), machine.GetInputPort("body_changes"))
