"""``build_station(scenario)``: the simulated world of the paper's experiments as a Diagram."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.geometry import (
    LightParameter,
    MakeRenderEngineVtk,
    Meshcat,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    RenderEngineVtkParams,
    SceneGraph,
)
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import GetScopedFrameByName
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant
from pydrake.multibody.tree import (
    ModelInstanceIndex,
    PdControllerGains,
    PrismaticJoint,
    RevoluteJoint,
    RigidBody,
    SpatialInertia,
)
from pydrake.systems.controllers import InverseDynamics
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import AffineSystem, MatrixGain, SharedPointerSystem
from pydrake.systems.sensors import CameraInfo, RgbdSensor

from sustain_drake.loops.coordination import camera_intrinsics
from sustain_drake.station.models import TOOL_FILES, ArmModel, make_parser, model_file
from sustain_drake.station.scenario import (
    HEAD_JOINTS,
    HeadMove,
    Scenario,
    ScenarioError,
    ToolSlip,
    Touch,
    arm_motion,
    arm_of,
    timeline,
)
from sustain_drake.station.scenario_files import validate_scenario
from sustain_drake.station.touch_plan import touch_postures
from sustain_drake.systems.camera_sampler import RgbdCameraSampler
from sustain_drake.systems.contact_truth import ContactTruth
from sustain_drake.systems.depth_noise import DepthNoiseModel
from sustain_drake.systems.distractor import DistractorPath
from sustain_drake.systems.disturbances import DisturbanceScheduler, Push, Step
from sustain_drake.systems.ground_truth import GroundTruth, PointMass
from sustain_drake.systems.motion_generator import MotionGenerator
from sustain_drake.systems.sensor_kinematics import SensorKinematicsFromPlant
from sustain_drake.systems.touch_motion import TouchMotion
from sustain_drake.systems.wrench_sensor import GripperCompensation, WristWrenchSensor

# Where the fixed furniture stands (world frame: origin on the table top, under the arm; the
# arm stands on the table's 0.25 m pedestal).
X_W_TABLE = RigidTransform([0.25, 0.0, 0.0])
X_W_ARM = RigidTransform([0.0, 0.0, 0.25])
# The posters' panel, its poster face 3 cm in front of the back wall's (world x = -2.725), its
# lower edge 0.3 m below the table top.
X_W_BACKDROP = RigidTransform([-2.705, 0.0, 0.7])
# The grip is two stiff PD joints (slide along the grasp z, pivot about the closing axis x):
# a tool slip is a fast move of these joints to new set points.
GRIP_GAINS = {"tool_slide": PdControllerGains(p=2.0e4, d=200.0),
              "tool_pivot": PdControllerGains(p=500.0, d=5.0)}
SENSOR_JOINT = "ft_sensor"
# A ceiling light and a dimmer light at the camera: the table and the person's sides are not
# black (VTK's default is a single headlight). A scenario's ``lights`` replace them.
ROOM_LIGHTS = [
    LightParameter(type="directional", frame="world", direction=[0.3, 0.2, -1.0],
                   intensity=0.8),
    LightParameter(type="directional", frame="camera", direction=[0.0, 0.0, 1.0],
                   intensity=0.5),
]

EXPORTED_OUTPUTS = (
    "joint_positions", "joint_velocities", "head_joint_positions", "X_WH", "X_WL", "wrench",
    "color_image", "depth_image", "label_image", "image_time",
    "true_X_WC", "true_p_HP", "true_X_HT", "true_tool_mass", "true_p_KCm", "true_outboard_mass",
    "true_p_KCo", "true_tool_inertia", "true_outboard_inertia", "true_touch", "true_contact",
    "sensor_kinematics",
)


def _selector(plant: MultibodyPlant, joints, velocities: bool) -> np.ndarray:
    """Rows picking the joints' positions (or velocities) out of the plant's full state."""
    nq = plant.num_positions()
    rows = np.zeros((len(joints), nq + plant.num_velocities()))
    for i, name in enumerate(joints):
        joint = plant.GetJointByName(name)
        rows[i, nq + joint.velocity_start() if velocities else joint.position_start()] = 1.0
    return rows


def _add_grip(plant: MultibodyPlant, scenario: Scenario, arm, tool_instance):
    """Holds the tool in the grasp frame G through the two slip joints (see GRIP_GAINS)."""
    # Nearly massless, so the held mass is the tool's (10 ug: far below the F/T noise).
    tiny = SpatialInertia.SolidSphereWithMass(1e-5, 0.005)
    slide_link = plant.AddRigidBody("tool_slide_link", tool_instance, tiny)
    pivot_link = plant.AddRigidBody("tool_pivot_link", tool_instance, tiny)
    grasp = plant.GetFrameByName("grasp", arm)
    slide = plant.AddJoint(PrismaticJoint(
        "tool_slide", grasp, slide_link.body_frame(), [0.0, 0.0, 1.0]))
    pivot = plant.AddJoint(RevoluteJoint(
        "tool_pivot", slide_link.body_frame(), pivot_link.body_frame(), [1.0, 0.0, 0.0]))
    slide.set_default_translation(scenario.tool.slide)
    pivot.set_default_angle(scenario.tool.pivot)
    tool_body = plant.GetBodyByName("tool", tool_instance)
    plant.WeldFrames(pivot_link.body_frame(), tool_body.body_frame(),
                     _deterministic(scenario.tool.X_GT, "tool.X_GT"))
    for joint in (slide, pivot):
        actuator = plant.AddJointActuator(joint.name(), joint)
        actuator.set_controller_gains(GRIP_GAINS[joint.name()])
    return tool_body


def _gripper_compensation(plant: MultibodyPlant, hand, X_HK) -> GripperCompensation:
    """The gripper's own mass and CoM in K (the arm's bodies outboard of the sensor: palm and
    finger, the finger at its default closed position)."""
    context = plant.CreateDefaultContext()
    arm = hand.model_instance()
    bodies = [hand.index()] + [b for b in plant.GetBodiesKinematicallyAffectedBy(
        [plant.GetJointByName("gripper_joint").index()])
        if plant.get_body(b).model_instance() == arm]
    X_KW = (plant.EvalBodyPoseInWorld(context, hand) @ X_HK).inverse()
    masses = [plant.get_body(b).default_mass() for b in bodies]
    p_KC = sum(m * (X_KW @ plant.EvalBodyPoseInWorld(context, plant.get_body(b))
                    @ plant.get_body(b).default_com())
               for m, b in zip(masses, bodies, strict=True)) / sum(masses)
    g_W = plant.gravity_field().gravity_vector()
    return GripperCompensation(sum(masses), tuple(p_KC), tuple(g_W))


@dataclass
class _World:
    """The plant's model instances and bodies that the station's systems are wired to."""

    plant: MultibodyPlant
    scene_graph: SceneGraph
    arm_model: ArmModel  # the arm's model file, joints and hand
    arm: ModelInstanceIndex
    head: ModelInstanceIndex
    person: ModelInstanceIndex | None
    tool: ModelInstanceIndex | None
    tool_body: RigidBody | None
    posture: np.ndarray  # the arm's initial posture, within the joint limits

    @property
    def hand(self) -> RigidBody:
        return self.plant.GetBodyByName(self.arm_model.hand_body, self.arm)

    @property
    def joints(self) -> list:
        """The arm's babbling joints, base to hand."""
        return [self.plant.GetJointByName(name, self.arm) for name in self.arm_model.joints]

    @property
    def X_HK(self) -> RigidTransform:
        """The sensor frame K (the weld's child frame Jc) in the hand frame H."""
        return self.plant.GetJointByName(SENSOR_JOINT).frame_on_child().GetFixedPoseInBodyFrame()


