"""The second arm (issue 27, item 2): ``arm: {model: ur_arm}`` builds a six-joint arm with UR5e's
kinematics holding the same gripper; its flange is where UR5e's DH parameters put it; it babbles
within its ranges holding the tool; a scenario's motion lists must fit it; and the hand-eye
experiment runs on ``diagrams/second_arm.yaml``."""

from __future__ import annotations

import json
import runpy
from pathlib import Path

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from sustain_drake.experiments.run import simulate_file
from sustain_drake.station import ScenarioError, build_station, camera_info, load_scenario, models_dir
from sustain_drake.station.build import sensor_pose_in_hand
from sustain_drake.station.models import ARMS, make_parser, model_file
from sustain_drake.station.scenario import Scenario, arm_motion, scenario_text
from sustain_drake.station.scenario_files import load_scenario_string

ROOT = Path(__file__).resolve().parents[1]
SECOND_ARM = ROOT / "diagrams" / "second_arm.yaml"
UR = ARMS["ur_arm"]
# UR5e's DH parameters (Universal Robots): d (m), a (m), alpha (rad) per joint.
DH_D = (0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996)
DH_A = (0.0, -0.425, -0.3922, 0.0, 0.0, 0.0)
DH_ALPHA = (np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0)


def ur_scenario(**motion) -> Scenario:
    """The default world on the second arm, without camera or person (fast)."""
    s = Scenario()
    s.arm.model = "ur_arm"
    s.camera.rgb = s.camera.depth = s.camera.label = False
    s.distractor.enabled = False
    for key, value in motion.items():
        setattr(s.motion, key, value)
    return s


def dh_flange(q_ur) -> np.ndarray:
    """The flange frame in the base frame from UR5e's DH parameters (4 x 4)."""
    X = np.eye(4)
    for theta, d, a, alpha in zip(q_ur, DH_D, DH_A, DH_ALPHA, strict=True):
        ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
        X = X @ np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                          [0, sa, ca, d], [0, 0, 0, 1]])
    return X


@pytest.fixture(scope="module")
def arm_alone():
    """ur_arm.sdf alone, its base at the world origin: (plant, context, joints)."""
    plant = MultibodyPlant(0.0)
    arm = make_parser(plant).AddModels(model_file(UR.file))[0]
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(UR.base_frame, arm))
    plant.Finalize()
    return plant, plant.CreateDefaultContext(), [plant.GetJointByName(j, arm) for j in UR.joints]


def test_ur_arm_sdf_is_its_generators_output():
    generator = runpy.run_path(str(models_dir() / "generate_ur_arm.py"), run_name="generate_ur_arm")
    assert (models_dir() / "ur_arm.sdf").read_text(encoding="utf-8") == generator["sdf_text"](), \
        "run python models/generate_ur_arm.py"


def test_the_station_builds_the_second_arm_with_six_joints_and_the_same_gripper():
    station = build_station(ur_scenario())
    plant = station.GetSubsystemByName("plant")
    arm = plant.GetModelInstanceByName("ur_arm")
    assert not plant.HasModelInstanceNamed("arm")
    revolute = [plant.get_joint(j).name() for j in plant.GetJointIndices(arm)
                if plant.get_joint(j).type_name() == "revolute"]
    assert tuple(revolute) == UR.joints == (
        "shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
        "wrist_3_joint")
    context = station.CreateDefaultContext()
    assert station.GetOutputPort("joint_positions").Eval(context).shape == (6,)
    assert station.GetOutputPort("joint_velocities").Eval(context).shape == (6,)
    np.testing.assert_allclose(station.GetOutputPort("joint_positions").Eval(context), UR.initial_posture)
    # The same gripper as the first arm's, on the F/T weld at the flange: K = H exactly.
    assert plant.GetJointByName("ft_sensor").child_body().name() == UR.hand_body == "gripper"
    assert plant.GetJointByName("ft_sensor").parent_body().name() == "wrist_3_link"
    assert sensor_pose_in_hand(station).IsExactlyIdentity()
    for name in ("gripper", "gripper_finger"):
        assert plant.GetBodyByName(name, arm).default_mass() == pytest.approx(
            {"gripper": 0.25, "gripper_finger": 0.05}[name])
    mass = sum(plant.get_body(b).default_mass() for b in plant.GetBodyIndices(arm))
    assert 15.0 <= mass <= 20.0
    for joint in (plant.GetJointByName(j, arm) for j in UR.joints):
        assert joint.position_lower_limits()[0] < 0 < joint.position_upper_limits()[0]
        assert joint.default_damping() > 0


def test_the_flange_is_where_ur5es_dh_parameters_put_it(arm_alone):
    plant, context, joints = arm_alone
    flange = plant.GetFrameByName("flange")

    def X_BF(q):
        for joint, angle in zip(joints, q, strict=True):
            joint.set_angle(context, angle)
        return flange.CalcPoseInWorld(context)

    # Straight up: the shoulder's height, the upper arm and the forearm, the wrist's second offset
    # towards -x, the lateral offset towards -y, the flange facing up.
    X = X_BF(np.zeros(6))
    np.testing.assert_allclose(X.translation(), [-0.0997, -0.1333, 0.1625 + 0.425 + 0.3922 + 0.0996],
                               atol=1e-12)
    np.testing.assert_allclose(X.rotation().matrix()[:, 2], [0, 0, 1], atol=1e-12)
    # Anywhere: UR5e's DH chain with this model's joint zeros and directions.
    for q in np.random.default_rng(0).uniform(-3.0, 3.0, (20, 6)):
        q_ur = [q[0], -q[1] - np.pi / 2, -q[2], -q[3], q[4] + np.pi / 2, q[5]]
        expected, X = dh_flange(q_ur), X_BF(q)
        np.testing.assert_allclose(X.translation(), expected[:3, 3], atol=1e-12)
        np.testing.assert_allclose(X.rotation().matrix()[:, 2], expected[:3, 2], atol=1e-12)


