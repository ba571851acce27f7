"""MotionCoincidenceDetector in a Diagram with the OpticalFlowTracker on a synthetic scene:
Eq. (27) on real optical flow, the confirming request, per-feature flags, context cloning."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from test_optical_flow_tracker import CAMERA, GRID_SHAPE, MovingScene, W, build_scene_diagram

from sustain_drake.perception.coincidence import CoincidenceState
from sustain_drake.systems.motion_coincidence_detector import (
    FeatureBodyFlags,
    MotionCoincidenceDetector,
)
from sustain_drake.systems.optical_flow_tracker import OpticalFlowTracker


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
    confirm = detector.GetOutputPort("confirm").Eval(ctx)           # MotionGenerator's format
    assert confirm.tolist() == [request[1], -1.0, q_star]
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
    in_cell = np.isin(features.cell, body_cells)
    assert np.array_equal(flags.in_body_cell, in_cell)
    assert not flags.on_body.any()              # no feature went through a confirming trial
    assert np.all(flags.actuator[in_cell] == 0) and np.all(flags.actuator[~in_cell] == -1)
    assert not detector.GetOutputPort("body_feature_cells").Eval(dctx).any()
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
    ma = detector.feature_memory(detector.GetMyContextFromRoot(sim.get_context()))
    mb = detector.feature_memory(detector.GetMyContextFromRoot(sim2.get_context()))
    assert ma is not mb and np.array_equal(ma.ids, mb.ids) and np.array_equal(ma.hits, mb.hits)
    assert a.size == CoincidenceState.size(1, 48)


def test_constructor_rejects_bad_sizes():
    with pytest.raises(ValueError, match="at least one actuator"):
        MotionCoincidenceDetector(0, 10)
    with pytest.raises(ValueError, match="period"):
        MotionCoincidenceDetector(2, 10, period=0.0)


class ScriptedArm(LeafSystem):
    """A stand-in motion generator for one joint: alternates 0.5 s moves (±0.4 rad/s) and
    0.6 s pauses, and answers the detector's confirming requests: back to q* in 0.2 s, hold
    for the requested time, move again for 0.4 s. State: [q, v, phase, phase_end, count, q*]."""

    MOVE, PAUSE, RETURN, HOLD = 0.0, 1.0, 2.0, 3.0

    def __init__(self, period=1.0 / 30.0):
        super().__init__()
        self._period = period
        self._request = self.DeclareVectorInputPort("confirm_request", 3)
        self._posture = self.DeclareVectorInputPort("confirm_posture", 1)
        self.DeclareDiscreteState(np.array([0.0, 0.0, self.PAUSE, 1.0, 0.0, 0.0, 0.0]))
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareVectorOutputPort("position", 1, lambda c, o: o.SetFromVector(
            c.get_discrete_state_vector().value()[:1]),
            prerequisites_of_calc={self.all_state_ticket()})

    def _update(self, context, discrete_state):
        q, v, phase, end, count, q_star, n_moves = context.get_discrete_state_vector().value()
        t = context.get_time()
        request = self._request.Eval(context)
        if request[0] > 0 and request[1] > count:
            count, q_star = request[1], self._posture.Eval(context)[0]
            phase, end, v = self.RETURN, t + 0.2, (q_star - q) / 0.2
        elif t >= end - 1e-9:
            if phase == self.RETURN:
                q, v, phase, end = q_star, 0.0, self.HOLD, t + request[2]
            elif phase in (self.HOLD, self.PAUSE):
                n_moves += 1
                # away from 0 when near it, back towards 0 otherwise, to stay in ±0.6 rad
                direction = 1.0 if (n_moves % 2 == 1) == (q <= 0) else -1.0
                v, phase, end = 0.4 * direction, self.MOVE, t + (0.4 if phase == self.HOLD else 0.5)
            else:
                v, phase, end = 0.0, self.PAUSE, t + 0.6
        q = float(np.clip(q + v * self._period, -0.6, 0.6))
        discrete_state.get_mutable_vector(0).SetFromVector(
            [q, v, phase, end, count, q_star, n_moves])


def test_closed_loop_confirming_motions_mark_arm_cells_and_never_the_distractor():
    """Real optical flow on a synthetic scene, the detector, and a scripted arm answering its
    requests; the distractor patch moves by itself for 0.3 s every ~1-2 s."""
    rng = np.random.default_rng(1)
    starts = np.cumsum(rng.uniform(1.0, 2.0, 12))
    distractor = tuple((s, s + 0.3) for s in starts)
    builder = DiagramBuilder()
    arm = builder.AddNamedSystem("arm", ScriptedArm())
    scene = builder.AddNamedSystem("scene", MovingScene(distractor=distractor))
    tracker = builder.AddNamedSystem("tracker", OpticalFlowTracker(CAMERA, GRID_SHAPE))
    detector = builder.AddNamedSystem(
        "detector", MotionCoincidenceDetector(1, tracker.grid.num_cells))
    builder.Connect(arm.GetOutputPort("position"), scene.get_input_port(0))
    builder.Connect(scene.GetOutputPort("color_image"), tracker.GetInputPort("color_image"))
    builder.Connect(scene.GetOutputPort("depth_image"), tracker.GetInputPort("depth_image"))
    builder.Connect(arm.GetOutputPort("position"), detector.GetInputPort("actuator_positions"))
    builder.Connect(tracker.GetOutputPort("visual_change"), detector.GetInputPort("visual_change"))
    builder.Connect(tracker.GetOutputPort("tracked_features"),
                    detector.GetInputPort("tracked_features"))
    builder.Connect(detector.GetOutputPort("confirm_request"), arm.GetInputPort("confirm_request"))
    builder.Connect(detector.GetOutputPort("confirm_posture"), arm.GetInputPort("confirm_posture"))
    sim = Simulator(builder.Build())
    ctx = detector.GetMyContextFromRoot(sim.get_context())
    tctx = tracker.GetMyContextFromRoot(sim.get_context())
    ever = np.zeros(tracker.grid.num_cells, bool)
    ever_feature_cells = np.zeros(tracker.grid.num_cells, bool)
    body_feature_u = []
    for k in range(1, 12 * 30):
        sim.AdvanceTo(k / 30.0)
        ever |= detector.GetOutputPort("body_cells").Eval(ctx) > 0
        ever_feature_cells |= detector.GetOutputPort("body_feature_cells").Eval(ctx) > 0
        flags = detector.GetOutputPort("feature_on_body").Eval(ctx)
        f = tracker.GetOutputPort("tracked_features").Eval(tctx)
        body_feature_u.extend(f.p_px[flags.on_body, 0].tolist())
    cols = columns(tracker)
    rows = np.arange(tracker.grid.num_cells) // tracker.grid.cols
    arm_cells = cols <= 2
    distractor_cells = (rows >= 2) & (rows <= 3) & (cols >= 5) & (cols <= 6)
    assert detector.GetOutputPort("confirm_request").Eval(ctx)[1] >= 2
    # Arm cells are marked by the cell rule or by the confirmed features they hold (cells
    # holding one raise no more requests, so the cell rule may stop short of them).
    assert (ever | ever_feature_cells)[arm_cells].mean() >= 0.8
    assert not ever[cols >= 5].any() and not ever[distractor_cells].any()
    # features confirmed one by one: on the arm half only, and they mark its cells
    assert len(body_feature_u) > 100 and max(body_feature_u) < W // 2 + 10
    assert ever_feature_cells[arm_cells].mean() >= 0.5 and not ever_feature_cells[cols >= 5].any()