def held_shape(station):
    """The held tool's collision shape (a ``pydrake.geometry`` shape) and its pose ``X_KG`` in the
    sensor frame K at the nominal grasp, from the station's plant and SceneGraph."""
    plant = station.GetSubsystemByName("plant")
    inspector = station.GetSubsystemByName("scene_graph").model_inspector()
    tool = plant.GetBodyByName("tool")
    geometries = plant.GetCollisionGeometriesForBody(tool)
    if len(geometries) != 1:
        raise ValueError(f"the held tool needs exactly one collision geometry, it has {len(geometries)}")
    context = plant.CreateDefaultContext()
    hand = plant.GetJointByName(SENSOR_JOINT).child_body()
    X_WK = plant.EvalBodyPoseInWorld(context, hand) @ sensor_pose_in_hand(station)
    X_KG = X_WK.inverse() @ plant.EvalBodyPoseInWorld(context, tool) @ inspector.GetPoseInFrame(geometries[0])
    return inspector.GetShape(geometries[0]), RigidTransform(X_KG)


def babbling_joints(station, scenario: Scenario) -> list:
    """The arm's babbling joints (base to hand) in the station's plant."""
    plant = station.GetSubsystemByName("plant")
    arm = plant.GetJointByName(SENSOR_JOINT).child_body().model_instance()
    return [plant.GetJointByName(name, arm) for name in arm_of(scenario).joints]


