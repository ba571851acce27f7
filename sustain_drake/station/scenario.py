"""Scenario files: dataclasses loaded from YAML with Drake's ``yaml_load_typed``.

A scenario says everything about one simulated experiment (paper section 4): the plant, the
RGB-D camera on the pan-tilt head, the held tool, the motion generator, the sensors' noise, the
walking distractor and a timeline of disturbances. Every field has a default, so a scenario
file only lists what differs. Units are SI (m, s, rad, kg, N, N m). ``validate_scenario`` checks a
scenario before anything is built: every number finite and in its range (``RANGES``, by section
and key), fixed poses (``POSES``), Drake's strings, the sections' consistency; every problem (and
an unknown or duplicate key, a value of the wrong type) is a one-line ``ScenarioError`` naming the
key.
"""


import dataclasses
import math
import re
from dataclasses import field

from pydrake.common.schema import Transform
from pydrake.common.yaml import yaml_dump_typed
from pydrake.geometry import LightParameter
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.systems.sensors import CameraConfig

from sustain_drake.loops.body_detection import BodyDetectionConfig
from sustain_drake.loops.hand_eye import HandEyeConfig
from sustain_drake.loops.payload import KinestheticConfig
from sustain_drake.station.models import ARMS, TOOL_FILES, ArmModel
from sustain_drake.station.random_disturbances import HEAD_MOVE, SLIP, RandomDisturbances, draw

# The first arm's joints (models/arm.sdf); a scenario's own arm: ``arm_of(scenario).joints``.
ARM_JOINTS = ARMS["arm"].joints
HEAD_JOINTS = ("head_pan", "head_tilt")
TOOL_MODELS = (*TOOL_FILES, "none")


class ScenarioError(ValueError):
    """A scenario file or value that cannot be used; the message is one line for the user."""


def _default_plant_config() -> MultibodyPlantConfig:
    # 2 ms steps: PD actuators are implicit in the discrete (SAP) solver, so this is stable,
    # and it keeps the simulation well ahead of real time.
    return MultibodyPlantConfig(time_step=0.002, discrete_contact_approximation="lagged")


def _default_camera() -> CameraConfig:
    camera = CameraConfig()
    camera.name = "head_camera"
    camera.fps = 30.0
    camera.rgb = True
    camera.depth = True
    camera.label = True
    camera.renderer_name = "vtk"
    camera.z_near = 0.1
    camera.z_far = 5.0
    camera.X_PB = Transform()
    camera.X_PB.base_frame = "head::camera_mount"
    return camera


@dataclasses.dataclass
class ArmConfig:
    """The robot arm on the table's pedestal (``station.models.ARMS``), holding the tool in the same
    gripper whichever it is."""

    # the arm: "arm" (5 joints, models/arm.sdf) or "ur_arm" (6 joints, UR5e-like, models/ur_arm.sdf)
    model: str = "arm"


@dataclasses.dataclass
class HeadConfig:
    """The pan-tilt head: where its post stands and its initial joint angles."""

    # pose of the post's foot in the world (+x forward): 1.4 m in front of the arm, looking back at it
    X_WP: Transform = field(default_factory=lambda: Transform(
        RigidTransform(RollPitchYaw(0.0, 0.0, math.pi), [1.4, 0.0, 0.0])))
    pan: float = 0.0  # rad: initial pan angle, within +-pi
    tilt: float = 0.1  # rad: initial tilt angle, within +-pi (positive looks down, towards the arm)


@dataclasses.dataclass
class ToolConfig:
    """Which tool is held and its pose in the gripper's grasp frame G."""

    # the held tool: "rod" (0.3 m, 0.1 kg, a black bar with a yellow checker), "box" (0.6 kg),
    # "wood_handle" (0.28 m, 0.49 kg: wood grain, two stickers, scratches), "metal_bar" (0.32 m,
    # 0.33 kg: red paint with slight wear, one logo), "speckle_bar" (0.3 m, 0.24 kg: a fine random
    # speckle), "plain_bar" (0.3 m, 0.46 kg: one colour, only edges and ends show), "charuco_board"
    # (0.26 kg: a 5 x 7 ChArUco board of 30 mm squares on a 45-degree bracket, the marker-based
    # baseline's target; its tracked point is a corner near its centre) or "none"; the bars and the
    # board's handle are the rod's 50 mm square at the grip, the bars' tip the tracked point as the rod's
    model: str = "rod"
    # pose of the tool frame T in the grasp frame G (between the fingers, z along the approach)
    X_GT: Transform = field(default_factory=Transform)
    slide: float = 0.0  # m: initial slip along G's z (see ToolSlip), within +-0.15 m (half the rod)
    pivot: float = 0.0  # rad: initial slip about G's x (see ToolSlip), within +-pi/2
    gripper_position: float = 0.0225  # m: the finger's closed position on this tool (0: open)


