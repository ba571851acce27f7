"""make_sustainable_coordination on an arm that is not ours: a 3-joint arm built here with the
MultibodyPlant API, fed by scripted sensors (postures, images, the static wrench of a known
payload)."""

from dataclasses import replace

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.geometry import Box
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import FixedOffsetFrame, RevoluteJoint, SpatialInertia, UnitInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource
from pydrake.systems.sensors import CameraInfo, ImageDepth32F, ImageRgba8U

from sustain_drake.identification import coordination
from sustain_drake.loops.coordination import (
    RANGE_MARGIN,
    Loops,
    joint_ranges_from_limits,
    make_sustainable_coordination,
)
from sustain_drake.loops.hand_eye import HandEyeConfig
from sustain_drake.station import models_dir
from sustain_drake.systems.hand_pose_from_plant import HandPoseFromPlant, parent_link

MASS, P_KCM = 0.8, np.array([0.02, -0.01, 0.09])  # the held payload, kg and m in K
G_W = np.array([0.0, 0.0, -9.81])


def three_joint_arm() -> MultibodyPlant:
    """Yaw, pitch, roll: a wrist that can turn the payload through many orientations."""
    plant = MultibodyPlant(0.0)
    parent = plant.world_body()
    axes = ([0, 0, 1], [0, 1, 0], [1, 0, 0])
    for i, axis in enumerate(axes):
        inertia = SpatialInertia(1.0, np.zeros(3), UnitInertia.SolidSphere(0.05))
        body = plant.AddRigidBody(f"link{i + 1}", inertia)
        # Each joint 0.3 m above the previous link's origin (the first 0.1 m above the world's).
        F = plant.AddFrame(FixedOffsetFrame(f"mount{i + 1}", parent.body_frame(),
                                            RigidTransform([0.0, 0.0, 0.3 if i else 0.1])))  # fmt: skip
        plant.AddJoint(RevoluteJoint(f"joint{i + 1}", F, body.body_frame(), axis, 0.0))
        parent = body
    plant.Finalize()
    return plant


def payload_wrench(plant, q) -> np.ndarray:
    """``[tau_K; f_K]`` of the wrist (link3) holding the payload at rest at posture ``q``."""
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, q)
    R_WK = plant.GetBodyByName("link3").EvalPoseInWorld(plant_context).rotation().matrix()
    f_K = R_WK.T @ (-MASS * G_W)  # the wrist holds the payload up
    return np.concatenate([np.cross(P_KCM, f_K), f_K])


def sensor_noise(t: float) -> np.ndarray:
    """A real sensor's noise (0.02 N m, 0.1 N), reproducible: noise-free data would make the
    allowable error of the observation rule vanish."""
    return np.random.default_rng(round(t * 1e4)).normal(size=6) * ([0.02] * 3 + [0.1] * 3)


class ScriptedArm(LeafSystem):
    """Stops at one posture after another (``period`` s each); outputs the joint positions and
    the wrench of the payload at rest, from the test's own forward kinematics."""

    def __init__(self, plant, postures, period, push_time=np.inf, p_KP=(0, 0, 0), f_env_K=(0, 0, 0)):
        super().__init__()
        self._plant, self._postures, self._period = plant, np.asarray(postures), period
        # From push_time on, the environment pushes the held object at p_KP with f_env_K.
        self._push = (push_time, np.asarray(p_KP), np.asarray(f_env_K))
        self.DeclareVectorOutputPort("q", plant.num_positions(), lambda c, o: o.SetFromVector(self._q(c)))
        self.DeclareVectorOutputPort("wrench", 6, self._calc_wrench)

    def _q(self, context):
        k = min(int(context.get_time() / self._period), len(self._postures) - 1)
        return self._postures[k]

    def _calc_wrench(self, context, output):
        tau_K, f_K = np.split(payload_wrench(self._plant, self._q(context)), 2)
        push_time, p_KP, f_env_K = self._push
        if context.get_time() >= push_time:  # the wrist balances the push too
            f_K, tau_K = f_K - f_env_K, tau_K - np.cross(p_KP, f_env_K)
        output.SetFromVector(np.concatenate([tau_K, f_K]) + sensor_noise(context.get_time()))


