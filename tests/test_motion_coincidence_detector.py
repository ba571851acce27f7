"""MotionCoincidenceDetector in a Diagram with the OpticalFlowTracker on a synthetic scene:
Eq. (27) on real optical flow, the confirming request, per-feature flags, context cloning."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from test_optical_flow_tracker import build_scene_diagram

from sustain_drake.perception.coincidence import CoincidenceState
from sustain_drake.systems.motion_coincidence_detector import (
    FeatureBodyFlags,
    MotionCoincidenceDetector,
)


@pytest.fixture(scope="module")
def run_2s():
    diagram, tracker, detector = build_scene_diagram(with_detector=True)
    sim = Simulator(diagram)
    sim.AdvanceTo(0.45)
    early = sim.get_context().Clone()
    sim.AdvanceTo(2.0)
    return diagram, tracker, detector, sim, early


def columns(tracker):
    return np.arange(tracker.grid.num_cells) % tracker.grid.cols


def test_arm_cells_coincide_with_the_actuator_and_the_distractor_never_does(run_2s):
    _, tracker, detector, sim, _ = run_2s
    ctx = detector.GetMyContextFromRoot(sim.get_context())
    n_c = tracker.grid.num_cells
    eps = detector.GetOutputPort("likelihood").Eval(ctx).reshape(1, n_c)
    cols = columns(tracker)
    arm = cols < tracker.grid.cols // 2 - 1
    right = cols >= tracker.grid.cols // 2 + 1
    # two actuator onsets (0.5 s and 1.5 s): arm cells count one or two coincidences each
    assert (eps[0, arm] >= 1).mean() > 0.8 and eps.max() <= 2
    # the distractor patch moved at 0.2-0.4 s and 1.2-1.4 s, with no actuator onset before it
    assert np.all(eps[0, right] == 0)
    state = detector.detector_state(ctx)
    assert state.unexplained[right].sum() >= 1          # seen as counter-evidence instead
    request = detector.GetOutputPort("confirm_request").Eval(ctx)
    assert request[1] >= 1
    p = detector.params
    assert p.hold_min <= request[2] <= p.hold_min + p.hold_spread
    # q* is the posture the motion started from (0 at 0.5 s, 0.25 at 1.5 s)
    q_star = detector.GetOutputPort("confirm_posture").Eval(ctx)[0]
    assert q_star == pytest.approx(0.0, abs=1e-9) or q_star == pytest.approx(0.25, abs=1e-9)
    # no confirming motion was made, so nothing is body yet
    assert np.all(detector.GetOutputPort("body_cells").Eval(ctx) == 0)
    assert np.all(np.isfinite(detector.GetOutputPort("body_evidence").Eval(ctx)))


def test_feature_on_body_follows_the_body_cells(run_2s):
    diagram, tracker, detector, sim, _ = run_2s
    ctx = sim.get_context().Clone()
    dctx = detector.GetMyContextFromRoot(ctx)
    state = detector.detector_state(dctx)
    body_cells = np.array([0, 1, 8, 9])
    state.evidence[body_cells] = 50.0
    state.hits[0, body_cells] = 3.0
    dctx.SetDiscreteState(state.to_vector())
    flags = detector.GetOutputPort("feature_on_body").Eval(dctx)
    features = tracker.GetOutputPort("tracked_features").Eval(
        tracker.GetMyContextFromRoot(ctx))
    assert isinstance(flags, FeatureBodyFlags)
    assert np.array_equal(flags.ids, features.ids)
    assert np.array_equal(flags.on_body, np.isin(features.cell, body_cells))
    assert np.all(flags.actuator[flags.on_body] == 0) and np.all(flags.actuator[~flags.on_body] == -1)
    assert np.array_equal(detector.GetOutputPort("body_cells").Eval(dctx).nonzero()[0], body_cells)
    moves = detector.GetOutputPort("actuator_cells").Eval(dctx)
    assert np.array_equal(np.flatnonzero(moves), body_cells)


def test_cloned_context_replays_identically(run_2s):
    diagram, _, detector, sim, early = run_2s
    sim2 = Simulator(diagram, early)
    before = detector.detector_state(detector.GetMyContextFromRoot(early)).eps.sum()
    sim2.AdvanceTo(2.0)
    a = detector.GetMyContextFromRoot(sim.get_context()).get_discrete_state_vector().value()
    b = detector.GetMyContextFromRoot(sim2.get_context()).get_discrete_state_vector().value()
    assert before == 0 and np.array_equal(a, b)
    assert a.size == CoincidenceState.size(1, 48)


def test_constructor_rejects_bad_sizes():
    with pytest.raises(ValueError, match="at least one actuator"):
        MotionCoincidenceDetector(0, 10)
    with pytest.raises(ValueError, match="period"):
        MotionCoincidenceDetector(2, 10, period=0.0)
