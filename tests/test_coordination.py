"""The identify <-> observe rule (pure) and the identifier + state machine systems in a diagram."""

import math

import numpy as np
import pytest
from eye_to_hand_data import make_truth, rotation_error_deg
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from scipy.spatial.transform import Rotation

from sustain_drake.identification import coordination
from sustain_drake.identification.coordination import CoordinationRule
from sustain_drake.identification.coordination import IdentifierReport as Report
from sustain_drake.loops.identify_observe import connect_identify_observe
from sustain_drake.systems.coordination_state_machine import CoordinationStateMachine
from sustain_drake.systems.sustainable_identifier_system import (
    EyeToHandFormulation,
    SustainableIdentifierSystem,
)

RULE = CoordinationRule()


def run_rule(signals, state=None):
    """signals: (converged, expected_mse, sample_count, sample_error) per tick."""
    state = coordination.initial_state() if state is None else state
    events = []
    for k, (conv, mse, count, err) in enumerate(signals):
        state, event = coordination.step(state, RULE, k * 0.1, Report(conv, mse, count, err))
        if event:
            events.append(event)
    return state, events


def test_converges_then_observes():
    state, events = run_rule([(False, 1.0, 1, 0.0), (False, 1.0, 2, 0.0), (True, 1e-6, 3, 0.0)])
    assert [e.kind for e in events] == [coordination.CONVERGED]
    assert events[0].time == pytest.approx(0.2)
    assert state[coordination.MODE] == coordination.OBSERVE
    assert state[coordination.SIGMA] == pytest.approx(100 * 1e-6)  # the paper's 100 lambda
    assert state[coordination.PAUSE_ID] == 1


def observing_state():
    state, _ = run_rule([(True, 1e-6, 1, 0.0)])
    return state


def test_nine_violations_do_nothing_ten_switch():
    over = 2e-4  # > sigma = 1e-4
    state, events = run_rule([(True, 1e-6, 2 + k, over) for k in range(9)], observing_state())
    assert not events and state[coordination.MODE] == coordination.OBSERVE
    assert state[coordination.VIOLATIONS] == 9
    state, events = run_rule([(True, 1e-6, 11, over)], state)
    assert [e.kind for e in events] == [coordination.CHANGE_DETECTED]
    assert state[coordination.MODE] == coordination.IDENTIFY
    assert state[coordination.RESET_COUNT] == 1


def test_a_good_sample_clears_the_count_and_repeated_ticks_count_once():
    over, ok = 2e-4, 5e-5
    signals = [(True, 1e-6, 2 + k, over) for k in range(9)] + [(True, 1e-6, 11, ok)]
    signals += [(True, 1e-6, 12 + k, over) for k in range(9)]
    state, events = run_rule(signals, observing_state())
    assert not events and state[coordination.VIOLATIONS] == 9
    # The same sample seen on 5 more ticks (no new sample): not counted again.
    state, events = run_rule([(True, 1e-6, 20, over)] * 5, state)
    assert not events and state[coordination.VIOLATIONS] == 9


def test_the_sensor_noise_floors_the_allowable_error():
    """Near noise-free data: a^2 lambda_N is round-off (1e-20 m^2); without a floor every sample
    would violate. With the sensor's noise (1 mm) as the floor, sigma = 100 (1 mm)^2."""
    rule = CoordinationRule(noise_rms=1e-3)
    state, event = coordination.step(coordination.initial_state(), rule, 0.0, Report(True, 1e-20, 1, 0.0))
    assert event.kind == coordination.CONVERGED
    assert state[coordination.SIGMA] == pytest.approx(100 * 1e-6)
    assert coordination.allowable_error(rule, 1e-20) == pytest.approx(1e-4)
    assert coordination.allowable_error(rule, 4e-6) == pytest.approx(4e-4)  # above the floor: the paper's
    assert coordination.allowable_error(RULE, 1e-20) == pytest.approx(1e-18)  # no floor: the paper's rule
    for k in range(20):  # 5 mm per sample: noise, not a change
        state, event = coordination.step(state, rule, 0.1 * (k + 1), Report(True, 1e-20, 2 + k, 25e-6))
        assert event is None
    assert state[coordination.MODE] == coordination.OBSERVE