def _arm_with_coordination(plant, postures, info, arm_kwargs=None, **kwargs):
    """The diagram under test fed by ``ScriptedArm``, still joints and textureless images."""
    coordination_diagram = make_sustainable_coordination(
        info, plant.num_positions(), plant=plant, hand_frame=plant.GetBodyByName("link3").body_frame(),
        **kwargs)  # fmt: skip
    builder = DiagramBuilder()
    sc = builder.AddSystem(coordination_diagram)
    arm = builder.AddSystem(ScriptedArm(plant, postures, 0.25, **(arm_kwargs or {})))
    color, depth = _images(builder, info)
    builder.Connect(color.get_output_port(), sc.GetInputPort("color_image"))
    builder.Connect(depth.get_output_port(), sc.GetInputPort("depth_image"))
    builder.Connect(arm.GetOutputPort("q"), sc.GetInputPort("joint_positions"))
    builder.Connect(arm.GetOutputPort("wrench"), sc.GetInputPort("wrench"))
    still = builder.AddSystem(ConstantVectorSource(np.zeros(plant.num_positions())))
    builder.Connect(still.get_output_port(), sc.GetInputPort("joint_velocities"))
    return sc, Simulator(builder.Build())


def _images(builder, info):
    color = ImageRgba8U(info.width(), info.height())
    depth = ImageDepth32F(info.width(), info.height())
    depth.mutable_data[:] = 1.0
    return (builder.AddSystem(ConstantValueSource(AbstractValue.Make(color))),
            builder.AddSystem(ConstantValueSource(AbstractValue.Make(depth))))  # fmt: skip


def test_identifies_the_payload_of_a_three_joint_arm_from_its_plant():
    plant = three_joint_arm()
    hand = plant.GetBodyByName("link3").body_frame()
    info = CameraInfo(160, 120, 1.0)
    rng = np.random.default_rng(3)
    postures = rng.uniform(-1.2, 1.2, size=(12, 3))
    sc, simulator = _arm_with_coordination(plant, postures, info)
    assert not sc.HasInputPort("X_WH")
    context = simulator.get_mutable_context()
    sc_context = sc.GetMyContextFromRoot(context)
    assert sc.GetOutputPort("payload_mode").Eval(sc_context)[0] == coordination.IDENTIFY
    assert sc.GetOutputPort("payload_mass").Eval(sc_context)[0] == 0.0  # nothing adopted yet
    assert sc.GetOutputPort("payload_valid").Eval(sc_context)[0] == 0.0
    assert np.all(np.isinf(sc.GetOutputPort("payload_sd").Eval(sc_context)))  # not known
    simulator.AdvanceTo(3.0)

    assert sc.GetOutputPort("payload_mode").Eval(sc_context)[0] == coordination.OBSERVE
    events = sc.GetOutputPort("payload_events").Eval(sc_context)
    assert [e.kind for e in events].count(coordination.CONVERGED) == 1
    assert sc.GetOutputPort("payload_mass").Eval(sc_context)[0] == pytest.approx(MASS, rel=0.01)
    np.testing.assert_allclose(sc.GetOutputPort("p_KCm").Eval(sc_context), P_KCM, atol=3e-3)
    assert sc.GetOutputPort("payload_valid").Eval(sc_context)[0] == 1.0
    # The uncertainty (1 sd, kg and m: millimetres from 12 postures) covers the error.
    sd = sc.GetOutputPort("payload_sd").Eval(sc_context)
    assert np.all(np.isfinite(sd)) and np.all(sd > 0) and sd[0] < 0.004 and np.all(sd[1:] < 5e-3)
    assert abs(sc.GetOutputPort("payload_mass").Eval(sc_context)[0] - MASS) < 4.0 * sd[0]
    assert np.all(np.abs(sc.GetOutputPort("p_KCm").Eval(sc_context) - P_KCM) < 4.0 * sd[1:])
    assert sc.GetOutputPort("payload_reset_reason").Eval(sc_context)[0] == coordination.NO_RESET
    # The hand pose is the plant's forward kinematics at the last posture.
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, postures[-1])
    X_WH = sc.GetOutputPort("X_WH_used").Eval(sc_context)
    assert X_WH.IsNearlyEqualTo(hand.CalcPoseInWorld(plant_context), 1e-12)
    assert not X_WH.IsNearlyEqualTo(RigidTransform(), 1e-3)
    # No texture, no features: the hand-eye loop runs but has nothing to adopt.
    assert sc.GetOutputPort("hand_eye_mode").Eval(sc_context)[0] == coordination.IDENTIFY
    assert sc.GetOutputPort("X_WC_valid").Eval(sc_context)[0] == 0.0  # X_WC (the identity) means nothing
    assert sc.GetOutputPort("followed_point_valid").Eval(sc_context)[0] == 0.0
    # The payload's state machine asked the motion to pause once (after its convergence).
    assert sc.GetOutputPort("payload_pause").Eval(sc_context)[0] == 1


