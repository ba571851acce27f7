"""Kinesthetic coordination (§3.5, §4.4): the payload formulation against Drake's weld reaction, the
quasi-static gate, the touching program's keep-touching rule, the contact truth, touches on the
real table and the end-to-end experiment."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource, LogVectorOutput
from scipy.spatial.transform import Rotation

from sustain_drake.experiments import kinesthetic
from sustain_drake.identification import coordination
from sustain_drake.identification.batch import identify_payload
from sustain_drake.identification.payload import STANDARD_GRAVITY_W, PayloadIdentifier
from sustain_drake.identification.sustainable_identifier import ConvergenceCriteria
from sustain_drake.identification.touch import predicted_wrench
from sustain_drake.station import build_station, load_scenario
from sustain_drake.station.scenario import Scenario, TouchTarget
from sustain_drake.systems.contact_truth import centre_of_pressure
from sustain_drake.systems.quasi_static_gate import QuasiStaticGate
from sustain_drake.systems.touch_estimator import TouchEstimator
from sustain_drake.systems.touch_motion import KEEP, LIFT, PHASE_NAMES, PRESS, REST, TouchMotion, TouchPosture

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "diagrams" / "inertia_touch.yaml"

# Postures spread over the wrist's pitch and roll (gravity in K in all directions).
POSTURES = [[0.0, 0.6, 1.1, 0.5, 0.0], [0.3, 0.4, 1.3, -0.8, 1.2], [-0.4, 0.7, 0.9, 1.0, -1.5],
            [0.1, 0.3, 1.4, -0.2, 2.4], [0.0, 0.8, 1.2, 0.9, 0.7]]  # fmt: skip


def box_scenario(posture, compensate=True, noise=False) -> Scenario:
    """The box held still at ``posture`` (no camera, no person)."""
    s = Scenario()
    s.camera.rgb = s.camera.depth = s.camera.label = False
    s.distractor.enabled = False
    s.tool.model = "box"
    s.wrench_sensor.compensate_gripper = compensate
    if not noise:
        s.wrench_sensor.force_noise = s.wrench_sensor.torque_noise = 0.0
    s.motion.initial_posture = list(posture)
    s.motion.joint_ranges = [[q, q] for q in posture]
    return s


@pytest.mark.parametrize("compensate", [True, False], ids=["tool alone", "outboard"])
def test_payload_formulation_matches_the_weld_reaction_at_rest(compensate):
    wrenches, rotations, truth = [], [], []
    for posture in POSTURES:
        diagram = build_station(box_scenario(posture, compensate))
        simulator = Simulator(diagram)
        simulator.AdvanceTo(0.6)
        context = simulator.get_context()
        wrenches.append(diagram.GetOutputPort("wrench").Eval(context))
        rotations.append(diagram.GetOutputPort("X_WH").Eval(context).rotation().matrix())
        names = ("true_tool_mass", "true_p_KCm") if compensate else ("true_outboard_mass", "true_p_KCo")
        truth.append([diagram.GetOutputPort(n).Eval(context).copy() for n in names])
    criteria = ConvergenceCriteria(max_expected_rms=0.3, min_gap_ratio=10.0, max_ssd=None, min_samples=5)
    result = identify_payload(np.array(wrenches), np.array(rotations), criteria=criteria)
    assert result.verdict.converged
    mass = truth[0][0][0]
    assert mass == pytest.approx(0.6 if compensate else 0.9, abs=1e-4)  # + the 2 x 10 mg grip links
    assert result.mass == pytest.approx(mass, rel=1e-3)
    # The stiff grip sags by a fraction of a millimetre with the orientation: compare with the mean.
    p_true = np.mean([p for _, p in truth], axis=0)
    assert np.linalg.norm(result.p_KCm - p_true) < 5e-4
    # One posture alone cannot tell the CoM component along gravity: not converged.
    one = identify_payload(np.array(wrenches[:1] * 12), np.array(rotations[:1] * 12), criteria=criteria)
    assert not one.verdict.converged


def exact_payload(mass=0.6, p_KCm=(0.0, 0.0, 0.15)):
    ident = PayloadIdentifier()
    rng = np.random.default_rng(3)
    for _ in range(30):
        R = Rotation.random(random_state=rng).as_matrix()
        ident.add(predicted_wrench(mass, np.asarray(p_KCm), R, STANDARD_GRAVITY_W), R)
    solution = ident.solve()
    assert solution.verdict.converged
    return solution


def add_estimator(builder, station, min_force):
    """A TouchEstimator on the station's wrench with the box's payload injected (adopted)."""
    shape, X_KG = kinesthetic.held_shape(station)
    estimator = builder.AddSystem(TouchEstimator(shape, X_KG, min_force=min_force))
    builder.Connect(station.GetOutputPort("wrench"), estimator.GetInputPort("wrench"))
    builder.Connect(station.GetOutputPort("X_WH"), estimator.GetInputPort("X_WK"))
    payload = builder.AddSystem(ConstantValueSource(AbstractValue.Make(exact_payload())))
    builder.Connect(payload.get_output_port(), estimator.GetInputPort("payload"))
    sigma = builder.AddSystem(ConstantVectorSource([0.3]))  # ~ the experiment's allowable error
    builder.Connect(sigma.get_output_port(), estimator.GetInputPort("allowable_error"))
    return estimator


def test_held_shape_comes_from_the_scene():
    station = build_station(box_scenario(POSTURES[0]))
    shape, X_KG = kinesthetic.held_shape(station)
    assert (shape.width(), shape.depth(), shape.height()) == pytest.approx((0.2, 0.15, 0.12))
    # The box's centre: 0.09 m (grasp) + 0.06 m along the hand's z.
    np.testing.assert_allclose(X_KG.translation(), [0.0, 0.0, 0.15], atol=1e-9)


def test_no_false_touch_during_free_motion():
    s = load_scenario(SCENARIO)
    s.touch_motion.enabled = False
    s.motion.dwell = 0.0  # keep moving all the time, at the scenario's pace
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(s))
    estimator = add_estimator(builder, station, s.kinesthetic.min_touch_force)
    touch = LogVectorOutput(estimator.GetOutputPort("touch"), builder, 0.01)
    residual = LogVectorOutput(estimator.GetOutputPort("residual_wrench"), builder, 0.01)
    contact = LogVectorOutput(station.GetOutputPort("true_contact"), builder, 0.01)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(6.0)
    context = simulator.get_context()
    assert not np.any(contact.FindLog(context).data()[0])  # free motion: no contact at all
    log = residual.FindLog(context)
    # After the first 0.2 s (the arm settles from its initial state under gravity).
    forces = np.linalg.norm(log.data()[3:6, log.sample_times() >= 0.2], axis=0)
    # The arm really moves (the payload's inertia shows) but stays under the touch threshold.
    assert 0.1 < forces.max() < s.kinesthetic.min_touch_force
    touched = touch.FindLog(context)
    assert not np.any(touched.data()[0, touched.sample_times() >= 0.2])


def run_table_touch(target: TouchTarget, t_max: float):
    """The box touches the table at one target (the touching program started at once), with the
    payload injected, until it lifts (or ``t_max``); returns the logs of the estimator, the contact
    truth and the phase."""
    s = box_scenario(POSTURES[0], noise=True)
    tm = s.touch_motion
    tm.enabled, tm.targets, tm.start_delay, tm.repeat = True, [target], 0.0, False
    tm.approach_height, tm.descend_speed, tm.keep_touching = 0.01, 0.01, 1.0
    # Start just above the target (the touch postures are solved by the station).
    q_above = build_station(s).GetSubsystemByName("touch_motion").postures()[0].q_above
    s.motion.initial_posture = list(q_above)
    s.motion.joint_ranges = [[q, q] for q in q_above]
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(s))
    estimator = add_estimator(builder, station, 2.0)
    start = builder.AddSystem(ConstantVectorSource([1.0]))
    builder.Connect(start.get_output_port(), station.GetInputPort("touch_start"))
    builder.Connect(estimator.GetOutputPort("touch"), station.GetInputPort("touch_feedback"))
    logs = {name: LogVectorOutput(port, builder, 0.01) for name, port in (
        ("touch", estimator.GetOutputPort("touch")), ("p_WP", estimator.GetOutputPort("p_WP")),
        ("contact", station.GetOutputPort("true_contact")), ("phase", station.GetOutputPort("touch_phase")))}
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_context()
    phase = station.GetOutputPort("touch_phase")
    while context.get_time() < t_max and phase.Eval(station.GetMyContextFromRoot(context))[0] < LIFT:
        simulator.AdvanceTo(context.get_time() + 0.25)
    return {name: log.FindLog(context).data().T for name, log in logs.items()}


@pytest.mark.parametrize(("target", "reach"), [
    # The far face: the wrist's PD compliance tilts it, so the pressure gathers towards an edge.
    (TouchTarget([0.0, 0.0, 0.12], [0.0, 0.0, 1.0], [0.3, 0.0]), 0.125),
    (TouchTarget([0.1, 0.075, 0.12], [0.1, 0.075, 0.06], [0.4, 0.1]), 0.015),  # a corner
], ids=["face", "corner"])
def test_a_real_touch_on_the_table_is_located_and_kept(target, reach):
    logs = run_table_touch(target, 12.0)
    phase = logs["phase"][:, 0].astype(int)
    contact, touch = logs["contact"], logs["touch"][:, 0] > 0.5
    assert {PRESS, KEEP, LIFT} <= set(phase), [PHASE_NAMES[p] for p in set(phase)]
    assert logs["phase"][-1, 2] == 1 and logs["phase"][-1, 3] == 0  # one touch felt, none missed
    # Keep touching: touched (really and estimated) all through KEEP.
    keep = phase == KEEP
    assert keep.sum() >= 90 and np.all(contact[keep, 0] == 1.0) and np.all(touch[keep])
    strong = touch & (np.linalg.norm(contact[:, 4:7], axis=1) >= 5.0)
    assert strong.sum() > 50
    errors = np.linalg.norm(logs["p_WP"][strong] - contact[strong, 1:4], axis=1)
    assert np.median(errors) < 3e-3 and np.max(errors) < 1e-2
    # The true contact is on the table top (z = 0), on the touching face or at the corner.
    np.testing.assert_allclose(contact[keep, 3], 0.0, atol=2e-3)
    assert np.max(np.linalg.norm(contact[keep, 1:3] - target.p_WQ, axis=1)) < reach


def test_centre_of_pressure_of_a_flat_contact():
    # Four corners of a square patch on z = 0 pressed unevenly, with friction along x.
    points = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.1, 0.1, 0.0], [0.0, 0.1, 0.0]])
    normal_forces = np.array([1.0, 3.0, 2.0, 2.0])
    forces = np.column_stack([0.2 * normal_forces, np.zeros(4), normal_forces])
    p, f = centre_of_pressure(points, forces, np.tile([0.0, 0.0, 1.0], (4, 1)), normal_forces)
    expected = (normal_forces[:, None] * points).sum(axis=0) / normal_forces.sum()
    np.testing.assert_allclose(p, expected, atol=1e-12)
    np.testing.assert_allclose(f, forces.sum(axis=0))
    # One point: the point itself.
    p1, _ = centre_of_pressure(points[1:2], forces[1:2], [[0.0, 0.0, 1.0]], [3.0])
    np.testing.assert_allclose(p1, points[1])


class _Script:
    """A piecewise-constant vector source: values[k] from times[k]."""

    def __init__(self, times, values):
        from pydrake.systems.primitives import TrajectorySource
        from pydrake.trajectories import PiecewisePolynomial

        self.system = TrajectorySource(PiecewisePolynomial.ZeroOrderHold(times, np.array(values).T))


def gate_run(velocities_at, touch_at, t_end=3.0, **kwargs):
    times = np.arange(0.0, t_end + 0.01, 0.01)
    builder = DiagramBuilder()
    gate = builder.AddSystem(QuasiStaticGate(5, 0.01, **kwargs))
    v = builder.AddSystem(_Script(times, [velocities_at(t) for t in times]).system)
    touch = builder.AddSystem(_Script(times, [[touch_at(t)] for t in times]).system)
    builder.Connect(v.get_output_port(), gate.GetInputPort("joint_velocities"))
    builder.Connect(touch.get_output_port(), gate.GetInputPort("touch"))
    log = LogVectorOutput(gate.GetOutputPort("sample_valid"), builder, 0.01)
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(t_end)
    data = log.FindLog(simulator.get_context())
    return data.sample_times(), data.data()[0]


def test_quasi_static_gate_rule():
    # Moving until 1 s (0.1 rad/s), still after; touched from 2.0 s to 2.4 s.
    t, valid = gate_run(lambda t: [0.1 if t < 1.0 else 0.0] + [0.0] * 4,
                        lambda t: 1.0 if 2.0 <= t < 2.4 else 0.0, window=0.2, touch_holdoff=0.5)
    def at(time):
        return valid[np.searchsorted(t, time - 1e-9)]

    assert at(0.5) == 0 and at(1.1) == 0  # moving, then within the window
    assert at(1.3) == 1 and at(1.95) == 1
    assert at(2.1) == 0 and at(2.7) == 0  # touched, then the hold-off after it
    assert at(2.95) == 1
    # A touch that lasts longer than max_touch_duration is a change of the body: samples pass.
    t, valid = gate_run(lambda t: [0.0] * 5, lambda t: 1.0 if t >= 0.5 else 0.0, max_touch_duration=1.0)
    assert valid[np.searchsorted(t, 1.0)] == 0 and valid[np.searchsorted(t, 1.7)] == 1
    with pytest.raises(ValueError, match="QuasiStaticGate"):
        QuasiStaticGate(5, period=0.0)


def test_touch_motion_keeps_touching_once_felt():
    above, press, high = np.zeros(5), np.full(5, 0.1), np.full(5, -0.1)
    builder = DiagramBuilder()
    motion = builder.AddSystem(TouchMotion([TouchPosture(tuple(above), tuple(press), tuple(high))],
                                           descend_duration=4.0, keep_touching=1.5, press_extra=0.1,
                                           max_speed=1.0, start_delay=0.5, repeat=False,
                                           rest=0.3))  # fmt: skip
    babble = builder.AddSystem(ConstantVectorSource(np.zeros(10)))
    start = builder.AddSystem(ConstantVectorSource([1.0]))
    builder.Connect(babble.get_output_port(), motion.GetInputPort("babble_state"))
    builder.Connect(start.get_output_port(), motion.GetInputPort("start"))
    q_log = LogVectorOutput(motion.GetOutputPort("desired_state"), builder, 0.01)
    phase_log = LogVectorOutput(motion.GetOutputPort("phase"), builder, 0.01)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    motion_context = motion.GetMyContextFromRoot(context)
    # The touch input by hand: "felt" once the desired posture is 40 % of the way down.
    motion.GetInputPort("touch").FixValue(motion_context, [0.0])
    while context.get_time() < 12.0:
        simulator.AdvanceTo(context.get_time() + 0.01)
        q = motion.GetOutputPort("desired_state").Eval(motion_context)[0]
        motion.GetInputPort("touch").FixValue(motion_context, [1.0 if q >= 0.04 else 0.0])
    q = q_log.FindLog(context).data()[0]
    phases = phase_log.FindLog(context).data()
    names = [PHASE_NAMES[int(p)] for p in dict.fromkeys(phases[0])]
    assert names == ["PASS", "MOVE", "REST", "APPROACH", "DESCEND", "PRESS", "KEEP", "LIFT", "DONE"]
    assert np.sum(phases[0] == REST) * 0.01 == pytest.approx(0.3, abs=0.02)
    keep = phases[0] == KEEP
    # Pressed on by press_extra of the descent beyond where it was felt, and held there 1.5 s.
    assert np.all(np.abs(q[keep] - 0.05) < 0.002)
    assert keep.sum() * 0.01 == pytest.approx(1.5, abs=0.02)
    assert phases[2, -1] == 1 and phases[3, -1] == 0
    assert q[-1] == pytest.approx(-0.1)  # lifted to the retreat posture


def test_inertia_touch_end_to_end(tmp_path):
    """The scenario's first 20 s: identified, paused, and the first touch felt and located."""
    s = load_scenario(SCENARIO)
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(s))
    handle = kinesthetic.add_to_diagram(builder, station, s)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(20.0)
    metrics = kinesthetic.finish(handle, diagram, simulator.get_context(), tmp_path)
    assert [e["kind"] for e in metrics["events"]] == [coordination.CONVERGED]
    assert 3.0 < metrics["identification_time_s"] < 12.0
    assert metrics["mass_error_percent"] < 1.0 and metrics["com_error_mm"] < 2.0
    touch = metrics["touch"]
    assert touch["touches_felt"] >= 1 and touch["samples_scored"] > 100
    assert touch["median_mm"] < 5.0 and touch["false_touch_samples"] == 0
    assert (tmp_path / "kinesthetic_eigenvalues.png").stat().st_size > 10_000
    assert (tmp_path / "kinesthetic_touch_points.png").stat().st_size > 10_000