def sensor_frame(station):
    """The wrist sensor's frame K (the weld's child frame) in the station's plant."""
    return station.GetSubsystemByName("plant").GetJointByName(SENSOR_JOINT).frame_on_child()


def hand_frame(station):
    """The hand's body frame H (the wrist weld's child body) in the station's plant."""
    return station.GetSubsystemByName("plant").GetJointByName(SENSOR_JOINT).child_body().body_frame()


def sensor_pose_in_hand(station) -> RigidTransform:
    """``X_HK``: the wrist sensor's frame K (the weld's child frame) in the hand frame H."""
    plant = station.GetSubsystemByName("plant")
    return plant.GetJointByName(SENSOR_JOINT).frame_on_child().GetFixedPoseInBodyFrame()


def camera_info(scenario: Scenario) -> CameraInfo:
    """The intrinsics of the scenario's camera (image size, focal lengths, principal point),
    e.g. for the optical-flow tracker's constructor."""
    return camera_intrinsics(scenario.camera, "scenario.camera")


def _deterministic(transform, name: str) -> RigidTransform:
    try:
        return transform.GetDeterministicValue()
    except Exception:
        raise ScenarioError(f"{name} must be a fixed pose, not a random one") from None


def build_station(scenario: Scenario, meshcat: Meshcat | None = None) -> Diagram:
    """Builds the world of ``scenario`` as a Diagram named ``station``.

    Exported outputs: see ``EXPORTED_OUTPUTS`` and docs/simulation.md (the
    camera ports exist only when the scenario's camera renders them). Exported inputs:
    ``motion_pause``, ``motion_confirm`` and ``motion_goal`` (the MotionGenerator's requests and
    its next babbling goal). With a
    ``meshcat``, the scene is also drawn there (illustration geometry). A scenario the world
    cannot be built from raises ``ScenarioError``.
    """
    validate_scenario(scenario)
    builder = DiagramBuilder()
    world = _add_world(builder, scenario)
    _add_motion_generator(builder, world, scenario)
    _add_disturbances(builder, world, scenario)
    if world.person is not None:
        _add_distractor(builder, world, scenario)
    _add_proprioception(builder, world)
    wrench = _add_wrench_sensor(builder, world, scenario)
    camera_body, X_BS = _camera_mount(world.plant, scenario)
    cam = scenario.camera
    if cam.rgb or cam.depth or cam.label:
        _add_camera(builder, world.plant, world.scene_graph, scenario, camera_body, X_BS)
    truth = _add_ground_truth(builder, world, camera_body,
                              X_BS @ _deterministic(cam.X_BC, "camera.X_BC"))
    _add_contact_truth(builder, world)
    if wrench.HasInputPort("X_WK"):
        builder.Connect(truth.GetOutputPort("X_WH"), wrench.GetInputPort("X_WK"))
    if meshcat is not None:
        # Illustration geometry only, at the camera's rate: enough for a replay, and cheap.
        MeshcatVisualizer.AddToBuilder(builder, world.scene_graph, meshcat,
                                       MeshcatVisualizerParams(publish_period=1.0 / 30.0))
    diagram = builder.Build()
    diagram.set_name("station")
    return diagram