def test_touch_on_the_held_object_after_the_payload_is_adopted():
    plant = three_joint_arm()
    info = CameraInfo(160, 120, 1.0)
    postures = np.random.default_rng(3).uniform(-1.2, 1.2, size=(12, 3))
    # A 0.2 m long box held below the sensor; at 3.2 s its tip is pushed towards the hand with 8 N.
    p_KP, f_env_K = np.array([0.0, 0.0, 0.2]), np.array([0.0, 0.0, -8.0])
    sc, simulator = _arm_with_coordination(
        plant, postures, info, arm_kwargs=dict(push_time=3.2, p_KP=p_KP, f_env_K=f_env_K),
        loops=Loops(touch=True), held_shape=Box(0.04, 0.04, 0.2),
        X_KG=RigidTransform([0.0, 0.0, 0.1]))  # fmt: skip
    sc_context = sc.GetMyContextFromRoot(simulator.get_mutable_context())
    simulator.AdvanceTo(3.15)
    assert sc.GetOutputPort("payload_mode").Eval(sc_context)[0] == coordination.OBSERVE
    assert sc.GetOutputPort("touch").Eval(sc_context)[0] == 0.0
    simulator.AdvanceTo(3.3)
    assert sc.GetOutputPort("touch").Eval(sc_context)[0] == 1.0
    X_WK = sc.GetOutputPort("X_WK_used").Eval(sc_context)
    np.testing.assert_allclose(sc.GetOutputPort("p_WP").Eval(sc_context), X_WK @ p_KP, atol=0.01)
    f_env_W = sc.GetOutputPort("f_env_W").Eval(sc_context)
    np.testing.assert_allclose(f_env_W, X_WK.rotation() @ f_env_K, atol=0.5)


def test_without_a_plant_the_hand_pose_is_an_input_and_sizes_are_checked():
    info = CameraInfo(160, 120, 1.0)
    diagram = make_sustainable_coordination(info, 6, joint_ranges=[[-1.0, 1.0]] * 6)
    names = {diagram.get_input_port(i).get_name() for i in range(diagram.num_input_ports())}
    assert names == {"color_image", "depth_image", "image_time", "joint_positions", "joint_velocities",
                     "X_WH", "wrench"}  # fmt: skip
    assert diagram.GetInputPort("joint_positions").size() == 6
    assert not diagram.HasOutputPort("touch")  # no held shape, no touch estimator
    context = diagram.CreateDefaultContext()
    X_WH = RigidTransform([0.1, 0.2, 0.3])
    diagram.GetInputPort("X_WH").FixValue(context, X_WH)
    assert diagram.GetOutputPort("X_WK_used").Eval(context).IsExactlyEqualTo(X_WH)
    with pytest.raises(ValueError, match="need a plant"):
        make_sustainable_coordination(info, 6, hand_frame=three_joint_arm().world_frame())
    with pytest.raises(ValueError, match="3 positions for num_joints = 6"):
        make_sustainable_coordination(info, 6, plant=three_joint_arm(),
                                      hand_frame=three_joint_arm().world_frame())  # fmt: skip
    babbling = HandEyeConfig(identifying_motion_interval=2.0)  # far postures: within which ranges?
    with pytest.raises(ValueError, match="the identifying motion needs joint_ranges .* or a plant"):
        make_sustainable_coordination(info, 6, hand_eye=babbling)
    assert make_sustainable_coordination(info, 6, hand_eye=replace(babbling, identifying_motion_interval=0.0))
    with pytest.raises(ValueError, match="joint_ranges has 5 rows for num_joints = 6"):
        make_sustainable_coordination(info, 6, hand_eye=babbling, joint_ranges=[[-1.0, 1.0]] * 5)
    for reach in (-0.3, float("nan")):
        with pytest.raises(ValueError, match="identifying_motion_reach must be >= 0 rad"):
            make_sustainable_coordination(info, 6, hand_eye=replace(babbling, identifying_motion_reach=reach),
                                          joint_ranges=[[-1.0, 1.0]] * 6)
    with_motion = make_sustainable_coordination(info, 6, hand_eye=babbling, joint_ranges=[[-1.0, 1.0]] * 6)
    assert with_motion.GetOutputPort("motion_confirm").size() == 2 + 6
    assert with_motion.GetSubsystemByName("identifying_motion") is not None