def test_a_refinement_is_adopted_in_observe_only_when_the_rule_says_so():
    """``adopt_refinements``: a converged solution with a higher refinement counter replaces the
    adopted one in OBSERVE (a REFINED event, sigma recomputed, the mode stays); the paper's rule
    (the default) keeps the model fixed."""
    for adopt in (True, False):
        rule = CoordinationRule(adopt_refinements=adopt)
        state, _ = coordination.step(coordination.initial_state(), rule, 0.0, Report(True, 4e-6, 1, 0.0))
        state, _ = coordination.step(state, rule, 0.1, Report(True, 4e-6, 2, 5e-4))  # one violation
        state, event = coordination.step(state, rule, 0.2, Report(True, 1e-6, 3, 0.0, refinement=1))
        assert state[coordination.MODE] == coordination.OBSERVE
        if adopt:
            assert event.kind == coordination.REFINED and event.time == pytest.approx(0.2)
            assert state[coordination.SIGMA] == pytest.approx(1e-4) and state[coordination.VIOLATIONS] == 0
            # The same refinement again, or a solution that is not converged: nothing.
            state, event = coordination.step(state, rule, 0.3, Report(True, 1e-6, 4, 0.0, refinement=1))
            assert event is None
            state, event = coordination.step(state, rule, 0.4, Report(False, 1e-6, 5, 0.0, refinement=2))
            assert event is None
        else:
            assert event is None and state[coordination.SIGMA] == pytest.approx(4e-4)


def test_rule_validation():
    with pytest.raises(ValueError, match="noise_rms"):
        CoordinationRule(noise_rms=-1e-3)
    with pytest.raises(ValueError, match="max_consecutive_violations"):
        CoordinationRule(max_consecutive_violations=0)
    with pytest.raises(ValueError, match="allowable_error_factor"):
        CoordinationRule(allowable_error_factor=float("nan"))


class ScriptedHandPoint(LeafSystem):
    """A hand moving to a new random pose every tick and a point on it seen by a fixed camera,
    with 1 mm noise; the point moves on the hand (a slip) at ``t_slip``."""

    def __init__(self, truth, p_HP_after, t_slip, period):
        super().__init__()
        self._truth, self._after, self._t_slip, self._period = truth, p_HP_after, t_slip, period
        self.DeclareVectorOutputPort("p_CP", 3, self._calc_p)
        self.DeclareAbstractOutputPort("X_WH", lambda: AbstractValue.Make(RigidTransform()), self._calc_X)

    def _pose(self, context):
        k = int(round(context.get_time() / self._period))
        rng = np.random.default_rng([7, k])
        R = Rotation.random(random_state=rng).as_matrix()
        p = rng.uniform(-0.3, 0.3, 3) + [0.4, 0.0, 0.3]
        return R, p, rng

    def _calc_X(self, context, output):
        R, p, _ = self._pose(context)
        output.set_value(RigidTransform(np.vstack([np.column_stack([R, p]), [0, 0, 0, 1]])))

    def _calc_p(self, context, output):
        R, p, rng = self._pose(context)
        p_HP = self._truth.p_HP if context.get_time() < self._t_slip else self._after
        p_W = R @ p_HP + p
        X_WC = self._truth.X_WC
        output.SetFromVector(X_WC[:3, :3].T @ (p_W - X_WC[:3, 3]) + rng.normal(0, 1e-3, 3))


def build(t_slip, period=0.1):
    truth = make_truth(21)
    builder = DiagramBuilder()
    source = builder.AddSystem(ScriptedHandPoint(truth, truth.p_HP + [0.03, -0.02, 0.01], t_slip, period))
    ident = builder.AddSystem(SustainableIdentifierSystem(EyeToHandFormulation(), period=period))
    sm = builder.AddSystem(CoordinationStateMachine(16, period=period))
    builder.Connect(source.GetOutputPort("p_CP"), ident.GetInputPort("p_CP"))
    builder.Connect(source.GetOutputPort("X_WH"), ident.GetInputPort("X_WH"))
    connect_identify_observe(builder, ident, sm)
    diagram = builder.Build()
    return truth, diagram, ident, sm