def _add_world(builder: DiagramBuilder, scenario: Scenario) -> _World:
    """The plant: arm on its pedestal, table, head, the held tool and the person, starting in
    the scenario's initial state (arm posture, closed gripper, head angles)."""
    plant, scene_graph = AddMultibodyPlant(scenario.plant_config, builder)
    parser = make_parser(plant)
    arm_model = arm_of(scenario)
    arm = parser.AddModels(model_file(arm_model.file))[0]
    head = parser.AddModels(model_file("head.sdf"))[0]
    table = parser.AddModels(model_file("table.sdf"))[0]
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(arm_model.base_frame, arm), X_W_ARM)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("table_top", table), X_W_TABLE)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("head_post", head),
                     _deterministic(scenario.head.X_WP, "head.X_WP"))
    if scenario.backdrop.enabled:
        backdrop = parser.AddModels(model_file("backdrop.sdf"))[0]
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("backdrop", backdrop), X_W_BACKDROP)
    person = None
    if scenario.distractor.enabled:
        person = parser.AddModels(model_file("person.sdf"))[0]
    tool = tool_body = None
    if scenario.tool.model != "none":
        tool = parser.AddModels(model_file(TOOL_FILES[scenario.tool.model]))[0]
        tool_body = _add_grip(plant, scenario, arm, tool)

    joints = [plant.GetJointByName(j, arm) for j in arm_model.joints]
    posture = np.clip(arm_motion(scenario).initial_posture,
                      [j.position_lower_limits()[0] for j in joints],
                      [j.position_upper_limits()[0] for j in joints])
    for joint, angle in zip(joints, posture, strict=True):
        joint.set_default_angle(angle)
    plant.GetJointByName("gripper_joint").set_default_translation(scenario.tool.gripper_position)
    plant.GetJointByName("head_pan").set_default_angle(scenario.head.pan)
    plant.GetJointByName("head_tilt").set_default_angle(scenario.head.tilt)
    plant.Finalize()
    return _World(plant, scene_graph, arm_model, arm, head, person, tool, tool_body, posture)


def babbling_ranges(scenario: Scenario, joints) -> tuple[list[float], list[float]]:
    """``(lower, upper)``, rad: the babbling's joint ranges (``motion.joint_ranges``, or the arm's
    own) clipped to the ``joints``' limits. ScenarioError when a range lies outside them."""
    m = arm_motion(scenario)
    lower = [max(r[0], j.position_lower_limits()[0])
             for r, j in zip(m.joint_ranges, joints, strict=True)]
    upper = [min(r[1], j.position_upper_limits()[0])
             for r, j in zip(m.joint_ranges, joints, strict=True)]
    if any(lo > hi for lo, hi in zip(lower, upper, strict=True)):
        raise ScenarioError("motion.joint_ranges lie outside the arm's joint limits")
    return lower, upper


def _add_motion_generator(builder, world: _World, scenario: Scenario) -> None:
    """Babbling arm: its joints from the motion generator, the gripper held closed."""
    m, joints = arm_motion(scenario), world.joints
    lower, upper = babbling_ranges(scenario, joints)
    motion = builder.AddSystem(MotionGenerator(
        lower, upper, world.posture, seed=m.seed, max_speed=m.max_speed,
        min_duration=m.min_duration, dwell=m.dwell, period=m.period,
        confirm_hold=m.confirm_hold, confirm_step=m.confirm_step, confirm_near=m.confirm_near))
    motion.set_name("motion_generator")
    n = len(joints)
    # The arm instance's desired state is [q_1..q_n, q_grip, v_1..v_n, v_grip] (by actuator).
    actuated = [world.plant.get_joint_actuator(a).joint().name()
                for a in world.plant.GetJointActuatorIndices(world.arm)]
    if actuated != [*world.arm_model.joints, "gripper_joint"]:
        raise ScenarioError(f"arm model {world.arm_model.file}: its actuators must be its joints in "
                            "order, then gripper_joint")
    D = np.zeros((2 * n + 2, 2 * n))
    D[:n, :n] = np.eye(n)
    D[n + 1:2 * n + 1, n:] = np.eye(n)
    y0 = np.zeros(2 * n + 2)
    y0[n] = scenario.tool.gripper_position
    arm_desired = builder.AddSystem(AffineSystem(D=D, y0=y0))
    arm_desired.set_name("arm_desired_state")
    builder.Connect(_add_touch_motion(builder, world, scenario, motion.get_output_port()),
                    arm_desired.get_input_port())
    builder.Connect(arm_desired.get_output_port(), world.plant.get_desired_state_input_port(world.arm))
    if m.gravity_compensation:
        _add_arm_gravity_compensation(builder, world)
    builder.ExportInput(motion.GetInputPort("pause"), "motion_pause")
    builder.ExportInput(motion.GetInputPort("confirm"), "motion_confirm")
    builder.ExportInput(motion.GetInputPort("goal"), "motion_goal")


