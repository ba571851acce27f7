"""The whole sustainable sensory-motor coordination as one Diagram for any controller and any arm:
``make_sustainable_coordination`` combines the loops chosen at construction (``Loops``: hand-eye,
payload, touch) behind documented ports."""

from __future__ import annotations

import numbers
from dataclasses import dataclass, fields

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.sensors import CameraConfig, CameraInfo, ImageDepth32F, ImageRgba8U

from sustain_drake.loops.body_detection import BodyDetectionConfig
from sustain_drake.loops.hand_eye import HandEyeConfig, add_hand_eye_loop, connect_wrench_watch
from sustain_drake.loops.inspection import add_inspection
from sustain_drake.loops.payload import KinestheticConfig, add_payload_loop
from sustain_drake.systems.coordination_outputs import AdoptedEstimates, InputsConnected, RequiredInput
from sustain_drake.systems.exciting_postures import HandKinematics
from sustain_drake.systems.hand_pose_from_plant import HandPoseFromPlant
from sustain_drake.systems.motion_generator import BABBLING_PACE
from sustain_drake.systems.sensor_kinematics import SensorKinematicsFromEncoders

__all__ = ["AdoptedEstimates", "Loops", "camera_intrinsics", "joint_ranges_from_limits",
           "make_sustainable_coordination"]

OWNER = "make_sustainable_coordination"
DEFAULT_FPS = 30.0  # frames per second of the camera when ``fps`` is not given


@dataclass(frozen=True)
class Loops:
    """Which loops a ``make_sustainable_coordination`` diagram runs. A loop that is off has no
    systems and no ports in the diagram (and its inputs need no sensor)."""

    hand_eye: bool = True  # the marker-free hand-eye loop: needs the depth camera's images
    payload: bool = True  # payload identification: needs the wrist wrench and the joint velocities
    touch: bool = False  # touch estimation on the held object (held_shape): needs the payload loop


# The diagram's inputs in port order, with what to connect when one is left unconnected.
_INPUTS = ("color_image", "depth_image", "image_time", "joint_positions", "joint_velocities", "X_WH",
           "wrench")
_ADVICE = {
    "color_image": "connect the camera's colour image (ImageRgba8U, e.g. RgbdSensor's color_image), or "
                   "build with loops=Loops(hand_eye=False)",
    "depth_image": "connect the camera's depth image (ImageDepth32F in m, e.g. RgbdSensor's "
                   "depth_image_32f), or build with loops=Loops(hand_eye=False)",
    "joint_positions": "connect the arm's {n} joint positions (rad, the encoders)",
    "joint_velocities": "connect the arm's {n} joint velocities (rad/s), or build with "
                        "loops=Loops(payload=False)",
    "X_WH": "connect the hand pose in the world (RigidTransform), or build with plant= and hand_frame=",
    "wrench": "connect the wrist force/torque sensor's [tau_K; f_K] (6, N m and N, in the sensor frame K), "
              "or build with loops=Loops(payload=False)",
}  # fmt: skip


@dataclass
class _Arguments:
    """``make_sustainable_coordination``'s arguments, checked (``_checked``) and defaulted."""

    camera_info: object
    num_joints: int
    loops: Loops
    fps: float | None
    hand_eye: HandEyeConfig | None
    body_detection: BodyDetectionConfig | None
    kinesthetic: KinestheticConfig | None
    plant: object
    hand_frame: object
    sensor_frame: object
    model_instance: object
    held_shape: object
    X_KG: RigidTransform | None
    joint_ranges: object
    motion_seed: int | None


# The arguments that belong to one loop: given while it is off, they are an error.
_LOOP_ARGUMENTS = {"hand_eye": ("camera_info", "fps", "hand_eye", "body_detection", "joint_ranges",
                                "motion_seed"),
                   "payload": ("kinesthetic", "sensor_frame"), "touch": ("held_shape", "X_KG")}
_TYPES = {"hand_eye": HandEyeConfig, "body_detection": BodyDetectionConfig, "kinesthetic": KinestheticConfig,
          "X_KG": RigidTransform}  # fmt: skip


