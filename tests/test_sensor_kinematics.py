"""The dynamic payload's systems (issue 26): the sensor frame's kinematics from a simulated plant and
from joint encoders against Drake's weld reaction, the dynamic loop in the coordination diagram and
in the inertia_touch experiment, and its payload YAML."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import (
    JacobianWrtVariable,
    PdControllerGains,
    RevoluteJoint,
    RotationalInertia,
    SpatialInertia,
    WeldJoint,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, MatrixGain, TrajectorySource, ZeroOrderHold
from pydrake.trajectories import PiecewisePolynomial

from sustain_drake.calibration_export import load_payload
from sustain_drake.experiments import kinesthetic
from sustain_drake.identification import coordination
from sustain_drake.identification import payload_dynamic as pd
from sustain_drake.loops import KinestheticConfig, Loops, make_sustainable_coordination
from sustain_drake.loops.identify_observe import CoordinationConfig
from sustain_drake.loops.payload import DynamicPayloadConfig, payload_formulation
from sustain_drake.station import build_station, load_scenario
from sustain_drake.systems.sensor_kinematics import SensorKinematicsFromEncoders, SensorKinematicsFromPlant
from sustain_drake.systems.sustainable_identifier_system import DynamicPayloadFormulation, PayloadFormulation
from sustain_drake.systems.wrench_sensor import WristWrenchSensor

ROOT = Path(__file__).resolve().parents[1]
PERIOD = 0.01
PAYLOAD = SpatialInertia.MakeFromCentralInertia(
    0.6, [0.02, -0.01, 0.08], RotationalInertia(0.0018, 0.0027, 0.0031, 0.0002, -0.0001, 0.0003))
AXES = ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])


def add_arm(plant, payload: bool):
    """Three revolute joints (z, x, y) under position servos; with ``payload``, a rigid payload welded
    at the hand through the sensor weld ``ft``. Returns the joints and the sensor frame."""
    link = SpatialInertia.SolidBoxWithMass(0.3, 0.05, 0.05, 0.05)
    parent, joints = plant.world_frame(), []
    for i, axis in enumerate(AXES):
        body = plant.AddRigidBody(f"link{i}", link)
        joint = plant.AddJoint(RevoluteJoint(f"joint{i}", parent, body.body_frame(), axis))
        plant.AddJointActuator(f"motor{i}", joint).set_controller_gains(PdControllerGains(p=200.0, d=10.0))
        joints.append(joint)
        parent = body.body_frame()
    sensor = parent
    if payload:
        body = plant.AddRigidBody("payload", PAYLOAD)
        sensor = plant.AddJoint(WeldJoint("ft", parent, body.body_frame(), RigidTransform())).frame_on_child()
    plant.Finalize()
    return joints, sensor


def trajectory(seed: int, duration: float, degree: int = 3) -> PiecewisePolynomial:
    """Smooth random joint motions: cubic splines through random postures every 0.5 s (or, with
    ``degree`` 3 and one segment, one cubic polynomial)."""
    rng = np.random.default_rng(seed)
    times = np.linspace(0.0, duration, int(duration / 0.5) + 1)
    postures = np.cumsum(rng.normal(0.0, 0.5, (3, times.size)), axis=1)
    return PiecewisePolynomial.CubicWithContinuousSecondDerivatives(times, postures, np.zeros(3), np.zeros(3))


def arm_world(seed: int, duration: float, time_step: float = 0.002, noise=(0.0, 0.0)):
    """The arm with its payload following ``trajectory(seed)``, its wrench sensor (``noise``: force and
    torque standard deviations), and the builder."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=time_step), builder)
    joints, sensor = add_arm(plant, payload=True)
    source = builder.AddSystem(TrajectorySource(trajectory(seed, duration), output_derivative_order=1))
    builder.Connect(source.get_output_port(), plant.get_desired_state_input_port(plant.GetModelInstanceByName(
        "DefaultModelInstance")))  # fmt: skip
    wrench = builder.AddSystem(WristWrenchSensor(plant.GetJointByName("ft").index(), PERIOD, *noise))
    builder.Connect(plant.get_reaction_forces_output_port(), wrench.GetInputPort("reaction_forces"))
    return builder, plant, joints, sensor, wrench