def test_loop_converges_detects_a_slip_and_reconverges():
    truth, diagram, ident, sm = build(t_slip=8.0)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    simulator.AdvanceTo(7.9)
    sm_context = sm.GetMyContextFromRoot(context)
    events = sm.events(sm_context)
    assert [e.kind for e in events] == [coordination.CONVERGED]
    assert events[0].time < 3.0  # 10 samples at 10 Hz minimum; well-spread poses converge fast
    adopted = sm.GetOutputPort("adopted_solution").Eval(sm_context)
    assert rotation_error_deg(adopted.estimate.R_WC, truth.X_WC[:3, :3]) < 0.5
    assert np.linalg.norm(adopted.estimate.p_WC - truth.X_WC[:3, 3]) < 5e-3
    # Cloned contexts are independent (all state is in the context).
    clone = context.Clone()
    simulator.AdvanceTo(15.0)
    events = sm.events(sm_context)
    kinds = [e.kind for e in events]
    assert kinds == [coordination.CONVERGED, coordination.CHANGE_DETECTED, coordination.CONVERGED]
    assert 8.0 < events[1].time <= 8.0 + 11 * 0.1 + 1e-9  # ten samples over the limit
    new = sm.GetOutputPort("adopted_solution").Eval(sm_context).estimate
    assert np.linalg.norm(new.p_HP - (truth.p_HP + [0.03, -0.02, 0.01])) < 5e-3
    assert len(sm.events(sm.GetMyContextFromRoot(clone))) == 1
    assert sm.GetOutputPort("pause").Eval(sm_context)[0] == 2  # one pause request per convergence


def test_while_observing_the_identifier_solves_nothing_until_read(monkeypatch):
    """The identifier's solution is a cache entry of its statistic and the state machine reads it
    only while identifying: after the convergence, samples keep arriving and nothing is solved;
    a read then solves once, the same solution as a fresh identifier's from the statistic."""
    solves = []
    original = EyeToHandFormulation.solve
    monkeypatch.setattr(EyeToHandFormulation, "solve",
                        lambda self, identifier: solves.append(1) or original(self, identifier))
    truth, diagram, ident, sm = build(t_slip=100.0)
    simulator = Simulator(diagram)
    simulator.AdvanceTo(4.0)
    sm_context = sm.GetMyContextFromRoot(simulator.get_context())
    assert [e.kind for e in sm.events(sm_context)] == [coordination.CONVERGED]
    before = len(solves)
    simulator.AdvanceTo(7.0)  # 30 more samples, observed
    assert len(solves) == before
    ident_context = ident.GetMyContextFromRoot(simulator.get_context())
    assert ident.GetOutputPort("verdict").Eval(ident_context)[1] > 60  # the samples went in
    assert len(solves) == before + 1
    x = ident.GetOutputPort("x").Eval(ident_context)
    assert len(solves) == before + 1  # one solve serves every output
    fresh = EyeToHandFormulation().make_identifier()
    fresh.set_state(ident.GetOutputPort("statistic").Eval(ident_context))
    np.testing.assert_array_equal(x, original(EyeToHandFormulation(), fresh).x)


def test_a_stale_solution_after_a_detection_is_not_adopted():
    # The identifier applies the reset one update after the detection: the solution seen on the
    # next tick is still the old converged one (500 samples), and must not be adopted again.
    over = 2e-4
    state, events = run_rule([(True, 1e-6, 2 + k, over) for k in range(10)], observing_state())
    assert [e.kind for e in events] == [coordination.CHANGE_DETECTED]
    detected_at = 11
    for k in range(1, 4):
        state, event = coordination.step(state, RULE, 2.0 + k, Report(True, 1e-6, detected_at + k, 0.0, 500))
        assert event is None and state[coordination.MODE] == coordination.IDENTIFY
    # A fresh solution (its samples all came after the detection) is adopted.
    state, event = coordination.step(state, RULE, 6.0, Report(True, 1e-6, detected_at + 20, 0.0, 12))
    assert event.kind == coordination.CONVERGED and state[coordination.MODE] == coordination.OBSERVE