@dataclasses.dataclass
class MotionConfig:
    """The babbling motion generator (smooth random joint-space moves within ranges)."""

    seed: int = 0  # seed of the random moves (any integer >= 0)
    # rad: [lower, upper] per arm joint, clipped to the model's joint limits; left at this default
    # (the 5-joint arm's), another arm babbles within its own (station.models.ARMS)
    joint_ranges: list[list[float]] = field(default_factory=lambda: [
        list(r) for r in ARMS["arm"].joint_ranges])
    # rad: the arm's joint angles at the start; left at this default (the 5-joint arm's), another arm
    # starts at its own (station.models.ARMS)
    initial_posture: list[float] = field(default_factory=lambda: list(ARMS["arm"].initial_posture))
    max_speed: float = 0.6  # rad/s: peak joint speed of a move (the pace)
    min_duration: float = 1.0  # s: the shortest move
    dwell: float = 0.0  # s of rest after each move (quasi-static identification)
    confirm_hold: float = 0.5  # s of rest at a confirm posture before moving again
    # rad per joint: a quick confirming trial in place (MotionGenerator) moves again by this step;
    # 0: go back to the posture, then a usual move
    confirm_step: float = 0.0
    # rad: a confirm request within this of the current posture is answered in place; 0: never
    confirm_near: float = 0.0
    period: float = 0.01  # s between the generator's updates
    # add the gravity torques of the arm's own links (not the held tool's, which the robot does
    # not know) to the joints' PD, as a real arm controller does; off, the arm sags ~0.4 deg
    gravity_compensation: bool = False


@dataclasses.dataclass
class WrenchSensorConfig:
    """The wrist force/torque sensor; noise like an ATI Mini40."""

    rate: float = 100.0  # Hz: sample rate of the reading (at most 10 kHz)
    force_noise: float = 0.02  # N: standard deviation per axis
    torque_noise: float = 0.0005  # N m: standard deviation per axis
    # N m, N: constant offset added to the reading, [tau_x, tau_y, tau_z, f_x, f_y, f_z]
    bias: list[float] = field(default_factory=lambda: [0.0] * 6)
    seed: int = 1  # seed of the sensor noise (any integer >= 0)
    # subtract the gripper's own static weight (as after an F/T tool calibration), so the reading
    # at rest is the held object's weight alone; off: the raw weld reaction
    compensate_gripper: bool = False


@dataclasses.dataclass
class DepthNoiseConfig:
    """Depth noise that grows with range, sigma(z) = a + b (z - z0)^2, as measured for
    structured-light RGB-D sensors (Nguyen et al. 2012)."""

    enabled: bool = True  # add the noise; false: exact depth
    a: float = 0.0012  # m: sigma at z0 (Nguyen et al.: 1.2 mm)
    b: float = 0.0019  # 1/m: growth of sigma with (z - z0)^2 (Nguyen et al.: 1.9 mm/m^2)
    z0: float = 0.4  # m: range of the least noise (Nguyen et al.: 0.4 m)
    seed: int = 2  # seed of the depth noise (any integer >= 0)


@dataclasses.dataclass
class DistractorConfig:
    """The walking person: a scripted path of floor waypoints walked at constant speed."""

    enabled: bool = True  # add the walking person
    # m: [x, y] floor waypoints in the world frame (not all the same); the default path crosses behind
    # the arm
    waypoints: list[list[float]] = field(default_factory=lambda: [[-1.0, -2.5], [-1.0, 2.5]])
    speed: float = 1.0  # m/s: walking speed
    start_time: float = 2.0  # s the person waits at the first waypoint before walking
    loop: bool = True  # walk back and forth along the path forever


@dataclasses.dataclass
class BackdropConfig:
    """Posters on the back wall (``models/backdrop.sdf``): a static scene with corners of its own,
    as a lab wall has (the default room's wall, floor and table show only a few)."""

    # add the posters: a camera that turns sees them move together (the hand-eye scenarios use it)
    enabled: bool = False


@dataclasses.dataclass
class ToolSlip:
    """The tool slips in the gripper to a new slip state, measured from its configured pose X_GT."""

    time: float = 0.0  # s: when the slip starts
    slide: float = 0.0  # m: new slide along the grasp frame's z, within +-0.15 m
    pivot: float = 0.0  # rad: new pivot about the grasp frame's x (the finger closing axis), within +-pi/2
    duration: float = 0.1  # s the slip takes