def test_a_short_run_holds_the_tool_and_stays_within_the_ranges():
    s = ur_scenario(max_speed=1.0)
    ranges = np.array(arm_motion(s).joint_ranges)
    np.testing.assert_array_equal(ranges, UR.joint_ranges)  # the arm's own defaults
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(s))
    loggers = {name: LogVectorOutput(station.GetOutputPort(name), builder, 0.01)
               for name in ("joint_positions", "true_p_HP")}
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(4.0)
    q, p_HP = (loggers[n].FindLog(simulator.get_context()).data().T for n in ("joint_positions", "true_p_HP"))
    assert np.all(q >= ranges[:, 0] - 0.005) and np.all(q <= ranges[:, 1] + 0.005)
    assert np.all(np.ptp(q, axis=0) > 0.05)  # every joint babbles
    # The rod's tip stays 0.09 + 0.25 m out along the gripper's approach axis.
    np.testing.assert_allclose(p_HP, np.tile([0.0, 0.0, 0.34], (len(p_HP), 1)), atol=5e-4)


@pytest.mark.parametrize("text, words", [
    ("arm: {model: ur_arm}\nmotion: {joint_ranges: [[0, 1], [0, 1], [0, 1], [0, 1], [0, 1]]}\n",
     "motion.joint_ranges needs 6 [lower, upper] pairs with lower <= upper (arm.model ur_arm has 6 joints)"),
    ("arm: {model: ur_arm}\nmotion: {initial_posture: [0, 0.6, 1.1, 0.5, 0.1]}\n",
     "motion.initial_posture needs 6 angles, got 5 (arm.model ur_arm has 6 joints)"),
    ("motion: {initial_posture: [0, 0, 0, 0, 0, 0]}\n", "motion.initial_posture needs 5 angles, got 6"),
    ("arm: {model: katana}\n", "arm.model must be one of arm, ur_arm"),
])
def test_motion_lists_that_do_not_fit_the_arm_are_one_line_errors(text, words):
    with pytest.raises(ScenarioError) as error:
        load_scenario_string(text)
    assert words in str(error.value) and "\n" not in str(error.value)


def test_the_arms_own_defaults_apply_unless_the_scenario_sets_them():
    s = load_scenario_string("arm: {model: ur_arm}\nmotion: {initial_posture: [0, 0.3, 1.5, 1.2, 0, 0]}\n")
    m = arm_motion(s)
    assert m.joint_ranges == [list(r) for r in UR.joint_ranges]
    assert m.initial_posture == [0, 0.3, 1.5, 1.2, 0, 0]
    # A run's scenario text holds what the arm used, and reads back the same.
    again = load_scenario_string(scenario_text(s))
    assert again.motion.joint_ranges == m.joint_ranges and again.motion.initial_posture == m.initial_posture
    first = Scenario()
    assert arm_motion(first) is first.motion


def test_touch_postures_are_solved_for_the_second_arm():
    s = ur_scenario()
    s.tool.model = "box"
    s.touch_motion.enabled = True
    s.touch_motion.targets = load_scenario(ROOT / "diagrams" / "inertia_touch.yaml").touch_motion.targets[:2]
    station = build_station(s)
    assert station.HasInputPort("touch_start") and station.HasOutputPort("touch_phase")


def test_the_hand_eye_experiment_runs_on_the_second_arm(tmp_path):
    scenario = load_scenario(SECOND_ARM)
    assert scenario.arm.model == "ur_arm" and scenario.tool.model == "rod"
    assert [type(e).__name__ for e in scenario.disturbances] == ["ToolSlip", "HeadMove"]
    result = simulate_file(SECOND_ARM, out=tmp_path / "out", duration=10.0, replay=False)
    metrics = json.loads(result.metrics.read_text())
    assert [d["kind"] for d in metrics["hand_eye"]["disturbances"]] == ["tool_slip", "head_move"]
    log = np.load(result.log)
    q, X_WH, X_WC, p_HP = (log[n] for n in ("joint_positions", "X_WH", "true_X_WC", "true_p_HP"))
    assert q.shape[1] == 6 and log["time"][-1] == pytest.approx(10.0, abs=0.02)
    ranges = np.array(scenario.motion.joint_ranges)
    assert np.all(q >= ranges[:, 0] - 0.005) and np.all(q <= ranges[:, 1] + 0.005)
    # The rod's tip stays in the camera's image all along (the camera's own placement and ranges).
    p_WP = np.einsum("nij,nj->ni", X_WH[:, :3, :3], p_HP) + X_WH[:, :3, 3]
    p_CP = np.einsum("nji,nj->ni", X_WC[:, :3, :3], p_WP - X_WC[:, :3, 3])
    info = camera_info(scenario)
    u = info.focal_x() * p_CP[:, 0] / p_CP[:, 2] + info.center_x()
    v = info.focal_y() * p_CP[:, 1] / p_CP[:, 2] + info.center_y()
    assert np.all(p_CP[:, 2] > 0.3)
    assert np.all((u > 0) & (u < info.width()) & (v > 0) & (v < info.height()))