def test_hand_pose_from_a_plant_with_other_bodies_reads_the_arm_instance_only():
    plant = MultibodyPlant(0.0)
    arm = Parser(plant).AddModelsFromUrl("package://drake/examples/acrobot/Acrobot.sdf")[0]
    plant.AddRigidBody("loose_box", plant.AddModelInstance("objects"),
                       SpatialInertia(1.0, np.zeros(3), UnitInertia.SolidBox(0.1, 0.1, 0.1)))  # fmt: skip
    plant.Finalize()
    assert plant.num_positions() == 9  # the arm's 2 and a free body's 7
    sensor = plant.GetBodyByName("upper_link").body_frame()
    fk = HandPoseFromPlant(plant, plant.GetBodyByName("lower_link").body_frame(), sensor, model_instance=arm)
    assert fk.get_input_port().size() == 2
    context = fk.CreateDefaultContext()
    q = np.array([0.4, -0.9])
    fk.get_input_port().FixValue(context, q)
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, arm, q)
    expected = plant.GetBodyByName("lower_link").EvalPoseInWorld(plant_context)
    assert fk.GetOutputPort("X_WH").Eval(context).IsNearlyEqualTo(expected, 1e-12)
    assert fk.GetOutputPort("X_WK").Eval(context).IsNearlyEqualTo(
        plant.GetBodyByName("upper_link").EvalPoseInWorld(plant_context), 1e-12)
    # The hand's parent link: the body its (elbow) joint turns it on.
    assert fk.GetOutputPort("X_WL").Eval(context).IsNearlyEqualTo(
        plant.GetBodyByName("upper_link").EvalPoseInWorld(plant_context), 1e-12)
    # A new input is a new pose (the cached plant context follows it).
    fk.get_input_port().FixValue(context, np.zeros(2))
    assert not fk.GetOutputPort("X_WH").Eval(context).IsNearlyEqualTo(expected, 1e-6)
    with pytest.raises(ValueError, match="finalized"):
        HandPoseFromPlant(MultibodyPlant(0.0), plant.world_frame())


def test_the_camera_motion_detector_is_optional_and_exported():
    """``hand_eye.camera_motion`` adds the camera-motion detector (fed by the same joint
    positions as the coincidence detector) and its ``camera_motion`` output; off, neither."""
    info = CameraInfo(160, 120, 1.0)
    off = HandEyeConfig(identifying_motion_interval=0.0, camera_motion=False)
    assert not make_sustainable_coordination(info, 6, hand_eye=off).HasOutputPort("camera_motion")
    config = HandEyeConfig(identifying_motion_interval=0.0)
    assert config.camera_motion  # the measured configuration's default
    diagram = make_sustainable_coordination(info, 6, hand_eye=config)
    context = diagram.CreateDefaultContext()
    diagram.GetInputPort("color_image").FixValue(context, ImageRgba8U(160, 120))
    diagram.GetInputPort("depth_image").FixValue(context, ImageDepth32F(160, 120))
    diagram.GetInputPort("joint_positions").FixValue(context, np.zeros(6))
    diagram.GetInputPort("joint_velocities").FixValue(context, np.zeros(6))
    diagram.GetInputPort("X_WH").FixValue(context, RigidTransform())
    diagram.GetInputPort("wrench").FixValue(context, np.zeros(6))
    simulator = Simulator(diagram, context)
    simulator.AdvanceTo(0.2)  # blank frames: nothing tracked, nothing moves
    assert list(diagram.GetOutputPort("camera_motion").Eval(context)) == [0.0, 0.0]
    camera = diagram.GetSubsystemByName("camera_motion_detector")
    assert camera.GetInputPort("actuator_positions").size() == 6