@dataclasses.dataclass
class HeadMove:
    """The head turns to new pan/tilt angles."""

    time: float = 0.0  # s: when the turn starts
    pan: float = 0.0  # rad: new pan angle, within +-pi
    tilt: float = 0.1  # rad: new tilt angle, within +-pi
    duration: float = 0.5  # s the turn takes


@dataclasses.dataclass
class Touch:
    """A force pushes the held tool at one point for a while, like a finger touching it."""

    time: float = 0.0  # s: when the touch starts
    duration: float = 1.0  # s the touch lasts
    # m: the pushed point in the tool frame T
    p_TQ: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    # N: the force in the tool frame T, so it keeps pushing on the same face while the arm moves
    f_T: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])


Disturbance = ToolSlip | HeadMove | Touch


@dataclasses.dataclass
class TouchTarget:
    """A real touch of the table with the held tool: a point of the tool goes down on the table top,
    the tool turned so that a chosen direction of it points straight down."""

    # m: the touching point in the tool frame T (e.g. a corner or a face centre)
    p_TQ: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.12])
    # tool-frame direction turned straight down (any length): a face's outward normal to touch flat
    # with that face, a corner's diagonal to touch with the corner
    down_T: list[float] = field(default_factory=lambda: [0.0, 0.0, 1.0])
    # m: [x, y] in the world where the point goes down on the table top
    p_WQ: list[float] = field(default_factory=lambda: [0.3, 0.0])


@dataclasses.dataclass
class TouchMotionConfig:
    """Touching the table after the identification (paper §4.4), with the "keep touching" rule.

    When enabled, the station has the inputs ``touch_start`` (start the touches when > 0.5,
    e.g. the coordination mode OBSERVE) and ``touch_feedback`` (a touch estimator's flag), and
    the output ``touch_phase`` (see ``TouchMotion``). Each target's postures are solved by
    inverse kinematics when the station is built.
    """

    enabled: bool = False  # add the touch motion and its station ports
    # the touches, in order; their postures are solved by inverse kinematics
    targets: list[TouchTarget] = field(default_factory=list)
    approach_height: float = 0.03  # m above the table where the descent starts
    retreat_height: float = 0.12  # m above the table for the moves between touches
    press_depth: float = 0.02  # m below the table top where the descent would end
    descend_speed: float = 0.01  # m/s of the touching point (nearly quasi-static)
    press_extra: float = 0.004  # m pressed on beyond where the touch is felt
    keep_touching: float = 2.0  # s the touch is kept once felt
    # s after touch_start rises before the first touch (the pause after identification)
    start_delay: float = 3.0
    rest: float = 0.5  # s of rest above each target before approaching (observation samples)
    max_speed: float = 0.5  # rad/s: peak joint speed of the moves between touches
    repeat: bool = True  # start again with the first target after the last


@dataclasses.dataclass
class Scenario:
    """One simulated experiment: the world, its sensors, its disturbances and the experiments run on
    it (``sustain_drake.experiments``)."""

    duration: float = 10.0  # s: default length of a simulate run
    # the plant: 2 ms discrete (SAP) steps, stable with implicit PD actuators (time_step from 10 us to 10 ms)
    plant_config: MultibodyPlantConfig = field(default_factory=_default_plant_config)
    arm: ArmConfig = field(default_factory=ArmConfig)  # the robot arm: "arm" (5 joints) or "ur_arm" (6)
    # the head's RGB-D camera: 30 fps, color, depth and label images, 0.1-5 m depth range (at most
    # 4096 px a side and 240 fps)
    camera: CameraConfig = field(default_factory=_default_camera)
    head: HeadConfig = field(default_factory=HeadConfig)  # the pan-tilt head carrying the camera
    tool: ToolConfig = field(default_factory=ToolConfig)  # the held tool and its grasp
    motion: MotionConfig = field(default_factory=MotionConfig)  # the babbling motion generator
    # the wrist force/torque sensor
    wrench_sensor: WrenchSensorConfig = field(default_factory=WrenchSensorConfig)
    depth_noise: DepthNoiseConfig = field(default_factory=DepthNoiseConfig)  # the depth image's noise
    distractor: DistractorConfig = field(default_factory=DistractorConfig)  # the walking person
    backdrop: BackdropConfig = field(default_factory=BackdropConfig)  # the posters on the back wall
    # the camera's lights, each a Drake LightParameter (type point, spot or directional; frame world
    # or camera; position, direction, intensity, color, attenuation_values, cone_angle); empty: the
    # room's two (a ceiling light of intensity 0.8 and one of 0.5 at the camera, build.ROOM_LIGHTS).
    # A second set-up, one dimmer light from the arm's side (+y, above, from the camera's side of the
    # arm), under half the room's: [{type: directional, frame: world, direction: [-0.5, -1.0, -0.5],
    # intensity: 0.6}]
    lights: list[LightParameter] = field(default_factory=list)
    # timeline of tool slips, head moves and touches
    disturbances: list[ToolSlip | HeadMove | Touch] = field(default_factory=list)
    # tool slips and camera moves drawn from a seed, played beside ``disturbances`` (off by default;
    # ``station.scenario.timeline`` merges them)
    random_disturbances: RandomDisturbances = field(default_factory=RandomDisturbances)
    # touching the table after the identification
    touch_motion: TouchMotionConfig = field(default_factory=TouchMotionConfig)
    # the body-detection experiment on this world (off by default)
    body_detection: BodyDetectionConfig = field(default_factory=BodyDetectionConfig)
    # the hand-eye experiment on this world (off by default)
    hand_eye: HandEyeConfig = field(default_factory=HandEyeConfig)
    # the payload and touch experiment on this world (off by default)
    kinesthetic: KinestheticConfig = field(default_factory=KinestheticConfig)