def phi_of_payload() -> np.ndarray:
    I = PAYLOAD.CalcRotationalInertia()  # noqa: E741 (about the weld's child frame = the payload's frame)
    return np.concatenate([[PAYLOAD.get_mass()], PAYLOAD.get_mass() * PAYLOAD.get_com(), I.get_moments(),
                           I.get_products()])  # fmt: skip


@pytest.mark.parametrize("time_step", [0.002, 0.0])
def test_plant_kinematics_explain_the_welds_reaction(time_step):
    """The weld's reaction force (``WristWrenchSensor``) is ``Y(kinematics_K) phi`` of the payload
    at every sample, discrete (the kinematics taken back to the step's start) or continuous."""
    builder, plant, _, sensor, wrench = arm_world(0, 3.0, time_step)
    kinematics = builder.AddSystem(SensorKinematicsFromPlant(plant, sensor, PERIOD))
    for name in ("body_poses", "body_spatial_velocities", "body_spatial_accelerations"):
        builder.Connect(getattr(plant, f"get_{name}_output_port")(), kinematics.GetInputPort(name))
    logs = [LogVectorOutput(port, builder, PERIOD) for port in (wrench.get_output_port(),
                                                               kinematics.get_output_port())]  # fmt: skip
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(3.0)
    # From 0.2 s on: the arm first jumps to the trajectory's start (accelerations of 1e3 rad/s^2).
    w, k = (log.FindLog(simulator.get_context()).data().T[20:] for log in logs)
    residual = w - np.array([pd.regressor(sample) @ phi_of_payload() for sample in k])
    assert np.abs(k[:, 3:6]).max() > 5.0  # the motion accelerates
    tolerance = 2e-5 if time_step else 1e-6
    assert np.abs(residual[:, :3]).max() < tolerance and np.abs(residual[:, 3:]).max() < 10 * tolerance