def _add_arm_gravity_compensation(builder, world: _World) -> None:
    """Feedforward of the arm's own gravity torques on its actuation input (added to the joints'
    PD), computed on a controller model of the arm alone: the held tool is unknown to the robot."""
    # SharedPointerSystem: the diagram keeps the controller model alive as long as it lives.
    controller_plant = SharedPointerSystem.AddToBuilder(builder, MultibodyPlant(time_step=0.0))
    arm = make_parser(controller_plant).AddModels(model_file(world.arm_model.file))[0]
    controller_plant.WeldFrames(controller_plant.world_frame(),
                                controller_plant.GetFrameByName(world.arm_model.base_frame, arm), X_W_ARM)
    controller_plant.Finalize()
    # The arm instance's actuation input is ordered by actuator, the inverse dynamics' output by
    # generalized velocity; the same model file gives both one actuator per joint in one order.
    actuated_dofs = [controller_plant.get_joint_actuator(a).joint().velocity_start()
                     for a in controller_plant.GetJointActuatorIndices()]
    if actuated_dofs != list(range(controller_plant.num_velocities())):
        raise ScenarioError("arm model: gravity compensation needs one actuator per joint, "
                            "in joint order")
    gravity = builder.AddSystem(InverseDynamics(
        controller_plant, InverseDynamics.InverseDynamicsMode.kGravityCompensation))
    gravity.set_name("arm_gravity_compensation")
    builder.Connect(world.plant.get_state_output_port(world.arm),
                    gravity.get_input_port_estimated_state())
    builder.Connect(gravity.get_output_port_generalized_force(),
                    world.plant.get_actuation_input_port(world.arm))


def _add_touch_motion(builder, world: _World, scenario: Scenario, babble):
    """With ``touch_motion`` enabled, the touching program sits between the babbling and the
    arm (inputs ``touch_start``, ``touch_feedback``; output ``touch_phase``). Returns the port
    that drives the arm."""
    tm = scenario.touch_motion
    if not tm.enabled:
        return babble
    postures = touch_postures(world.plant, world.tool_body, tm, X_W_TABLE.translation()[2],
                              world.posture, world.joints)
    descent = tm.approach_height + tm.press_depth
    touch = builder.AddSystem(TouchMotion(
        postures, descend_duration=descent / tm.descend_speed, keep_touching=tm.keep_touching,
        press_extra=tm.press_extra / descent, max_speed=tm.max_speed,
        start_delay=tm.start_delay, repeat=tm.repeat, period=scenario.motion.period, rest=tm.rest))
    touch.set_name("touch_motion")
    builder.Connect(babble, touch.GetInputPort("babble_state"))
    builder.ExportInput(touch.GetInputPort("start"), "touch_start")
    builder.ExportInput(touch.GetInputPort("touch"), "touch_feedback")
    builder.ExportOutput(touch.GetOutputPort("phase"), "touch_phase")
    return touch.GetOutputPort("desired_state")


def _add_contact_truth(builder, world: _World) -> None:
    """``true_contact``: the real contacts on the held tool (zeros without a tool)."""
    plant = world.plant
    bodies = [] if world.tool_body is None else [world.tool_body.index()]
    geometries = [g.get_value() for b in bodies
                  for g in plant.GetCollisionGeometriesForBody(plant.get_body(b))]
    truth = builder.AddSystem(ContactTruth(bodies, geometries))
    truth.set_name("contact_truth")
    builder.Connect(plant.get_contact_results_output_port(),
                    truth.GetInputPort("contact_results"))
    builder.ExportOutput(truth.GetOutputPort("true_contact"), "true_contact")


