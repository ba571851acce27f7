"""On your robot: the sustainable coordination wired to an arm of one's own, with its default
settings, hand-eye only (docs/on_your_robot.md shows this file and what to look at).

The arm stands in for yours: the project's second arm (``models/ur_arm.sdf``: six joints, UR5e-like,
a parallel gripper) holding the checker rod, a fixed RGB-D camera beside it (where
``diagrams/second_arm.yaml`` puts the head camera: 1.5 m from the arm's base, 45 deg around from its
front). The arm is a kinematic stand-in: it is where the babbling commands it (a real
position-controlled arm lags its command a little; its encoders then give ``joint_positions``).
Everything is public API: a ``MultibodyPlant`` of the arm, Drake's ``RgbdSensor``, the
``MotionGenerator`` babbling (``sustain_drake.systems.motion_generator``) answering the
coordination's pause and confirm requests, and ``make_sustainable_coordination(camera, 6,
loops=Loops(payload=False), plant=plant, hand_frame=hand)``: the hand-eye loop only (no wrist
force/torque sensor, so no ``wrench`` input).

    .venv/bin/python -m sustain_drake.examples.on_your_robot [--duration 90] [--seed 0]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import LightParameter, MakeRenderEngineVtk, RenderEngineVtkParams, SceneGraph
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Diagram, DiagramBuilder, EventStatus
from pydrake.systems.primitives import Demultiplexer, SharedPointerSystem
from pydrake.systems.rendering import MultibodyPositionToGeometryPose
from pydrake.systems.sensors import CameraConfig, RgbdSensor

from sustain_drake.identification.rotation import rotation_angle
from sustain_drake.loops import Loops, make_sustainable_coordination
from sustain_drake.station import models_dir
from sustain_drake.systems.camera_sampler import RgbdCameraSampler
from sustain_drake.systems.depth_noise import DepthNoiseModel
from sustain_drake.systems.motion_generator import MotionGenerator

# The arm's base on a 0.25 m pedestal at the world origin (the table top is z = 0).
X_W_BASE = RigidTransform([0.0, 0.0, 0.25])
# The finger's position (m) when the gripper is closed on the rod.
GRIPPER_CLOSED = 0.0225
# The camera's pose: 1.5 m from the arm's base at 45 deg around from its front, 0.57 m above the
# table, tilted down 0.1 rad and turned towards where the hand works (Drake's camera frame: z out of
# the lens, x right, y down). In a real cell this is what the calibration finds.
X_WC = RigidTransform(RollPitchYaw(-math.pi / 2 - 0.1, 0.0, math.radians(147.0)), [1.0437, 1.0350, 0.5670])
# rad: where the babbling may take each joint (lower, upper): the hand 0.5-0.7 m out towards the
# camera, the gripper pointing down, the whole rod in the image; and where the arm starts.
JOINT_RANGES = [(0.1, 0.6), (0.2, 0.55), (1.35, 1.8), (0.95, 1.55), (-0.35, 0.35), (-1.2, 1.2)]
START = [0.4, 0.35, 1.6, 1.2, 0.0, 0.0]
# The rod's tip in the hand frame H (the gripper body): the grasp frame 0.09 m out, the tip 0.25 m
# beyond it. The loop may follow any point fixed on the hand; this one is for reference.
P_H_ROD_TIP = np.array([0.0, 0.0, 0.34])


def camera_config() -> CameraConfig:
    """The RGB-D camera: 640 x 480 at 30 fps, 45 deg vertical field of view, depth 0.1-5 m."""
    return CameraConfig(width=640, height=480, fps=30.0, rgb=True, depth=True, name="camera",
                        renderer_name="vtk")


@dataclass
class OnYourRobot:
    """The built diagram and the parts of it a user reads."""

    diagram: Diagram
    coordination: Diagram  # make_sustainable_coordination's diagram
    motion: MotionGenerator
    plant: MultibodyPlant  # the arm (kinematics), holding the rod
    true_X_WC: RigidTransform  # where the camera really is (for checking only)


def add_arm(builder: DiagramBuilder, scene_graph: SceneGraph):
    """A MultibodyPlant of the arm holding the rod, registered with ``scene_graph`` for rendering,
    and the input port of its six positions (rad, through ``MultibodyPositionToGeometryPose``). The
    gripper's finger joint is replaced by a weld (closed on the rod) and the rod is welded in the
    grasp frame, so the plant's positions are the arm's six joints."""
    plant = SharedPointerSystem.AddToBuilder(builder, MultibodyPlant(time_step=0.0))
    plant.RegisterAsSourceForSceneGraph(scene_graph)
    parser = Parser(plant)
    parser.package_map().AddPackageXml(str(models_dir() / "package.xml"))  # package://sustain_drake
    arm = parser.AddModels(str(models_dir() / "ur_arm.sdf"))[0]
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("ur_base", arm), X_W_BASE)
    # The cell: the table with the arm's pedestal and the floor, posters on the wall behind the arm.
    for file, frame, X_WF in (("table.sdf", "table_top", RigidTransform([0.25, 0.0, 0.0])),
                              ("backdrop.sdf", "backdrop", RigidTransform([-2.705, 0.0, 0.7]))):
        model = parser.AddModels(str(models_dir() / file))[0]
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(frame, model), X_WF)
    rod = parser.AddModels(str(models_dir() / "rod_tool.sdf"))[0]
    plant.WeldFrames(plant.GetFrameByName("grasp", arm), plant.GetFrameByName("tool", rod))
    _weld_finger(plant, plant.GetJointByName("gripper_joint", arm), GRIPPER_CLOSED)
    plant.Finalize()
    to_pose = builder.AddSystem(MultibodyPositionToGeometryPose(plant))
    to_pose.set_name("arm_geometry")
    builder.Connect(to_pose.get_output_port(), scene_graph.get_source_pose_port(plant.get_source_id()))
    return plant, to_pose.get_input_port()


def _weld_finger(plant: MultibodyPlant, joint, position: float) -> None:
    """Replaces the prismatic ``joint`` (and its actuator) by a weld at ``position`` (m)."""
    X_PF = joint.frame_on_parent().GetFixedPoseInBodyFrame()
    X_CM = joint.frame_on_child().GetFixedPoseInBodyFrame()
    X_FM = RigidTransform(position * np.asarray(joint.translation_axis()))
    parent, child = joint.parent_body(), joint.child_body()
    for index in plant.GetJointActuatorIndices():
        if plant.get_joint_actuator(index).joint().index() == joint.index():
            plant.RemoveJointActuator(plant.get_joint_actuator(index))
    plant.RemoveJoint(joint)
    plant.WeldFrames(parent.body_frame(), child.body_frame(), X_PF @ X_FM @ X_CM.inverse())


def add_camera(builder: DiagramBuilder, scene_graph: SceneGraph, config: CameraConfig,
               X_WC: RigidTransform, seed: int = 0) -> RgbdCameraSampler:
    """A fixed RGB-D camera at ``X_WC`` (Drake's ``RgbdSensor``, rendered by VTK under a ceiling
    light and a light at the camera), sampled once per frame with a structured-light sensor's depth
    noise (``RgbdCameraSampler``: outputs ``color_image``, ``depth_image`` and ``image_time``)."""
    rgba = config.background
    scene_graph.AddRenderer(config.renderer_name, MakeRenderEngineVtk(RenderEngineVtkParams(
        default_clear_color=[rgba.r(), rgba.g(), rgba.b()],
        lights=[LightParameter(type="directional", frame="world", direction=[0.0, 0.3, -1.0], intensity=0.8),
                LightParameter(type="directional", frame="camera", direction=[0.0, 0.0, 1.0],
                               intensity=0.4)])))  # fmt: skip
    color_camera, depth_camera = config.MakeCameras()
    sensor = builder.AddSystem(RgbdSensor(scene_graph.world_frame_id(), X_WC, color_camera, depth_camera))
    sensor.set_name("rgbd_sensor")
    builder.Connect(scene_graph.get_query_output_port(), sensor.query_object_input_port())
    sampler = builder.AddSystem(RgbdCameraSampler(config.fps, depth_noise=DepthNoiseModel(), seed=seed))
    sampler.set_name("camera")
    builder.Connect(sensor.color_image_output_port(), sampler.GetInputPort("color_image"))
    builder.Connect(sensor.depth_image_32F_output_port(), sampler.GetInputPort("depth_image"))
    return sampler


def build(seed: int = 0) -> OnYourRobot:
    """The arm, the camera, the babbling and the coordination with its default settings, wired."""
    builder = DiagramBuilder()
    scene_graph = builder.AddSystem(SceneGraph())
    scene_graph.set_name("scene_graph")
    plant, arm_positions = add_arm(builder, scene_graph)
    config = camera_config()
    camera = add_camera(builder, scene_graph, config, X_WC, seed)
    hand = plant.GetBodyByName("gripper").body_frame()  # the hand frame H (here also the wrist's K)
    coordination = builder.AddSystem(make_sustainable_coordination(
        config, 6, loops=Loops(payload=False), plant=plant, hand_frame=hand))  # fmt: skip
    lower, upper = np.array(JOINT_RANGES).T
    motion = builder.AddSystem(MotionGenerator(lower, upper, START, seed=seed, max_speed=0.6))
    motion.set_name("motion_generator")

    # The arm follows the babbling's desired state [q, v]: its encoders read q (the velocities are
    # the payload loop's, which is off).
    state = builder.AddSystem(Demultiplexer([6, 6]))
    state.set_name("arm_state")
    builder.Connect(motion.GetOutputPort("desired_state"), state.get_input_port())
    builder.Connect(state.get_output_port(0), arm_positions)
    builder.Connect(state.get_output_port(0), coordination.GetInputPort("joint_positions"))
    for name in ("color_image", "depth_image", "image_time"):
        builder.Connect(camera.GetOutputPort(name), coordination.GetInputPort(name))
    # The babbling answers the coordination's requests: it stops after a convergence, and goes back
    # to a posture (then moves again) to confirm which pixels are the hand, or to a far posture.
    builder.Connect(coordination.GetOutputPort("hand_eye_pause"), motion.GetInputPort("pause"))
    builder.Connect(coordination.GetOutputPort("motion_confirm"), motion.GetInputPort("confirm"))
    diagram = builder.Build()
    diagram.set_name("on_your_robot")
    return OnYourRobot(diagram, coordination, motion, plant, X_WC)


@dataclass
class Event:
    """A hand-eye event (``coordination.Event``) with the adopted camera's error at that moment."""

    time: float  # s
    kind: str  # "converged", "change_detected" or "refined"
    detail: str
    camera_error_mm: float  # the adopted X_WC against the true camera (nan with none adopted)
    camera_error_deg: float