def test_a_camera_move_is_a_change_detection_and_keeps_the_identifier_reset_while_it_lasts():
    """The camera-motion input (beyond the paper): a new move in OBSERVE is the rule's change
    detection; while the camera moves every tick resets the identifier and nothing is adopted;
    a move while identifying resets too; a constant count changes nothing."""
    state = observing_state()
    ok = 1e-6  # well within sigma = 1e-4
    # Moves count constant (0): the paper's rule, as without the input.
    same, events = state, []
    for k in range(5):
        same, event = coordination.step(same, RULE, 0.1 * k, Report(True, 1e-6, 2 + k, ok), camera_moves=0)
        events += [event] if event else []
    assert not events and same[coordination.MODE] == coordination.OBSERVE
    # A new move: detected at once, with its time, like the rule's detection.
    state, event = coordination.step(same, RULE, 1.0, Report(True, 1e-6, 7, ok),
                                     camera_moving=True, camera_moves=1)
    assert event.kind == coordination.CHANGE_DETECTED and event.time == pytest.approx(1.0)
    assert event.detail == coordination.CAMERA_MOVED_DETAIL
    assert state[coordination.MODE] == coordination.IDENTIFY and state[coordination.RESET_COUNT] == 1
    assert state[coordination.DETECTIONS] == 1
    # While it moves: reset on every tick, a converged (fresh) solution is not adopted.
    for k in range(3):
        state, event = coordination.step(state, RULE, 1.1 + 0.1 * k, Report(True, 1e-6, 8 + k, ok, 1),
                                         camera_moving=True, camera_moves=1)  # fmt: skip
        assert event is None and state[coordination.RESET_COUNT] == 2 + k
        assert state[coordination.MODE] == coordination.IDENTIFY
    # At rest: the next fresh converged solution is adopted; a stale one (samples from before) not.
    state, event = coordination.step(state, RULE, 1.5, Report(True, 1e-6, 11, ok, 5), camera_moves=1)
    assert event is None  # 5 samples, but only 1 arrived since the last reset
    state, event = coordination.step(state, RULE, 1.6, Report(True, 1e-6, 12, ok, 2), camera_moves=1)
    assert event.kind == coordination.CONVERGED and state[coordination.RESET_COUNT] == 4
    # A move while identifying: reset and detected too (a half-identified model is stale).
    state, _ = coordination.step(coordination.initial_state(), RULE, 0.0, Report(False, 1.0, 1, 0.0),
                                 camera_moves=0)
    state, event = coordination.step(state, RULE, 0.1, Report(False, 1.0, 2, 0.0),
                                     camera_moving=True, camera_moves=1)
    assert event.kind == coordination.CHANGE_DETECTED and state[coordination.RESET_COUNT] == 1


def test_a_move_found_after_the_observations_reset_for_it_is_that_resets_change():
    """``camera_move_start`` (beyond the paper): a move declared late (the camera at rest again) that
    began before the observation rule's reset, with no convergence since, changes that reset's
    reason to a camera move in place: no event, no new reset, the identification under way goes on.
    A move that began after the reset, one still moving, or one after a convergence is a change."""
    over = 2e-4
    failed, events = run_rule([(True, 1e-6, 2 + k, over) for k in range(10)], observing_state())
    assert [e.kind for e in events] == [coordination.CHANGE_DETECTED]
    assert failed[coordination.RESET_REASON] == coordination.OBSERVATION_FAILED
    reset_at, resets = failed[coordination.RESET_TIME], failed[coordination.RESET_COUNT]
    assert np.isfinite(reset_at)
    idle = Report(False, 1.0, 40, 0.0)
    found, event = coordination.step(failed, RULE, reset_at + 15.0, idle, camera_moves=1,
                                     camera_move_start=reset_at - 0.5)
    assert event is None and found[coordination.RESET_COUNT] == resets
    assert found[coordination.RESET_REASON] == coordination.CAMERA_MOVED
    assert found[coordination.MODE] == coordination.IDENTIFY and found[coordination.DETECTIONS] == 1
    # The identification under way (its samples since the reset) is then adopted as usual.
    found, event = coordination.step(found, RULE, reset_at + 15.1, Report(True, 1e-6, 41, 0.0, 20),
                                     camera_moves=1, camera_move_start=reset_at - 0.5)
    assert event.kind == coordination.CONVERGED
    # Otherwise a change detection with a reset: a move that began after the reset, ...
    for moving, start in ((False, reset_at + 1.0), (True, reset_at - 0.5)):  # ... or still moving
        later, event = coordination.step(failed, RULE, reset_at + 15.0, idle, camera_moving=moving,
                                         camera_moves=1, camera_move_start=start)
        assert event.kind == coordination.CHANGE_DETECTED and later[coordination.RESET_COUNT] == resets + 1
        assert later[coordination.RESET_TIME] == reset_at + 15.0
    # ... a move in OBSERVE (converged since the reset), and a move with no start given.
    for state, start in ((found, reset_at - 0.5), (failed, None)):
        later, event = coordination.step(state, RULE, reset_at + 16.0, Report(False, 1.0, 42, 0.0),
                                         camera_moves=2 if state is found else 1, camera_move_start=start)
        assert event.kind == coordination.CHANGE_DETECTED
    with pytest.raises(coordination.IdentificationError, match="camera_move_start"):
        coordination.step(failed, RULE, 1.0, idle, camera_moves=1, camera_move_start=math.nan)