def _checked(a: _Arguments) -> _Arguments:
    """``a`` with defaults filled in; a one-line TypeError or ValueError naming the argument for a
    wrong type, an option of a loop that is off, no loop on, or sizes that disagree."""
    if not isinstance(a.loops, Loops):
        raise TypeError(f"{OWNER}: loops must be a Loops, got {type(a.loops).__name__}")
    for name in (f.name for f in fields(Loops)):
        if not isinstance(getattr(a.loops, name), bool):
            raise TypeError(f"{OWNER}: loops.{name} must be a bool, got {getattr(a.loops, name)!r}")
    if not (a.loops.hand_eye or a.loops.payload):
        raise ValueError(f"{OWNER}: loops has no loop on: turn on loops.hand_eye or loops.payload")
    if a.loops.touch and not a.loops.payload:
        raise ValueError(f"{OWNER}: loops.touch needs loops.payload (the touch estimator reads the payload)")
    for loop, names in _LOOP_ARGUMENTS.items():
        given = [name for name in names if getattr(a, name) is not None]
        if given and not getattr(a.loops, loop):
            raise ValueError(f"{OWNER}: {given[0]} is an option of the {loop} loop, which is off "
                             f"(loops.{loop} = False)")  # fmt: skip
    for name, kind in _TYPES.items():
        value = getattr(a, name)
        if value is not None and not isinstance(value, kind):
            raise TypeError(f"{OWNER}: {name} must be a {kind.__name__}, got {type(value).__name__}")
    if isinstance(a.num_joints, bool) or not isinstance(a.num_joints, numbers.Integral) or a.num_joints < 1:
        raise ValueError(f"{OWNER}: num_joints must be a positive integer, got {a.num_joints!r}")
    if a.loops.touch and a.held_shape is None:
        raise ValueError(f"{OWNER}: loops.touch needs held_shape (the held object's pydrake.geometry shape)")
    if a.fps is not None and not (isinstance(a.fps, numbers.Real) and a.fps > 0):
        raise ValueError(f"{OWNER}: fps must be > 0 frames per second, got {a.fps!r}")
    if a.plant is not None and a.hand_frame is None:
        raise ValueError(f"{OWNER}: a plant needs its hand_frame")
    if a.loops.payload and a.kinesthetic is not None and a.kinesthetic.mode != "static" and a.plant is None:
        raise ValueError(f"{OWNER}: kinesthetic.mode {a.kinesthetic.mode!r} needs plant= and hand_frame= "
                         "(the sensor's kinematics come from the joint encoders through the arm's plant)")
    if a.plant is None and not (a.hand_frame is None and a.sensor_frame is None and a.model_instance is None):
        raise ValueError(f"{OWNER}: hand_frame, sensor_frame and model_instance need a plant")
    if a.plant is not None:
        instance = () if a.model_instance is None else (a.model_instance,)
        positions = a.plant.num_positions(*instance)
        if positions != a.num_joints:
            raise ValueError(f"{OWNER}: the plant has {positions} positions for num_joints = {a.num_joints}")
        if a.joint_ranges is None and a.loops.hand_eye:
            a.joint_ranges = joint_ranges_from_limits(a.plant, a.model_instance)
    if a.loops.hand_eye:
        a.camera_info = camera_intrinsics(a.camera_info)
    a.fps = DEFAULT_FPS if a.fps is None else float(a.fps)
    a.motion_seed = 0 if a.motion_seed is None else a.motion_seed
    a.hand_eye = a.hand_eye or HandEyeConfig()
    a.body_detection = a.body_detection or BodyDetectionConfig()
    a.kinesthetic = a.kinesthetic or KinestheticConfig()
    return a


# px: Drake's VTK renderer samples pixel (u, v) at (u + 0.5, v + 0.5) of the pinhole model its
# CameraInfo states (the OpenCV convention puts pixel centres at integers, the principal point of
# a centred W x H camera at ((W - 1) / 2, (H - 1) / 2)): the rendered image lies half a pixel up and
# left of it (RobotLocomotion/drake PR #10190, open). A depth edge shows it
# (tests/test_coordination_camera_info.py); at 640 x 480 it turns every back-projected ray by 0.05 deg.
VTK_RENDER_OFFSET_PX = 0.5


def rendered_intrinsics(info: CameraInfo) -> CameraInfo:
    """The intrinsics that describe the images Drake's VTK renderer makes for a camera of ``info``:
    the principal point moved by ``-VTK_RENDER_OFFSET_PX`` in u and v."""
    return CameraInfo(info.width(), info.height(), info.focal_x(), info.focal_y(),
                      info.center_x() - VTK_RENDER_OFFSET_PX, info.center_y() - VTK_RENDER_OFFSET_PX)