@dataclass
class Run:
    """What a run shows: the hand-eye events, and at its end the mode and the adopted estimates."""

    robot: OnYourRobot = field(repr=False)
    simulator: Simulator = field(repr=False)  # to read any port after the run
    wall_time: float = 0.0  # s
    events: list[Event] = field(default_factory=list)
    hand_eye_mode: int = 0  # 0 identify, 1 observe (an adopted camera and tool point in use)
    X_WC_valid: bool = False  # the coordination's X_WC_valid output: a camera is adopted
    X_WC: RigidTransform = field(default_factory=RigidTransform)  # the coordination's X_WC output
    p_HP: np.ndarray = field(default_factory=lambda: np.zeros(3))  # m, its p_HP output
    camera_error_mm: float = math.nan  # X_WC against the true camera (nan: none adopted)
    camera_error_deg: float = math.nan


def camera_error(X_WC: RigidTransform, true_X_WC: RigidTransform) -> tuple[float, float]:
    """The position (mm) and rotation (deg) error of a camera pose."""
    R = X_WC.rotation().matrix().T @ true_X_WC.rotation().matrix()
    return (1000.0 * float(np.linalg.norm(X_WC.translation() - true_X_WC.translation())),
            math.degrees(rotation_angle(R)))


def run(duration: float, seed: int = 0, on_event=None) -> Run:
    """Builds and simulates ``duration`` s; ``on_event(Event)`` is called as each hand-eye event
    happens. Returns the events and the coordination's outputs at the end."""
    robot = build(seed)
    result = Run(robot, Simulator(robot.diagram))
    context = robot.coordination.GetMyContextFromRoot(result.simulator.get_context())
    port = robot.coordination.GetOutputPort

    def adopted_error() -> tuple[float, float]:
        if not port("X_WC_valid").Eval(context)[0]:  # no camera adopted: X_WC means nothing
            return math.nan, math.nan
        return camera_error(port("X_WC").Eval(context), robot.true_X_WC)

    def monitor(root_context) -> EventStatus:
        for e in port("hand_eye_events").Eval(context)[len(result.events):]:
            result.events.append(Event(e.time, e.kind, e.detail, *adopted_error()))
            if on_event is not None:
                on_event(result.events[-1])
        return EventStatus.Succeeded()

    result.simulator.set_monitor(monitor)
    start = time.perf_counter()
    result.simulator.AdvanceTo(duration)
    result.wall_time = time.perf_counter() - start
    result.hand_eye_mode = int(port("hand_eye_mode").Eval(context)[0])
    result.X_WC_valid = bool(port("X_WC_valid").Eval(context)[0])
    result.X_WC = port("X_WC").Eval(context)
    result.p_HP = np.array(port("p_HP").Eval(context))
    result.camera_error_mm, result.camera_error_deg = adopted_error()
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=90.0, help="simulated s (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="the babbling's and the depth noise's seed")
    args = parser.parse_args(argv)

    def show(e: Event) -> None:
        print(f"{e.time:7.2f} s  {e.kind:16s} {e.detail:32s} camera {e.camera_error_mm:7.2f} mm "
              f"{e.camera_error_deg:6.3f} deg", flush=True)

    result = run(args.duration, args.seed, show)
    mode = "observe: a camera adopted and in use" if result.hand_eye_mode else "identify"
    print(f"after {args.duration:.1f} s ({result.wall_time:.0f} s wall): hand_eye_mode "
          f"{result.hand_eye_mode} ({mode})")
    print(f"X_WC {result.camera_error_mm:.2f} mm / {result.camera_error_deg:.3f} deg from the true camera; "
          f"p_HP {np.round(result.p_HP, 4)} m (the rod's tip: {P_H_ROD_TIP})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