class ScriptedCameraMotion(LeafSystem):
    """``[moving, moves]`` of a camera that moves from ``t0`` for ``duration`` s."""

    def __init__(self, t0, duration):
        super().__init__()
        self.DeclareVectorOutputPort("camera_motion", 2, lambda c, o: o.SetFromVector(
            [float(t0 <= c.get_time() < t0 + duration), float(c.get_time() >= t0)]))  # fmt: skip


def camera_moving_loop():
    """A point on a babbling hand seen by a fixed camera that moves from 5 s to 6 s: the identifier
    and the state machine, with the camera-motion input. Returns ``(simulator, state machine)``."""
    truth, _, _, _ = build(t_slip=np.inf)
    builder = DiagramBuilder()
    source = builder.AddSystem(ScriptedHandPoint(truth, truth.p_HP, np.inf, 0.1))
    ident = builder.AddSystem(SustainableIdentifierSystem(EyeToHandFormulation(), period=0.1))
    sm = builder.AddSystem(CoordinationStateMachine(16, period=0.1))
    camera = builder.AddSystem(ScriptedCameraMotion(5.0, 1.0))
    builder.Connect(source.GetOutputPort("p_CP"), ident.GetInputPort("p_CP"))
    builder.Connect(source.GetOutputPort("X_WH"), ident.GetInputPort("X_WH"))
    builder.Connect(camera.get_output_port(), sm.GetInputPort("camera_motion"))
    connect_identify_observe(builder, ident, sm)
    simulator = Simulator(builder.Build())
    return simulator, sm


def test_the_state_machine_takes_the_camera_motion_input():
    simulator, sm = camera_moving_loop()
    simulator.AdvanceTo(12.0)
    events = sm.events(sm.GetMyContextFromRoot(simulator.get_context()))
    assert [e.kind for e in events] == [coordination.CONVERGED, coordination.CHANGE_DETECTED,
                                        coordination.CONVERGED]  # fmt: skip
    assert events[0].time < 5.0 and events[1].time == pytest.approx(5.0)
    # Nothing adopted while the camera moved (to 6 s), then re-identified from fresh samples.
    assert 6.0 + 0.1 * 9 <= events[2].time < 12.0


def test_a_camera_move_clears_the_adopted_model():
    """After a camera move the adopted estimate is dropped (zeros: nothing for the candidates to
    keep as the previous camera, which would be the moved one) until the next convergence."""
    simulator, sm = camera_moving_loop()
    context = sm.GetMyContextFromRoot(simulator.get_context())
    simulator.AdvanceTo(4.9)
    assert np.any(sm.GetOutputPort("adopted_x").Eval(context) != 0)
    simulator.AdvanceTo(5.5)
    assert not np.any(sm.GetOutputPort("adopted_x").Eval(context))
    assert sm.GetOutputPort("adopted_solution").Eval(context) is None
    simulator.AdvanceTo(12.0)
    assert np.any(sm.GetOutputPort("adopted_x").Eval(context) != 0)  # re-identified


class ScriptedLateMove(LeafSystem):
    """A camera-motion detector that declares at ``t_found`` a move that began at ``t_start``."""

    def __init__(self, t_start, t_found):
        super().__init__()
        self.DeclareVectorOutputPort("camera_motion", 2, lambda c, o: o.SetFromVector(
            [0.0, float(c.get_time() >= t_found)]))  # fmt: skip
        self.DeclareVectorOutputPort("move_start", 1, lambda c, o: o.SetAtIndex(
            0, t_start if c.get_time() >= t_found else -np.inf))  # fmt: skip