def _add_disturbances(builder, world: _World, scenario: Scenario) -> None:
    """The timeline: head moves, tool slips, touches (and the touches' ground truth)."""
    plant, events = world.plant, timeline(scenario)
    scheduler = builder.AddSystem(DisturbanceScheduler(
        head_initial=[scenario.head.pan, scenario.head.tilt],
        head_steps=[Step(e.time, (e.pan, e.tilt), e.duration)
                    for e in events if isinstance(e, HeadMove)],
        tool_initial=[scenario.tool.slide, scenario.tool.pivot],
        tool_steps=[Step(e.time, (e.slide, e.pivot), e.duration)
                    for e in events if isinstance(e, ToolSlip)],
        pushes=[Push(e.time, e.duration, tuple(e.p_TQ), tuple(e.f_T))
                for e in events if isinstance(e, Touch)],
        tool_body=None if world.tool_body is None else world.tool_body.index(),
        sensor_body=world.hand.index(), X_SK=world.X_HK))
    scheduler.set_name("disturbances")
    builder.Connect(plant.get_body_poses_output_port(), scheduler.GetInputPort("body_poses"))
    builder.Connect(scheduler.GetOutputPort("head_desired_state"),
                    plant.get_desired_state_input_port(world.head))
    if world.tool is not None:
        builder.Connect(scheduler.GetOutputPort("tool_desired_state"),
                        plant.get_desired_state_input_port(world.tool))
    builder.Connect(scheduler.GetOutputPort("applied_forces"),
                    plant.get_applied_spatial_force_input_port())
    builder.ExportOutput(scheduler.GetOutputPort("true_touch"), "true_touch")


def _add_distractor(builder, world: _World, scenario: Scenario) -> None:
    """The person walks the scenario's path (PD-tracked x-y-yaw joints), from its start."""
    d, plant = scenario.distractor, world.plant
    path = builder.AddSystem(DistractorPath(d.waypoints, d.speed, d.start_time, d.loop))
    path.set_name("distractor_path")
    start = path.state_at(0.0)
    plant.GetJointByName("person_x_joint").set_default_translation(start[0])
    plant.GetJointByName("person_y_joint").set_default_translation(start[1])
    plant.GetJointByName("person_yaw").set_default_angle(start[2])
    builder.Connect(path.get_output_port(), plant.get_desired_state_input_port(world.person))


def _add_proprioception(builder, world: _World) -> None:
    """The joint encoders: arm positions and velocities, head positions."""
    arm_joints = world.arm_model.joints
    for name, joints, velocities in (("joint_positions", arm_joints, False),
                                     ("joint_velocities", arm_joints, True),
                                     ("head_joint_positions", HEAD_JOINTS, False)):
        gain = builder.AddSystem(MatrixGain(_selector(world.plant, joints, velocities)))
        gain.set_name(name)
        builder.Connect(world.plant.get_state_output_port(), gain.get_input_port())
        builder.ExportOutput(gain.get_output_port(), name)


def _add_wrench_sensor(builder, world: _World, scenario: Scenario) -> WristWrenchSensor:
    """The wrist F/T sensor on the weld (K = Jc, the weld's frame on the gripper side)."""
    w, plant = scenario.wrench_sensor, world.plant
    compensation = None
    if w.compensate_gripper:
        if not world.X_HK.IsExactlyIdentity():
            raise ScenarioError("gripper compensation needs the sensor frame K = hand H")
        compensation = _gripper_compensation(plant, world.hand, world.X_HK)
    wrench = builder.AddSystem(WristWrenchSensor(
        plant.GetJointByName(SENSOR_JOINT).index(), 1.0 / w.rate, w.force_noise,
        w.torque_noise, w.bias, w.seed, compensation))
    wrench.set_name("wrench_sensor")
    builder.Connect(plant.get_reaction_forces_output_port(),
                    wrench.GetInputPort("reaction_forces"))
    builder.ExportOutput(wrench.get_output_port(), "wrench")
    # The sensor frame's true kinematics at the wrench's instants (the dynamic payload identification).
    kinematics = builder.AddSystem(SensorKinematicsFromPlant(
        plant, plant.GetJointByName(SENSOR_JOINT).frame_on_child(), 1.0 / w.rate))
    kinematics.set_name("sensor_kinematics")
    for name in ("body_poses", "body_spatial_velocities", "body_spatial_accelerations"):
        builder.Connect(getattr(plant, f"get_{name}_output_port")(), kinematics.GetInputPort(name))
    builder.ExportOutput(kinematics.get_output_port(), "sensor_kinematics")
    return wrench