def camera_intrinsics(camera, argument: str = "camera_info") -> CameraInfo:
    """The intrinsics of ``camera``: a ``pydrake.systems.sensors.CameraInfo`` as it is (a real
    camera's calibration), or those of the images a simulated ``CameraConfig``'s colour camera
    renders (its width, height and focal lengths as ``CameraConfig.MakeCameras`` makes them, its
    principal point as the VTK renderer places it: ``rendered_intrinsics``; the config's ``fps`` is
    not read). Any other type raises a one-line ``TypeError`` naming ``argument``."""
    if isinstance(camera, CameraInfo):
        return camera
    if isinstance(camera, CameraConfig):
        color_camera, _ = camera.MakeCameras()
        return rendered_intrinsics(color_camera.core().intrinsics())
    raise TypeError(f"{argument} must be a pydrake.systems.sensors.CameraInfo or CameraConfig, got "
                    f"{type(camera).__name__}")


def make_sustainable_coordination(camera_info, num_joints: int, *, loops: Loops | None = None,
                                  fps: float | None = None, hand_eye: HandEyeConfig | None = None,
                                  body_detection: BodyDetectionConfig | None = None,
                                  kinesthetic: KinestheticConfig | None = None,
                                  plant=None, hand_frame=None, sensor_frame=None, model_instance=None,
                                  held_shape=None, X_KG: RigidTransform | None = None,
                                  joint_ranges=None, motion_seed: int | None = None,
                                  ) -> Diagram:  # fmt: skip
    """The sustainable coordination of an arm with ``num_joints`` joints, running the ``loops``
    chosen (``Loops``: by default hand-eye and payload; a loop that is off has no systems and no
    ports here). The hand-eye loop reads a depth camera with intrinsics ``camera_info`` (a
    ``pydrake.systems.sensors.CameraInfo``, or a ``CameraConfig`` whose intrinsics are taken,
    ``camera_intrinsics``; pass None with the hand-eye loop off) at ``fps`` frames per second (30 if
    None; not read from a ``CameraConfig``); the payload loop a wrist force/torque sensor. Settings
    are the scenario sections' dataclasses (defaults if None): ``hand_eye``, ``body_detection``,
    ``joint_ranges`` and ``motion_seed`` are the hand-eye loop's, ``kinesthetic`` and
    ``sensor_frame`` the payload loop's, ``held_shape`` and ``X_KG`` the touch loop's: one given
    for a loop that is off, a wrong type, or no loop on raises a one-line ``ValueError`` or
    ``TypeError`` naming the argument. With ``plant`` (a finalized MultibodyPlant of the arm) and
    ``hand_frame`` the hand pose (and the sensor pose, at ``sensor_frame``, else the hand's) is
    computed from the joint positions (``HandPoseFromPlant``); else it is the ``X_WH`` input and the
    sensor frame K is the hand frame H. ``loops.touch`` adds the touch estimator on ``held_shape``
    (the held object's ``pydrake.geometry`` shape at ``X_KG`` in K). ``joint_ranges`` (n x [lower,
    upper], rad) are the postures the identifying motion may ask for (needed with
    ``hand_eye.identifying_motion_interval`` > 0, the default; with a plant and no ranges, its
    position limits narrowed by ``RANGE_MARGIN``; its draws come from ``motion_seed``, 0 if None).

    .. pydrake_system::

        name: SustainableCoordination
        input_ports:
        - color_image (with hand_eye)
        - depth_image (with hand_eye)
        - image_time (optional, with hand_eye)
        - joint_positions (with hand_eye or plant)
        - joint_velocities (with payload)
        - X_WH (without plant)
        - wrench (with payload)
        output_ports:
        - X_WC (with hand_eye)
        - X_WC_valid (with hand_eye)
        - X_WC_sd (with hand_eye)
        - p_HP (with hand_eye)
        - p_HP_valid (with hand_eye)
        - p_HP_sd (with hand_eye)
        - followed_point (with hand_eye)
        - followed_point_valid (with hand_eye)
        - candidate_states (with hand_eye)
        - hand_eye_mode (with hand_eye)
        - hand_eye_events (with hand_eye)
        - hand_eye_allowable_error (with hand_eye)
        - hand_eye_reset_reason (with hand_eye)
        - camera_motion (with hand_eye.camera_motion)
        - payload_mass (with payload)
        - p_KCm (with payload)
        - payload_valid (with payload)
        - payload_sd (with payload)
        - payload_mode (with payload)
        - payload_events (with payload)
        - payload_reset_reason (with payload)
        - touch (with touch)
        - p_WP (with touch)
        - f_env_W (with touch)
        - motion_confirm (with hand_eye)
        - hand_eye_pause (with hand_eye)
        - payload_pause (with payload)
        - X_WH_used
        - X_WK_used

    Inputs: ``color_image`` (ImageRgba8U), ``depth_image`` (ImageDepth32F, m), ``image_time`` (1, s,
    the capture time; unconnected: every frame is new), ``joint_positions`` and
    ``joint_velocities`` (``num_joints``, rad and rad/s; velocities gate the quasi-static wrench
    samples), ``X_WH`` (RigidTransform), ``wrench`` (6, ``[tau_K; f_K]`` applied by the wrist on the
    outboard side, N m and N, in K; see ``identification.payload``). With ``kinesthetic.mode``
    ``dynamic`` (it needs ``plant``) the payload loop identifies the rotational inertia and the
    sensor's bias too, from every sample, the sensor's kinematics computed from ``joint_positions``
    (``SensorKinematicsFromEncoders``: read with the wrench, every ``kinesthetic.period``). Every input but
    ``image_time`` is required: one left unconnected stops the simulation's initialization with a
    one-line ``RuntimeError`` naming the port and what to connect (``InputsConnected``).

    Outputs (``AdoptedEstimates``, ``FollowedPoint``): the estimates ``X_WC`` (RigidTransform, the
    camera in the world), ``p_HP`` (3, m, the tool point in the hand frame), ``payload_mass`` (1,
    kg), ``p_KCm`` (3, m, the payload's centre of mass in K), each beside its validity flag
    (``X_WC_valid``, ``p_HP_valid``, ``payload_valid``: 1 when the estimate is one to use; at 0 the
    value means nothing: the identity, zeros or a stale estimate, never NaN) and its 1-sd
    uncertainty (``X_WC_sd``: 6, the camera's rotation about its x, y, z axes in rad, then its
    position in m; ``p_HP_sd``: 3, m; ``payload_sd``: 4, kg then m; ``inf`` when not known);
    ``followed_point`` (9, ``[feature_id, u, v, p_CP, p_HP]``: the tracked feature observed under
    the adopted model, its pixel in px, its point in the camera frame and in the hand frame in m)
    with ``followed_point_valid`` (1); ``candidate_states`` (``3 * hand_eye.max_candidates``:
    per candidate ``[feature_id, num_samples, state]``, state 0 identifying, 1 converged, 2 leader,
    -1 an empty slot); ``hand_eye_mode`` and ``payload_mode`` (1: 0 identify, 1 observe);
    ``*_events`` (the state machines' event lists); ``*_reset_reason`` (1: why the loop last
    identified again: 0 never, 1 an observation failed (the body changed: the tool slipped, the
    payload changed), 2 the camera moved; ``coordination.RESET_REASON_NAMES``);
    ``hand_eye_allowable_error`` (1, m^2); ``camera_motion`` (2, ``[moving, moves]``: the camera
    noticed its own motion from the static scene, ``CameraMotionDetector``; each new move is a
    hand-eye change detection); the touch estimator's ``touch``, ``p_WP``, ``f_env_W``; for the
    user's motion generator ``motion_confirm``, ``hand_eye_pause`` and ``payload_pause`` (below);
    ``X_WH_used`` and ``X_WK_used`` (the hand and sensor poses the loops use).

    Which estimates mean something when: ``X_WC_valid`` is 1 from the first hand-eye convergence (a
    ``converged`` event, ``hand_eye_mode`` 1) on; a camera move (a ``change_detected`` event "the
    camera moved", ``hand_eye_reset_reason`` 2) drops the camera until the next convergence; a failed
    observation (a ``change_detected`` event "... samples over the limit": the tool slipped,
    ``hand_eye_reset_reason`` 1) keeps it. ``p_HP_valid`` and ``payload_valid`` are 1 while their
    loop observes an adopted estimate (its mode 1). ``hand_eye_allowable_error`` is 0 until the first
    convergence, then the last adoption's. With both loops and ``hand_eye.slip_from_wrench`` (the
    default), each payload change detection is a hand-eye change detection too, unless the hand-eye
    observation detects it first (a slip: a ``change_detected`` event "the held body changed
    (another sensor)", ``hand_eye_reset_reason`` 1, the camera kept), so a slip is found while the
    camera sees no point on the tool.

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
    a = _checked(_Arguments(camera_info, num_joints, Loops() if loops is None else loops, fps, hand_eye,
                            body_detection, kinesthetic, plant, hand_frame, sensor_frame, model_instance,
                            held_shape, X_KG, joint_ranges, motion_seed))  # fmt: skip
    builder = DiagramBuilder()
    inputs = {name: [] for name in _INPUTS}
    check = builder.AddSystem(InputsConnected(OWNER, _required_inputs(a)))
    check.set_name("inputs_connected")
    for i in range(check.num_input_ports()):
        inputs[check.get_input_port(i).get_name()].append(check.get_input_port(i))
    vision = payload = None
    if a.loops.hand_eye:
        try:
            vision = add_hand_eye_loop(builder, a.camera_info, a.num_joints, a.fps, a.hand_eye,
                                       a.body_detection, a.joint_ranges, a.motion_seed,
                                       kinematics=_hand_kinematics(a))  # fmt: skip
        except ValueError as e:
            raise ValueError(f"{OWNER}: {e}") from None
        for name in ("color_image", "depth_image", "image_time"):
            inputs[name] += vision.image_inputs(name)
        inputs["joint_positions"] += vision.actuator_inputs()
    if a.loops.payload:
        shape = a.held_shape if a.loops.touch else None
        payload = add_payload_loop(builder, a.num_joints, a.kinesthetic, shape, a.X_KG)
        inputs["joint_velocities"].append(payload.gate.GetInputPort("joint_velocities"))
    X_WH, X_WK, X_WL = _hand_poses(builder, a, inputs)
    if vision is not None:
        builder.Connect(X_WH, vision.candidates.GetInputPort("X_WH"))
        if X_WL is not None:  # the hand's parent link: points fixed on it are told from the hand's
            builder.Connect(X_WL, vision.candidates.GetInputPort("X_WL"))
    if payload is not None:
        _connect_payload(builder, a, payload, X_WK, inputs)
        if vision is not None and a.hand_eye.slip_from_wrench:  # the wrench's change is a slip
            connect_wrench_watch(builder, vision.state_machine, payload)
    for name, ports in inputs.items():
        _export_input(builder, name, ports)
    _export_outputs(builder, vision, payload)
    builder.ExportOutput(X_WH, "X_WH_used")
    builder.ExportOutput(X_WK, "X_WK_used")
    diagram = builder.Build()
    diagram.set_name("sustainable_coordination")
    return diagram


def _required_inputs(a: _Arguments) -> tuple[RequiredInput, ...]:
    """The inputs the diagram of ``a`` needs connected (every one but ``image_time``)."""
    models = {"color_image": AbstractValue.Make(ImageRgba8U()),
              "depth_image": AbstractValue.Make(ImageDepth32F()),
              "joint_positions": a.num_joints, "joint_velocities": a.num_joints,
              "X_WH": AbstractValue.Make(RigidTransform()), "wrench": 6}  # fmt: skip
    needed = {"color_image": a.loops.hand_eye, "depth_image": a.loops.hand_eye,
              "joint_positions": a.loops.hand_eye or a.plant is not None,
              "joint_velocities": a.loops.payload, "X_WH": a.plant is None, "wrench": a.loops.payload}
    return tuple(RequiredInput(name, models[name], _ADVICE[name].format(n=a.num_joints))
                 for name in _INPUTS if needed.get(name, False))


def _hand_poses(builder, a: _Arguments, inputs: dict) -> tuple:
    """The output ports of the hand and sensor poses and of the hand's parent link: the plant's
    forward kinematics of the joint positions, or the ``X_WH`` input for both (the parent link then
    not known: None)."""
    if a.plant is not None:
        fk = builder.AddSystem(HandPoseFromPlant(a.plant, a.hand_frame, a.sensor_frame, a.model_instance))
        fk.set_name("hand_pose_from_plant")
        inputs["joint_positions"].append(fk.get_input_port())
        return fk.GetOutputPort("X_WH"), fk.GetOutputPort("X_WK"), fk.GetOutputPort("X_WL")
    passthrough = builder.AddSystem(_PosePassThrough())
    inputs["X_WH"].append(passthrough.get_input_port())
    return passthrough.get_output_port(), passthrough.get_output_port(), None


def _connect_payload(builder, a: _Arguments, payload, X_WK, inputs: dict) -> None:
    """The payload loop's sensor inputs: the wrench and the sensor pose (static mode), or the wrench
    and the sensor's kinematics from the joint encoders through the plant (dynamic mode:
    ``SensorKinematicsFromEncoders``, the wrench delayed with them)."""
    if payload.estimator is not None:
        inputs["wrench"].append(payload.estimator.GetInputPort("wrench"))
        builder.Connect(X_WK, payload.estimator.GetInputPort("X_WK"))
    if a.kinesthetic.mode == "static":
        inputs["wrench"].append(payload.identifier.GetInputPort("wrench"))
        builder.Connect(X_WK, payload.identifier.GetInputPort("X_WK"))
        return
    d = a.kinesthetic.dynamic
    joints = None if a.model_instance is None else _arm_joints(a)
    encoders = builder.AddSystem(SensorKinematicsFromEncoders(
        a.plant, a.sensor_frame or a.hand_frame, a.kinesthetic.period, d.encoder_window, d.encoder_order,
        joints, d.wrench_delay))  # fmt: skip
    encoders.set_name("sensor_kinematics_from_encoders")
    inputs["joint_positions"].append(encoders.GetInputPort("joint_positions"))
    inputs["wrench"].append(encoders.GetInputPort("wrench"))
    for name, target in (("wrench_aligned", "wrench"), ("kinematics_K", "kinematics_K")):
        builder.Connect(encoders.GetOutputPort(name), payload.identifier.GetInputPort(target))


def _arm_joints(a: _Arguments) -> list:
    """The joints with positions of ``a.model_instance`` (every joint of ``a.plant`` if None), in the
    order of their positions: those of the ``joint_positions`` input."""
    indices = a.plant.GetJointIndices(*(() if a.model_instance is None else (a.model_instance,)))
    joints = (a.plant.get_joint(j) for j in indices)
    return sorted((j for j in joints if j.num_positions() > 0), key=lambda j: j.position_start())


def _hand_kinematics(a: _Arguments) -> HandKinematics | None:
    """With ``hand_eye.excite`` and a plant: the arm's kinematics for the identifying motion's choice,
    its moves timed at the scenarios' babbling pace (``BABBLING_PACE``: your motion generator's moves
    may differ; a shortest move's candidates are all ranked alike by it)."""
    if a.plant is None or not a.hand_eye.excite:
        return None
    return HandKinematics(a.plant, a.hand_frame, _arm_joints(a), BABBLING_PACE)