def test_a_move_found_after_the_observations_reset_drops_the_kept_model_without_a_new_reset():
    """The point moves on the hand at 8 s (to the identifier, as a moved camera would look) and the
    observation rule resets, keeping the abandoned model; at 9.5 s the detector declares a move that
    began at 7.9 s: the reset becomes a camera move's (reason 2), the kept model is dropped, and no
    second change is detected."""
    truth, _, _, _ = build(t_slip=np.inf)
    builder = DiagramBuilder()
    source = builder.AddSystem(ScriptedHandPoint(truth, truth.p_HP + [0.03, -0.02, 0.01], 8.0, 0.1))
    ident = builder.AddSystem(SustainableIdentifierSystem(EyeToHandFormulation(), period=0.1))
    sm = builder.AddSystem(CoordinationStateMachine(16, period=0.1))
    camera = builder.AddSystem(ScriptedLateMove(7.9, 9.5))
    builder.Connect(source.GetOutputPort("p_CP"), ident.GetInputPort("p_CP"))
    builder.Connect(source.GetOutputPort("X_WH"), ident.GetInputPort("X_WH"))
    builder.Connect(camera.GetOutputPort("camera_motion"), sm.GetInputPort("camera_motion"))
    builder.Connect(camera.GetOutputPort("move_start"), sm.GetInputPort("camera_move_start"))
    connect_identify_observe(builder, ident, sm)
    simulator = Simulator(builder.Build())
    context = sm.GetMyContextFromRoot(simulator.get_context())
    simulator.AdvanceTo(9.4)
    assert [e.kind for e in sm.events(context)] == [coordination.CONVERGED, coordination.CHANGE_DETECTED]
    assert sm.GetOutputPort("reset_reason").Eval(context)[0] == coordination.OBSERVATION_FAILED
    assert np.any(sm.GetOutputPort("adopted_x").Eval(context) != 0)  # kept as the previous camera
    resets = sm.GetOutputPort("reset").Eval(context)[0]
    simulator.AdvanceTo(9.7)
    assert sm.GetOutputPort("reset_reason").Eval(context)[0] == coordination.CAMERA_MOVED
    assert not np.any(sm.GetOutputPort("adopted_x").Eval(context))
    assert sm.GetOutputPort("adopted_solution").Eval(context) is None
    assert sm.GetOutputPort("reset").Eval(context)[0] == resets
    assert [e.kind for e in sm.events(context)] == [coordination.CONVERGED, coordination.CHANGE_DETECTED]


def _observing(body_changes=0):
    """A state in OBSERVE (sigma 1e-4) that has seen ``body_changes``, and the next sample count."""
    state, _ = coordination.step(coordination.initial_state(), RULE, 0.0, Report(False, 1.0, 1, 0.0),
                                 body_changes=body_changes)  # fmt: skip
    state, event = coordination.step(state, RULE, 0.1, Report(True, 1e-6, 2, 0.0), body_changes=body_changes)
    assert event.kind == coordination.CONVERGED
    return state, 3


def test_a_body_change_reported_while_identifying_is_only_counted():
    state, _ = coordination.step(coordination.initial_state(), RULE, 0.0, Report(False, 1.0, 1, 0.0),
                                 body_changes=0)
    state, event = coordination.step(state, RULE, 0.1, Report(False, 1.0, 2, 0.0), body_changes=1)
    assert event is None and state[coordination.MODE] == coordination.IDENTIFY
    assert state[coordination.BODY_CHANGES] == 1 and state[coordination.BODY_PENDING] == -1
    state, event = coordination.step(state, RULE, 0.2, Report(True, 1e-6, 3, 0.0), body_changes=1)
    assert event.kind == coordination.CONVERGED
    for k in range(30):  # observing, the same count: nothing
        state, event = coordination.step(state, RULE, 0.3 + 0.1 * k, Report(True, 1e-6, 4 + k, 1e-8),
                                         body_changes=1)
        assert event is None and state[coordination.MODE] == coordination.OBSERVE
    with pytest.raises(coordination.IdentificationError, match="body_changes"):
        coordination.step(state, RULE, 9.0, Report(True, 1e-6, 40, 0.0), body_changes=-1)


