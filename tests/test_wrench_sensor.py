"""The wrist wrench sensor: the documented sign convention, noise, bias, and the weight at rest."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource

from sustain_drake.station import build_station
from sustain_drake.station.scenario import Scenario, Touch
from sustain_drake.systems.wrench_sensor import WristWrenchSensor

G = 9.81


def sensor_diagram(forces, **kwargs):
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantValueSource(AbstractValue.Make(forces)))
    sensor = builder.AddSystem(WristWrenchSensor(**kwargs))
    builder.Connect(source.get_output_port(), sensor.get_input_port())
    builder.ExportOutput(sensor.get_output_port(), "wrench")
    return builder.Build()


def readings(diagram, n, period):
    simulator = Simulator(diagram)
    out = []
    for k in range(n):
        simulator.AdvanceTo((k + 0.5) * period)
        out.append(diagram.GetOutputPort("wrench").Eval(simulator.get_context()).copy())
    return np.array(out)


def test_reads_its_joints_reaction_torque_first_with_bias():
    forces = [SpatialForce([9, 9, 9], [9, 9, 9]), SpatialForce([1, 2, 3], [4, 5, 6])]
    bias = [0.1, 0.2, 0.3, -1, -2, -3]
    d = sensor_diagram(forces, joint_index=1, period=0.01, bias=bias)
    np.testing.assert_allclose(readings(d, 3, 0.01), [[1.1, 2.2, 3.3, 3, 3, 3]] * 3)


def test_noise_has_the_configured_spread_and_is_reproducible():
    forces = [SpatialForce(np.zeros(3), np.zeros(3))]
    kwargs = dict(joint_index=0, period=0.01, force_noise=0.02, torque_noise=0.0005, seed=4)
    a = readings(sensor_diagram(forces, **kwargs), 400, 0.01)
    b = readings(sensor_diagram(forces, **kwargs), 400, 0.01)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(a.std(axis=0), [0.0005] * 3 + [0.02] * 3, rtol=0.15)
    assert np.all(np.abs(a.mean(axis=0)) < 4 * np.array([0.0005] * 3 + [0.02] * 3) / 20)
    c = readings(sensor_diagram(forces, **{**kwargs, "seed": 5}), 400, 0.01)
    assert not np.allclose(a, c)


@pytest.mark.parametrize("kwargs", [
    dict(joint_index=0, period=0.0),
    dict(joint_index=0, period=0.01, force_noise=-1),
    dict(joint_index=0, period=0.01, bias=[0, 0, 0]),
    dict(joint_index=0, period=0.01, bias=[np.nan] * 6),
])
def test_rejects_bad_parameters(kwargs):
    with pytest.raises(ValueError):
        WristWrenchSensor(**kwargs)


def still_arm(tool: str) -> Scenario:
    s = Scenario()
    s.camera.rgb = s.camera.depth = s.camera.label = False
    s.distractor.enabled = False
    s.tool.model = tool
    s.motion.initial_posture = [0.4, 0.5, 1.0, 0.7, 0.9]  # a posture with K tilted
    s.motion.joint_ranges = [[q, q] for q in s.motion.initial_posture]
    return s


def rest_wrench(s: Scenario, t: float = 1.5):
    diagram = build_station(s)
    simulator = Simulator(diagram)
    simulator.AdvanceTo(t)
    ctx = simulator.get_context()

    def port(name):
        return diagram.GetOutputPort(name).Eval(ctx)

    # The arm is still (joint speeds ~0), so the wrench is the static weight.
    assert np.max(np.abs(port("joint_velocities"))) < 1e-3
    return port("wrench"), port("X_WH"), port


@pytest.mark.parametrize("tool", ["rod", "box", "none"])
def test_wrench_at_rest_is_the_outboard_weight(tool):
    wrench, X_WH, port = rest_wrench(still_arm(tool))
    tau_K, f_K = wrench[:3], wrench[3:]
    R_WK = X_WH.rotation()  # K = H for our sensor weld
    m_o = port("true_outboard_mass")[0]
    # The force the wrist applies on the gripper side holds it up: R_WK f_K = -m g_W.
    np.testing.assert_allclose(R_WK @ f_K, [0, 0, m_o * G], atol=5 * 0.02)
    # ... about K's origin, at the outboard centre of mass: tau_K = p_KCo x f_K.
    np.testing.assert_allclose(tau_K, np.cross(port("true_p_KCo"), f_K), atol=5 * 0.0005)
    # The held tool alone: mass and CoM documented separately.
    m_tool = port("true_tool_mass")[0]
    assert m_tool == {"rod": 0.1, "box": 0.6, "none": 0.0}[tool]
    # Gripper 0.25 kg + finger 0.05 kg + the tool (and its two 10 ug grip links).
    assert m_o == pytest.approx(0.3 + m_tool, abs=1e-4)


def test_held_box_weight_is_what_the_wrench_adds():
    """Subtracting the wrench without a tool leaves the box's weight at its CoM (what the
    payload identification estimates): f = m R_KW (0, 0, g), tau = p_KCm x f."""
    with_box, X_WH, port = rest_wrench(still_arm("box"))
    without, _, _ = rest_wrench(still_arm("none"))
    d = with_box - without
    R_WK = X_WH.rotation()
    np.testing.assert_allclose(R_WK @ d[3:], [0, 0, 0.6 * G], atol=5 * 0.02 * np.sqrt(2))
    np.testing.assert_allclose(d[:3], np.cross(port("true_p_KCm"), d[3:]), atol=0.004)


@pytest.mark.parametrize("tool", ["box", "none"])
def test_gripper_compensation_leaves_the_held_object_alone(tool):
    s = still_arm(tool)
    s.wrench_sensor.compensate_gripper = True
    wrench, X_WH, port = rest_wrench(s)
    f_K = wrench[3:]
    m_tool = port("true_tool_mass")[0]
    np.testing.assert_allclose(X_WH.rotation() @ f_K, [0, 0, m_tool * G], atol=5 * 0.02)
    np.testing.assert_allclose(wrench[:3], np.cross(port("true_p_KCm"), f_K),
                               atol=5 * 0.0005)


def test_a_touch_changes_the_wrench_by_the_touch_force():
    s = still_arm("box")
    s.wrench_sensor.force_noise = s.wrench_sensor.torque_noise = 0.0
    s.disturbances = [Touch(time=1.0, duration=1.0, p_TQ=[0.05, 0.03, 0.12], f_T=[0, 0, -3.0])]
    before, _, _ = rest_wrench(s, 0.9)
    during, X_WH, port = rest_wrench(s, 1.9)
    d = during - before
    # K = H, and the box frame T is the grasp frame (0.09 m along H's z, no slip).
    p_KQ = np.array([0.05, 0.03, 0.09 + 0.12])
    f_K = np.array([0, 0, -3.0])
    # The wrist holds the push: the reading changes by minus the touch wrench about K.
    np.testing.assert_allclose(d[3:], -f_K, atol=0.05)
    np.testing.assert_allclose(d[:3], -np.cross(p_KQ, f_K), atol=0.01)
    # The ground truth of the touch, for evaluating touch estimation.
    np.testing.assert_allclose(port("true_touch"), np.concatenate([[1.0], p_KQ, f_K]),
                               atol=1e-3)
    _, _, port_before = rest_wrench(s, 0.9)
    np.testing.assert_array_equal(port_before("true_touch"), np.zeros(7))