def _camera_mount(plant: MultibodyPlant, scenario: Scenario):
    """The body carrying the camera and the camera sensor body's pose S in it."""
    cam = scenario.camera
    try:
        frame = (GetScopedFrameByName(plant, cam.X_PB.base_frame)
                 if cam.X_PB.base_frame else plant.world_frame())
    except RuntimeError:
        raise ScenarioError(
            f"camera.X_PB.base_frame: no frame named '{cam.X_PB.base_frame}' "
            "(the head's is 'head::camera_mount')") from None
    return frame.body(), frame.GetFixedPoseInBodyFrame() @ _deterministic(cam.X_PB,
                                                                          "camera.X_PB")


def _add_ground_truth(builder, world: _World, camera_body, X_BC) -> GroundTruth:
    """Hand pose and the evaluation-only ground truth (camera pose, tool point and pose in the
    hand, masses)."""
    plant = world.plant
    wrist_roll = world.joints[-1]
    outboard = [b for b in plant.GetBodiesKinematicallyAffectedBy([wrist_roll.index()])
                if b != wrist_roll.child_body().index()]
    tracked = (plant.GetFrameByName("tracked_point", world.tool) if world.tool is not None
               else plant.GetFrameByName("grasp", world.arm))

    def point_mass(body):
        I_BBcm = body.default_spatial_inertia().Shift(body.default_com()).CalcRotationalInertia()
        return PointMass(int(body.index()), body.default_mass(), tuple(body.default_com()),
                         tuple(I_BBcm.get_moments()) + tuple(I_BBcm.get_products()))

    truth = builder.AddSystem(GroundTruth(
        hand_body=world.hand.index(), X_HK=world.X_HK, camera_body=camera_body.index(),
        X_BC=X_BC, tool_body=tracked.body().index(),
        p_TP=tracked.GetFixedPoseInBodyFrame().translation(),
        tool=None if world.tool_body is None else point_mass(world.tool_body),
        outboard=[point_mass(plant.get_body(b)) for b in outboard],
        parent_body=wrist_roll.parent_body().index()))
    truth.set_name("ground_truth")
    builder.Connect(plant.get_body_poses_output_port(), truth.get_input_port())
    for port in ("X_WH", "X_WL", "true_X_WC", "true_p_HP", "true_X_HT", "true_tool_mass", "true_p_KCm",
                 "true_outboard_mass", "true_p_KCo", "true_tool_inertia", "true_outboard_inertia"):
        builder.ExportOutput(truth.GetOutputPort(port), port)
    return truth


def _add_camera(builder, plant, scene_graph, scenario: Scenario, body, X_BS) -> None:
    """The RGB-D camera at ``X_BS`` on ``body``: a continuous ``RgbdSensor`` read once per frame
    by a sampler, so each image the scenario asks for is rendered once per frame."""
    cam = scenario.camera
    if not scene_graph.HasRenderer(cam.renderer_name):
        rgba = cam.background
        scene_graph.AddRenderer(cam.renderer_name, MakeRenderEngineVtk(RenderEngineVtkParams(
            default_clear_color=[rgba.r(), rgba.g(), rgba.b()],
            lights=list(scenario.lights) or ROOM_LIGHTS)))
    color_camera, depth_camera = cam.MakeCameras()
    sensor = builder.AddSystem(RgbdSensor(
        plant.GetBodyFrameIdOrThrow(body.index()), X_BS, color_camera, depth_camera))
    sensor.set_name("rgbd_sensor")
    builder.Connect(scene_graph.get_query_output_port(), sensor.query_object_input_port())
    images = [name for name, wanted in (("color_image", cam.rgb), ("depth_image", cam.depth),
                                        ("label_image", cam.label)) if wanted]
    noise = scenario.depth_noise
    sampler = builder.AddSystem(RgbdCameraSampler(
        cam.fps, images,
        DepthNoiseModel(noise.a, noise.b, noise.z0) if noise.enabled else None, noise.seed))
    sampler.set_name("camera")
    sources = {"color_image": sensor.color_image_output_port(),
               "depth_image": sensor.depth_image_32F_output_port(),
               "label_image": sensor.label_image_output_port()}
    for name in images:
        builder.Connect(sources[name], sampler.GetInputPort(name))
        builder.ExportOutput(sampler.GetOutputPort(name), name)
    builder.ExportOutput(sampler.GetOutputPort("image_time"), "image_time")