@pytest.mark.parametrize("samples", ["within", "none"])
def test_a_body_change_the_camera_does_not_see_is_a_slip_after_the_rules_window(samples):
    """Samples within the limit (new points that fit the model) or none at all (the tool unseen):
    the report becomes a change detection for a slip (the camera kept) after
    ``max_consecutive_violations`` ticks, not before."""
    state, count = _observing()
    n = RULE.max_consecutive_violations
    for k in range(n):
        count += samples == "within"
        state, event = coordination.step(state, RULE, 1.0 + 0.1 * k, Report(True, 1e-6, count, 1e-8),
                                         body_changes=1)
        if k < n - 1:
            assert event is None and state[coordination.MODE] == coordination.OBSERVE
    assert event.kind == coordination.CHANGE_DETECTED and event.detail == coordination.BODY_CHANGED_DETAIL
    assert event.time == pytest.approx(1.0 + 0.1 * (n - 1))
    assert state[coordination.MODE] == coordination.IDENTIFY and state[coordination.RESET_COUNT] == 1
    assert state[coordination.RESET_REASON] == coordination.OBSERVATION_FAILED
    assert state[coordination.BODY_PENDING] == -1


def test_a_body_change_the_camera_sees_is_the_rules_detection():
    """A report while the samples go over the limit: the rule detects the change by itself, at its
    tenth violation, as without the report (the ticks over the limit do not count for the report),
    and the report is answered."""
    state, count = _observing()
    events = []
    for k in range(3):  # within the limit, then the report arrives with the first violation
        count += 1
        state, event = coordination.step(state, RULE, 1.0 + 0.1 * k, Report(True, 1e-6, count, 1e-8),
                                         body_changes=0)
    for k in range(RULE.max_consecutive_violations + 5):
        count += 1
        state, event = coordination.step(state, RULE, 2.0 + 0.1 * k, Report(False, 1e-6, count, 1.0),
                                         body_changes=1)
        events += [event] if event else []  # not converged again: nothing to adopt after the detection
    assert [e.detail for e in events] == [f"{RULE.max_consecutive_violations} samples over the limit"]
    assert events[0].time == pytest.approx(2.0 + 0.1 * (RULE.max_consecutive_violations - 1))
    assert state[coordination.BODY_PENDING] == -1


class ScriptedBodyChanges(LeafSystem):
    """A count of the held body's changes: one at ``t0``."""

    def __init__(self, t0):
        super().__init__()
        self.DeclareVectorOutputPort("body_changes", 1, lambda c, o: o.SetFromVector(
            [float(c.get_time() >= t0)]))  # fmt: skip


def test_the_state_machine_takes_the_body_changes_input():
    """A point on a babbling hand that never changes, and a body change reported at 6 s: the state
    machine detects a change after the rule's window, keeps the adopted model (the previous camera
    for a slip), and identifies again."""
    truth, _, _, _ = build(t_slip=np.inf)
    builder = DiagramBuilder()
    source = builder.AddSystem(ScriptedHandPoint(truth, truth.p_HP, np.inf, 0.1))
    ident = builder.AddSystem(SustainableIdentifierSystem(EyeToHandFormulation(), period=0.1))
    sm = builder.AddSystem(CoordinationStateMachine(16, period=0.1))
    changes = builder.AddSystem(ScriptedBodyChanges(6.0))
    builder.Connect(source.GetOutputPort("p_CP"), ident.GetInputPort("p_CP"))
    builder.Connect(source.GetOutputPort("X_WH"), ident.GetInputPort("X_WH"))
    builder.Connect(changes.get_output_port(), sm.GetInputPort("body_changes"))
    connect_identify_observe(builder, ident, sm)
    simulator = Simulator(builder.Build())
    context = sm.GetMyContextFromRoot(simulator.get_context())
    simulator.AdvanceTo(7.5)
    events = sm.events(context)
    assert [e.kind for e in events] == [coordination.CONVERGED, coordination.CHANGE_DETECTED]
    # After the rule's window: max_consecutive_violations ticks of 0.1 s with no sample over the limit,
    assert events[0].time < 6.0 and events[1].time == pytest.approx(6.0 + 0.1 * 9)  # the report's tick counts
    assert events[1].detail == coordination.BODY_CHANGED_DETAIL
    assert sm.GetOutputPort("reset_reason").Eval(context)[0] == coordination.OBSERVATION_FAILED
    assert np.any(sm.GetOutputPort("adopted_x").Eval(context) != 0)  # kept: the camera did not move
    simulator.AdvanceTo(14.0)
    assert [e.kind for e in sm.events(context)][2:] == [coordination.CONVERGED]