def _body_changes_source(diagram) -> str | None:
    """The system and output port feeding the hand-eye state machine's ``body_changes`` (None:
    unconnected)."""
    machine = diagram.GetSubsystemByName("coordination_state_machine")
    index = machine.GetInputPort("body_changes").get_index()
    for (system, input_index), (source, output_index) in diagram.connection_map().items():
        if system is machine and input_index == index:
            return f"{source.get_name()}.{source.get_output_port(output_index).get_name()}"
    return None


def test_a_payload_change_is_a_hand_eye_slip_with_both_loops():
    """``hand_eye.slip_from_wrench`` (the default): with both loops, the payload loop's change
    detections (its state machine's ``reset`` count) feed the hand-eye state machine's
    ``body_changes``; off, or without the payload loop, nothing does."""
    info = CameraInfo(160, 120, 1.0)
    config = HandEyeConfig(identifying_motion_interval=0.0)
    assert config.slip_from_wrench
    both = make_sustainable_coordination(info, 6, hand_eye=config)
    assert _body_changes_source(both) == "payload_coordination.reset"
    off = make_sustainable_coordination(info, 6, hand_eye=replace(config, slip_from_wrench=False))
    assert _body_changes_source(off) is None
    vision = make_sustainable_coordination(info, 6, hand_eye=config, loops=Loops(payload=False))
    assert _body_changes_source(vision) is None


def test_the_identifying_motion_takes_its_ranges_from_the_plant_limits():
    """With a plant and no ``joint_ranges``, the identifying motion (on by default) asks for
    postures within the plant's position limits narrowed by RANGE_MARGIN at each end."""
    plant = three_joint_arm()
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    ranges = joint_ranges_from_limits(plant)
    lo = np.where(np.isfinite(lower), lower, -np.pi)
    hi = np.where(np.isfinite(upper), upper, np.pi)
    np.testing.assert_allclose(ranges[:, 0], lo + RANGE_MARGIN * (hi - lo))
    np.testing.assert_allclose(ranges[:, 1], hi - RANGE_MARGIN * (hi - lo))
    assert np.all(ranges[:, 0] < ranges[:, 1])
    diagram = make_sustainable_coordination(CameraInfo(160, 120, 1.0), 3, plant=plant,
                                            hand_frame=plant.GetBodyByName("link3").body_frame())
    assert diagram.GetSubsystemByName("identifying_motion") is not None


def test_with_excite_and_a_plant_the_identifying_motion_chooses_from_the_candidates_statistic():
    """``hand_eye.excite`` with a plant: the candidates' ``motion_statistic`` feeds the identifying
    motion's ``statistic`` (its postures chosen for what they add); without a plant, or with it off
    (the default), the statistic is not connected and the farthest draw is asked for."""
    plant = three_joint_arm()
    arm = {"plant": plant, "hand_frame": plant.GetBodyByName("link3").body_frame()}
    info = CameraInfo(160, 120, 1.0)

    def fed(diagram) -> bool:
        motion = diagram.GetSubsystemByName("identifying_motion")
        candidates = diagram.GetSubsystemByName("candidate_identifiers")
        source = diagram.connection_map().get((motion, motion.GetInputPort("statistic").get_index()))
        return source == (candidates, candidates.GetOutputPort("motion_statistic").get_index())
    assert fed(make_sustainable_coordination(info, 3, hand_eye=HandEyeConfig(excite=True), **arm))
    assert not fed(make_sustainable_coordination(info, 3, **arm))
    assert not fed(make_sustainable_coordination(info, 3, hand_eye=HandEyeConfig(excite=True),
                                                 joint_ranges=[[-1.0, 1.0]] * 3))


def test_the_hands_parent_link_is_found_through_welds():
    """``parent_link``: our arm's gripper is welded to the last link (the wrist sensor), which the
    wrist roll turns on ``arm_link4``; a body welded to the world has the world as its parent."""
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModels(str(models_dir() / "arm.sdf"))
    inertia = SpatialInertia(1.0, np.zeros(3), UnitInertia.SolidBox(0.1, 0.1, 0.1))
    box = plant.AddRigidBody("welded_box", plant.AddModelInstance("objects"), inertia)
    plant.WeldFrames(plant.world_frame(), box.body_frame())
    plant.Finalize()
    assert parent_link(plant, plant.GetBodyByName("gripper")).name() == "arm_link4"
    assert parent_link(plant, plant.GetBodyByName("arm_link2")).name() == "arm_link1"
    assert parent_link(plant, box).index() == plant.world_body().index()