def timeline(scenario: Scenario) -> list[ToolSlip | HeadMove | Touch]:
    """The run's disturbances, in time order: the scenario's ``disturbances`` and the ones
    ``random_disturbances`` draws (``station.random_disturbances.draw``) from the configured head
    angles and grasp, over the scenario's ``duration``. What the station plays and the metrics score."""
    r = scenario.random_disturbances
    drawn = draw(r, scenario.duration, (scenario.head.pan, scenario.head.tilt),
                 (scenario.tool.slide, scenario.tool.pivot))
    kinds = {HEAD_MOVE: HeadMove, SLIP: ToolSlip}
    events = list(scenario.disturbances) + [kinds[d.kind](d.time, *d.state, d.duration) for d in drawn]
    return sorted(events, key=lambda e: e.time)


def scenario_text(scenario: Scenario) -> str:
    """The scenario as YAML, every key written out (what a run actually used: the arm's own motion
    defaults filled in, see ``arm_motion``)."""
    return yaml_dump_typed(dataclasses.replace(scenario, motion=arm_motion(scenario)))


def arm_of(scenario: Scenario) -> ArmModel:
    """The scenario's arm (``arm.model``) in ``station.models.ARMS``."""
    try:
        return ARMS[scenario.arm.model]
    except (KeyError, TypeError):
        raise ScenarioError(f"arm.model must be one of {', '.join(ARMS)}, "
                            f"got {scenario.arm.model!r}") from None


def arm_motion(scenario: Scenario) -> MotionConfig:
    """The motion section the arm babbles with: ``joint_ranges`` and ``initial_posture`` left at their
    defaults (the 5-joint arm's) take the scenario's arm's own (``ArmModel``); the section itself for
    the 5-joint arm or where both are set."""
    arm, first, motion = arm_of(scenario), ARMS["arm"], scenario.motion
    if arm is first:
        return motion
    changes = {}
    if motion.joint_ranges == [list(r) for r in first.joint_ranges]:
        changes["joint_ranges"] = [list(r) for r in arm.joint_ranges]
    if motion.initial_posture == list(first.initial_posture):
        changes["initial_posture"] = list(arm.initial_posture)
    return dataclasses.replace(motion, **changes) if changes else motion


def one_line(error: Exception) -> str:
    """A yaml_load_typed or Drake error as one line a user acts on (unknown keys and tags named)."""
    message = " ".join(str(error).split())
    # yaml_load_typed says "The fields ['fooo'] were unknown to the schema".
    unknown = re.search(r"The fields \[(.*?)\] were unknown", message)
    if unknown:
        return f"unknown key(s) {unknown.group(1)} (misspelled?)"
    tag = re.search(r"type tag value '(.*?)' did not match any of the allowed type options "
                    r"for '(.*?)' \((.*)\)", message)
    if tag:
        allowed = ", ".join("!" + n for n in re.findall(r"\.(\w+)'>", tag.group(3)))
        return f"unknown tag !{tag.group(1)} (expected one of {allowed})"
    if "incompatible function arguments" in message or "incompatible constructor" in message:
        return "a value has the wrong type or length (e.g. a translation needs 3 numbers)"
    return message if len(message) <= 300 else message[:297] + "..."