def test_encoder_kinematics_match_the_plants_at_the_window_centre():
    """Cubic joint motions (the filter is exact on them): the kinematics from the encoders are the
    plant's at the window's centre (or ``wrench_delay`` before it), and the wrench is that sample's."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
    joints, sensor = add_arm(plant, payload=False)
    coefficients = np.random.default_rng(1).normal(0.0, 1.0, (3, 4))
    q_of = lambda t: np.array([np.polyval(c, t) for c in coefficients])  # noqa: E731
    v_of = lambda t: np.array([np.polyval(np.polyder(c), t) for c in coefficients])  # noqa: E731
    motion = PiecewisePolynomial.CubicHermite([0.0, 2.0], np.column_stack([q_of(0.0), q_of(2.0)]),
                                              np.column_stack([v_of(0.0), v_of(2.0)]))  # fmt: skip
    source = builder.AddSystem(TrajectorySource(motion))
    wrench = builder.AddSystem(MatrixGain(np.vstack([np.eye(3), np.eye(3)])))  # a "wrench" that is q
    builder.Connect(source.get_output_port(), wrench.get_input_port())
    delay = 0.004
    encoders = builder.AddSystem(SensorKinematicsFromEncoders(plant, sensor, PERIOD, 11, 3, joints, delay))
    builder.Connect(source.get_output_port(), encoders.GetInputPort("joint_positions"))
    builder.Connect(wrench.get_output_port(), encoders.GetInputPort("wrench"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_context()
    encoders_context = encoders.GetMyContextFromRoot(context)
    simulator.AdvanceTo(0.055)  # readings at 0.00 .. 0.05: 6 of 11
    assert encoders.GetOutputPort("valid").Eval(encoders_context)[0] == 0.0
    simulator.AdvanceTo(1.0051)  # the last reading at 1.00: the centre at 0.95
    assert encoders.GetOutputPort("valid").Eval(encoders_context)[0] == 1.0
    centre = 0.95
    assert np.allclose(encoders.GetOutputPort("wrench_aligned").Eval(encoders_context)[:3], q_of(centre))
    t = centre - delay
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, q_of(t))
    plant.SetVelocities(plant_context, v_of(t))
    vdot = np.array([np.polyval(np.polyder(c, 2), t) for c in coefficients])
    world = plant.world_frame()
    kV, origin = JacobianWrtVariable.kV, np.zeros(3)
    J = plant.CalcJacobianSpatialVelocity(plant_context, kV, sensor, origin, world, world)
    bias = plant.CalcBiasSpatialAcceleration(plant_context, kV, sensor, origin, world, world)
    A = J @ vdot + bias.get_coeffs()
    V = J @ plant.GetVelocities(plant_context)
    R_WK = sensor.CalcRotationMatrixInWorld(plant_context).matrix()
    expected = pd.sensor_kinematics(R_WK, V[:3], A[:3], A[3:], plant.gravity_field().gravity_vector())
    assert np.allclose(encoders.GetOutputPort("kinematics_K").Eval(encoders_context), expected, atol=1e-8)


def test_the_dynamic_loop_in_the_coordination_diagram_identifies_the_payload():
    """``make_sustainable_coordination`` with ``kinesthetic.mode`` dynamic, fed by the arm's encoders
    (sampled with the wrench) and its wrist sensor (an ATI Mini40's noise), identifies the payload
    while the arm moves, and keeps observing it: no false change detection."""
    builder, plant, _, _, wrench = arm_world(2, 8.0, noise=(0.02, 0.0005))
    model = MultibodyPlant(0.0)  # the coordination's own model of the arm: no payload
    _, hand = add_arm(model, payload=False)
    # inertia_touch.yaml's criteria; noise_rms: sqrt(6) 0.02 N, the rows' noise (torque rows / 0.025 m)
    criteria = CoordinationConfig(max_expected_rms=0.3, min_gap_ratio=3000.0, noise_rms=0.05)
    config = KinestheticConfig(mode="dynamic", coordination=criteria,
                               dynamic=DynamicPayloadConfig(wrench_delay=plant.time_step()))  # fmt: skip
    loop = builder.AddSystem(make_sustainable_coordination(
        None, 3, loops=Loops(hand_eye=False, payload=True), kinesthetic=config, plant=model, hand_frame=hand))
    state = plant.get_state_output_port()
    hold = builder.AddSystem(ZeroOrderHold(PERIOD, 6))  # the encoders, read with the sampled wrench
    builder.Connect(state, hold.get_input_port())
    for name, rows in (("joint_positions", slice(0, 3)), ("joint_velocities", slice(3, 6))):
        pick = builder.AddSystem(MatrixGain(np.eye(6)[rows]))
        builder.Connect(hold.get_output_port(), pick.get_input_port())
        builder.Connect(pick.get_output_port(), loop.GetInputPort(name))
    builder.Connect(wrench.get_output_port(), loop.GetInputPort("wrench"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(8.0)
    context = loop.GetMyContextFromRoot(simulator.get_context())
    events = loop.GetOutputPort("payload_events").Eval(context)
    assert [e.kind for e in events] == [coordination.CONVERGED] and events[0].time < 6.0
    assert loop.GetOutputPort("payload_valid").Eval(context)[0] == 1.0
    assert loop.GetOutputPort("payload_mass").Eval(context)[0] == pytest.approx(0.6, rel=2e-3)
    assert np.allclose(loop.GetOutputPort("p_KCm").Eval(context), [0.02, -0.01, 0.08], atol=1e-3)
    assert np.all(np.isfinite(loop.GetOutputPort("payload_sd").Eval(context)))


def test_the_dynamic_coordination_needs_a_plant():
    with pytest.raises(ValueError, match="needs plant= and hand_frame="):
        make_sustainable_coordination(None, 3, loops=Loops(hand_eye=False), kinesthetic=KinestheticConfig(
            mode="dynamic"))  # fmt: skip


def test_the_station_reads_the_rigid_outboard_bodys_wrench():
    """In the station (noise-free, the grasp's joints locked): the wrench is the regressor of the
    outboard body's true parameters at the station's ``sensor_kinematics``, while the arm babbles."""
    s = load_scenario(ROOT / "diagrams" / "inertia_touch.yaml")
    s.touch_motion.enabled = s.kinesthetic.enabled = s.wrench_sensor.compensate_gripper = False
    s.wrench_sensor.force_noise = s.wrench_sensor.torque_noise = 0.0
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(s))
    logs = [LogVectorOutput(station.GetOutputPort(name), builder, PERIOD)
            for name in ("wrench", "sensor_kinematics", "true_outboard_inertia")]
    diagram = builder.Build()
    simulator = Simulator(diagram)
    plant = station.GetSubsystemByName("plant")
    plant_context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    for name in ("gripper_joint", "tool_slide", "tool_pivot"):
        plant.GetJointByName(name).Lock(plant_context)
    simulator.AdvanceTo(2.0)
    w, k, phi = (log.FindLog(simulator.get_context()).data().T[2:] for log in logs)
    residual = w - np.array([pd.regressor(k[i]) @ phi[i] for i in range(len(w))])
    assert np.abs(k[:, 3:6]).max() > 2.0 and phi[0, 0] == pytest.approx(0.9, abs=1e-3)
    assert np.abs(residual[:, :3]).max() < 2e-5 and np.abs(residual[:, 3:]).max() < 2e-4


def test_inertia_touch_in_the_dynamic_mode_writes_the_payload_with_its_inertia(tmp_path):
    s = load_scenario(ROOT / "diagrams" / "inertia_touch.yaml")
    s.kinesthetic.mode, s.wrench_sensor.compensate_gripper, s.touch_motion.enabled = "dynamic", False, False
    s.wrench_sensor.bias = [0.01, -0.02, 0.015, 0.3, -0.2, 0.4]
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(s))
    handle = kinesthetic.add_to_diagram(builder, station, s)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(8.0)
    metrics = kinesthetic.finish(handle, diagram, simulator.get_context(), tmp_path)
    assert [e["kind"] for e in metrics["events"]] == [coordination.CONVERGED]
    assert metrics["mass_error_percent"] < 0.5 and metrics["com_error_mm"] < 1.0
    dynamic = metrics["dynamic"]
    assert dynamic["bias_error_N"] < 0.05 and dynamic["bias_error_Nm"] < 0.002
    assert dynamic["inertia_error_percent"] < 30.0  # the compliant grasp; see docs/results.md
    assert metrics["payload_yaml"] == "payload.yaml"
    payload = load_payload((tmp_path / "payload.yaml").read_text())
    assert payload.mass == pytest.approx(metrics["mass_kg"]) and any(payload.I_BBcm)
    assert np.allclose(payload.I_BBcm, dynamic["I_BBcm"])


def test_the_static_mode_stays_the_default():
    """The payload loop is the static one unless asked: Eqs. (37)-(38) on quasi-static samples."""
    assert KinestheticConfig().mode == "static"
    assert isinstance(payload_formulation(KinestheticConfig()), PayloadFormulation)
    assert isinstance(payload_formulation(KinestheticConfig(mode="dynamic")), DynamicPayloadFormulation)
    with pytest.raises(ValueError, match="kinesthetic.mode must be one of static, dynamic"):
        payload_formulation(KinestheticConfig(mode="quasi"))