def test_touch_motion_hands_back_to_the_babbling_when_start_falls():
    above, press, high = np.zeros(5), np.full(5, 0.1), np.full(5, -0.1)
    builder = DiagramBuilder()
    motion = builder.AddSystem(TouchMotion([TouchPosture(tuple(above), tuple(press), tuple(high))],
                                           descend_duration=4.0, keep_touching=1.5, press_extra=0.1,
                                           max_speed=1.0, start_delay=0.0))  # fmt: skip
    babble = builder.AddSystem(ConstantVectorSource(np.concatenate([np.full(5, 0.3), np.zeros(5)])))
    builder.Connect(babble.get_output_port(), motion.GetInputPort("babble_state"))
    simulator = Simulator(builder.Build())
    context = motion.GetMyContextFromRoot(simulator.get_mutable_context())
    motion.GetInputPort("start").FixValue(context, [1.0])
    simulator.AdvanceTo(1.5)  # moving to the first posture, away from the babbling's 0.3 rad
    assert PHASE_NAMES[int(motion.GetOutputPort("phase").Eval(context)[0])] in ("MOVE", "APPROACH")
    motion.GetInputPort("start").FixValue(context, [0.0])  # identify again: back to babbling
    previous = motion.GetOutputPort("desired_state").Eval(context).copy()
    seen = set()
    while simulator.get_context().get_time() < 6.0:
        simulator.AdvanceTo(simulator.get_context().get_time() + 0.01)
        seen.add(PHASE_NAMES[int(motion.GetOutputPort("phase").Eval(context)[0])])
        now = motion.GetOutputPort("desired_state").Eval(context).copy()
        assert np.max(np.abs(now[:5] - previous[:5])) < 0.02  # no jump in the desired posture
        previous = now
    assert {"RELEASE", "HANDBACK", "PASS"} <= seen
    np.testing.assert_allclose(previous, np.concatenate([np.full(5, 0.3), np.zeros(5)]))


@pytest.mark.parametrize(("text", "words"), [
    ("kinesthetic: {enabled: true}\n", "tool.model: box"),
    ("tool: {model: box}\nkinesthetic: {enabled: true, period: 0}\n", "kinesthetic"),
    ("tool: {model: box}\ntouch_motion: {enabled: true}\n", "targets"),
    ("tool: {model: box}\ntouch_motion: {enabled: true, targets: [{p_WQ: [0.3]}]}\n", "p_WQ"),
    ("tool: {model: box}\ntouch_motion: {enabled: true, targets: [{p_WQ: [3.0, 0.0]}]}\n", "reach"),
])
def test_kinesthetic_scenario_errors_are_one_line(tmp_path, text, words):
    from sustain_drake.station import ScenarioError

    path = tmp_path / "bad.yaml"
    path.write_text("camera: {rgb: false, depth: false, label: false}\n" + text)
    with pytest.raises(ScenarioError) as error:
        build_station(load_scenario(path))
    assert words in str(error.value) and "\n" not in str(error.value)