def _export_input(builder, name: str, ports: list) -> None:
    """Exports ``ports`` (all that take it) as the diagram's input ``name``; none: no such input."""
    if ports:
        first, *others = ports
        builder.ExportInput(first, name)
        for port in others:
            builder.ConnectInput(name, port)


def _export_outputs(builder, vision, payload) -> None:
    """The loops' outputs (see ``make_sustainable_coordination``), in the documented order."""
    inspection = add_inspection(builder, vision, payload)
    adopted, followed = inspection.adopted, inspection.followed
    if vision is not None:
        machine = vision.state_machine
        for name in ("X_WC", "X_WC_valid", "X_WC_sd", "p_HP", "p_HP_valid", "p_HP_sd"):
            builder.ExportOutput(adopted.GetOutputPort(name), name)
        for name in ("followed_point", "followed_point_valid", "candidate_states"):
            builder.ExportOutput(followed.GetOutputPort(name), name)
        for name in ("mode", "events", "allowable_error", "reset_reason"):
            builder.ExportOutput(machine.GetOutputPort(name), f"hand_eye_{name}")
        if vision.camera_motion is not None:
            builder.ExportOutput(vision.camera_motion.GetOutputPort("camera_motion"), "camera_motion")
    if payload is not None:
        for name in ("payload_mass", "p_KCm", "payload_valid", "payload_sd"):
            builder.ExportOutput(adopted.GetOutputPort(name), name)
        for name in ("mode", "events", "reset_reason"):
            builder.ExportOutput(payload.state_machine.GetOutputPort(name), f"payload_{name}")
        if payload.estimator is not None:
            for name in ("touch", "p_WP", "f_env_W"):
                builder.ExportOutput(payload.estimator.GetOutputPort(name), name)
    if vision is not None:
        builder.ExportOutput(vision.motion_confirm(), "motion_confirm")
        builder.ExportOutput(vision.state_machine.GetOutputPort("pause"), "hand_eye_pause")
    if payload is not None:
        builder.ExportOutput(payload.state_machine.GetOutputPort("pause"), "payload_pause")


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
