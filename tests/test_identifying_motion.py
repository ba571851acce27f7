"""IdentifyingMotion: far postures while identifying, the detector's confirming requests first."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource, DiscreteTimeDelay, MatrixGain

from sustain_drake.identification import coordination
from sustain_drake.systems.identifying_motion import IdentifyingMotion

RANGES = [[-0.7, 0.7], [0.2, 0.9], [0.7, 1.5], [-0.3, 1.0], [-1.2, 1.2]]
Q = np.array([0.0, 0.6, 1.1, 0.5, 0.0])


class Scripted(LeafSystem):
    """The state machine's mode (IDENTIFY before ``t_observe``, and OBSERVE in ``[observe)``) and the
    detector's requests (one, id 1, at ``t_request``)."""

    def __init__(self, t_observe, t_request, observe=(0.0, 0.0)):
        super().__init__()
        self.DeclareVectorOutputPort("mode", 1, lambda c, o: o.SetAtIndex(
            0, coordination.OBSERVE if c.get_time() >= t_observe or observe[0] <= c.get_time() < observe[1]
            else coordination.IDENTIFY))  # fmt: skip
        self.DeclareVectorOutputPort("confirm", 7, lambda c, o: o.SetFromVector(
            [1.0, 2.0, *Q] if c.get_time() >= t_request else np.zeros(7)))  # fmt: skip


def simulate(t_observe, t_request, until):
    builder = DiagramBuilder()
    scripted = builder.AddSystem(Scripted(t_observe, t_request))
    motion = builder.AddSystem(IdentifyingMotion(RANGES, interval=1.0, seed=3, period=0.1))
    q = builder.AddSystem(ConstantVectorSource(Q))
    builder.Connect(scripted.GetOutputPort("mode"), motion.GetInputPort("mode"))
    builder.Connect(scripted.GetOutputPort("confirm"), motion.GetInputPort("detector_confirm"))
    builder.Connect(q.get_output_port(), motion.GetInputPort("joint_positions"))
    simulator = Simulator(builder.Build())
    outputs = []
    for t in np.arange(0.1, until + 1e-9, 0.1):
        simulator.AdvanceTo(t)
        outputs.append(np.array(motion.GetOutputPort("confirm").Eval(
            motion.GetMyContextFromRoot(simulator.get_context()))))  # fmt: skip
    return np.array(outputs)


def test_far_postures_while_identifying_and_the_detector_first():
    out = simulate(t_observe=np.inf, t_request=1.5, until=4.0)
    ids = out[:, 0]
    # Identifying, no request for 1 s: its own request (a usual move after it, joint -1), far
    # from the current posture and within the ranges.
    first = np.flatnonzero(ids == 1)[0]
    assert out[first, 1] == -1.0
    far = out[first, 2:]
    assert np.all(far >= np.array(RANGES)[:, 0]) and np.all(far <= np.array(RANGES)[:, 1])
    assert np.max(np.abs(far - Q)) > 0.5
    # The detector's request at 1.5 s is forwarded at once, as it is (joint 2, its posture).
    forwarded = np.flatnonzero(ids == 2)[0]
    assert forwarded == pytest.approx(14, abs=1) and list(out[forwarded, 1:]) == [2.0, *Q]
    # Then its own again after each second without requests (2.5 s, 3.5 s), each a new posture.
    assert list(ids[[forwarded + 9, forwarded + 11, -1]]) == [2, 3, 4] and out[-1, 1] == -1.0
    assert not np.allclose(out[-1, 2:], far)


def test_nothing_of_its_own_while_observing():
    out = simulate(t_observe=0.0, t_request=np.inf, until=3.0)
    assert out[:, 0].max() == 0


def test_a_far_posture_when_the_detector_holds_the_arm_near_one_posture():
    """The detector asking every 0.5 s for the same posture (its confirming trials one after the
    other): while identifying again (a first convergence at 0.1 s, a change detected at 0.2 s), once
    the arm has stayed there for ``max_hold`` (3 intervals) a far posture all the same, and the
    detector's requests wait until the arm is there (an arm that takes 1 s to reach a requested
    posture), then go on. Before any convergence the detector alone decides."""
    new, own, forwarded = _chatty_detector(observed_before=0.2)
    # The arm at the detector's posture from ~1.3 s (the first request, 1 s to get there): a far
    # posture 3 s later; there at ~5.3 s, back at the detector's at ~6.7 s: the next 3 s later.
    assert own == pytest.approx([4.3, 9.7], abs=0.15)
    assert all(not (o <= f < o + 1.0) for o in own for f in forwarded)  # the arm on its way
    assert len(forwarded) >= 12  # the detector is still served most of the time
    new, own, forwarded = _chatty_detector(observed_before=0.0)
    assert own == [] and len(forwarded) == 19  # every request after the first tick's


def test_a_far_posture_before_any_convergence_when_the_identifiers_ask_for_more_motion():
    """``more_motion`` (the candidates converged but their views do not pin the camera's rotation
    yet): the same far postures as after a convergence, before any."""
    new, own, forwarded = _chatty_detector(observed_before=0.0, more_motion=1.0)
    assert own == pytest.approx([4.3, 9.7], abs=0.15)
    new, own, forwarded = _chatty_detector(observed_before=0.0, more_motion=0.0)
    assert own == []


def test_with_a_reach_the_identifiers_ask_is_met_at_once_within_reach():
    """``more_motion_reach``: while the identifiers ask for more motion, a posture within the reach
    (max-norm) of the arm's posture when they first asked (the anchor, where their points were seen:
    no walk away from it), after one interval near a posture (not ``max_hold``); the far postures
    of the whole ranges otherwise. (A detector that never asks: its turns are the next test's.)"""
    postures = []
    new, own, forwarded = _chatty_detector(observed_before=0.0, more_motion=1.0, reach=0.3,
                                           postures=postures, asks=lambda t: False)
    # One interval near a posture (the arm's start) is enough: the first at 1.1 s, and five in
    # 10 s, where without the reach two came (4.3 and 9.7 s, above).
    assert own[0] == pytest.approx(1.1, abs=0.15) and len(own) >= 4
    lower, upper = np.array(RANGES).T  # the arm starts at 0, outside the ranges: from the nearest in them
    anchor = np.clip(postures[0][0], lower, upper)
    from_anchor = [np.max(np.abs(requested - anchor)) for _, requested in postures]
    steps = [np.max(np.abs(requested - q)) for q, requested in postures]
    assert len(steps) == len(own) and max(from_anchor) <= 0.3 + 1e-9 and min(steps) > 0.1
    assert all(np.all(requested >= lower) and np.all(requested <= upper) for _, requested in postures)
    far = []
    _chatty_detector(observed_before=0.0, more_motion=1.0, postures=far)
    assert min(np.max(np.abs(requested - q)) for q, requested in far) > 0.5
    with pytest.raises(ValueError, match="more_motion_reach"):
        IdentifyingMotion(RANGES, interval=1.0, more_motion_reach=0.0)


def test_the_anchor_is_set_anew_each_time_the_identifiers_ask_again():
    """An ask that ends (3 s: the detector's requests, made while it is off, take the arm to its
    posture Q) and comes back (6 s): the postures asked for after it are within the reach of where
    the arm is then (Q), not of the first anchor (the arm's start, 0.4-0.5 rad from Q on three
    joints)."""
    postures = []
    _chatty_detector(observed_before=0.0, more_motion=lambda t: float(not 3.0 <= t < 6.0), reach=0.1,
                     postures=postures, asks=lambda t: 3.0 <= t < 6.0)
    lower, upper = np.array(RANGES).T
    first_anchor = np.clip(postures[0][0], lower, upper)
    before = [requested for q, requested in postures if np.max(np.abs(q - Q)) > 0.2]
    again = [(q, requested) for q, requested in postures if np.max(np.abs(q - Q)) <= 0.2]
    assert len(before) >= 1 and len(again) >= 3
    assert max(np.max(np.abs(r - first_anchor)) for r in before) <= 0.1 + 1e-9
    assert max(np.max(np.abs(r - Q)) for _, r in again) <= 0.1 + 1e-9  # the new anchor: Q
    assert min(np.max(np.abs(r - first_anchor)) for _, r in again) > 0.3


def _every_tick(builder, scripted, detector, motion, arm, more_motion=None, until=10.0):
    """Wire the mode, the detector's requests, the arm's posture (its output) and the identifiers'
    ``more_motion(t)`` (None: unconnected) into ``motion``, simulate, and yield ``(t, motion's confirm,
    arm's posture)`` every 0.1 s up to ``until``."""
    builder.Connect(scripted.GetOutputPort("mode"), motion.GetInputPort("mode"))
    builder.Connect(detector.get_output_port(), motion.GetInputPort("detector_confirm"))
    builder.Connect(arm.get_output_port(), motion.GetInputPort("joint_positions"))
    if more_motion is not None:
        builder.Connect(builder.AddSystem(Asking(more_motion)).get_output_port(),
                        motion.GetInputPort("more_motion"))
    simulator = Simulator(builder.Build())
    for t in np.arange(0.1, until + 1e-9, 0.1):
        simulator.AdvanceTo(t)
        root = simulator.get_context()
        yield (round(t, 1), np.array(motion.GetOutputPort("confirm").Eval(motion.GetMyContextFromRoot(root))),
               np.array(arm.get_output_port().Eval(arm.GetMyContextFromRoot(root))))


def _chatty_detector(observed_before, more_motion=None, reach=None, postures=None, asks=lambda t: True):
    """The requests made over 10 s (time, joint), the own ones' and the detector's times; with a
    list ``postures``, each own request's ``(arm's posture, requested posture)`` is appended. The
    detector asks every 0.5 s while ``asks(t)``."""
    builder = DiagramBuilder()
    scripted = builder.AddSystem(Scripted(t_observe=np.inf, t_request=np.inf, observe=(0.1, observed_before)))
    detector = builder.AddSystem(Chatty(asks))
    motion = builder.AddSystem(IdentifyingMotion(RANGES, interval=1.0, seed=3, period=0.1,
                                                 more_motion_reach=reach))
    posture = builder.AddSystem(MatrixGain(np.hstack([np.zeros((5, 2)), np.eye(5)])))  # q of the request
    arm = builder.AddSystem(DiscreteTimeDelay(0.1, 10, 5))
    builder.Connect(motion.GetOutputPort("confirm"), posture.get_input_port())
    builder.Connect(posture.get_output_port(), arm.get_input_port())
    asking = None if more_motion is None else more_motion if callable(more_motion) else lambda t: more_motion
    joints = []
    for t, out, q in _every_tick(builder, scripted, detector, motion, arm, asking):
        if postures is not None and out[1] == -1.0 and out[0] > 0 and (not joints or out[0] != joints[-1][1]):
            postures.append((q, out[2:]))
        joints.append((round(t, 1), out[0], out[1]))
    new = [(t, j) for (t, i, j), prev in zip(joints[1:], joints[:-1], strict=True) if i != prev[1]]
    return new, [t for t, j in new if j == -1.0], [t for t, j in new if j == 2.0]


class Chatty(LeafSystem):
    """A detector with a new confirming request (joint 2) every 0.5 s while ``asks(t)`` (always by
    default); the last one stays on its output otherwise."""

    def __init__(self, asks=lambda t: True):
        super().__init__()
        times = np.arange(0.0, 20.0, 0.5)

        def last_id(t):
            return float(np.count_nonzero([asks(u) for u in times[times <= t + 1e-9]]))

        self.DeclareVectorOutputPort("confirm", 7, lambda c, o: o.SetFromVector(
            [last_id(c.get_time()), 2.0, *Q]))  # fmt: skip


class Asking(LeafSystem):
    """The identifiers' ``more_motion``: ``asks(t)``."""

    def __init__(self, asks):
        super().__init__()
        self.DeclareVectorOutputPort("more_motion", 1, lambda c, o: o.SetAtIndex(0, asks(c.get_time())))


class Recording:
    """A ``HandEyePostures`` stand-in: records each call and picks the draw nearest the arm's posture
    (never the farthest of several random draws)."""

    num_joints = 5

    def __init__(self):
        self.calls = []

    def choose(self, q_now, goals, state):
        self.calls.append((np.array(q_now), np.array(goals), np.array(state)))
        return int(np.argmin(np.max(np.abs(goals - q_now), axis=1)))


def _asked_with_chooser(statistic):
    builder = DiagramBuilder()
    scripted = builder.AddSystem(Scripted(t_observe=np.inf, t_request=np.inf))
    chooser = Recording()
    motion = builder.AddSystem(IdentifyingMotion(RANGES, interval=1.0, seed=3, period=0.1, postures=chooser))
    q = builder.AddSystem(ConstantVectorSource(Q))
    more = builder.AddSystem(Asking(lambda t: 1.0))
    builder.Connect(scripted.GetOutputPort("mode"), motion.GetInputPort("mode"))
    builder.Connect(q.get_output_port(), motion.GetInputPort("joint_positions"))
    builder.Connect(more.get_output_port(), motion.GetInputPort("more_motion"))
    builder.Connect(builder.AddSystem(ConstantVectorSource(statistic)).get_output_port(),
                    motion.GetInputPort("statistic"))
    simulator = Simulator(builder.Build())
    requests = []
    for t in np.arange(0.1, 6.0 + 1e-9, 0.1):
        simulator.AdvanceTo(t)
        out = motion.GetOutputPort("confirm").Eval(motion.GetMyContextFromRoot(simulator.get_context()))
        if not requests or out[0] != requests[-1][0]:
            requests.append(np.array(out))
    return chooser, [r[2:] for r in requests if r[1] == -1.0 and r[0] > 0]


def test_with_postures_the_chooser_picks_among_the_draws():
    """With a chooser and a statistic with samples, each posture asked for is the chooser's pick among
    the draws it was shown (here the nearest); with a statistic of no samples it is not asked, and the
    farthest draw is asked for, as without one."""
    statistic = np.zeros(258)
    statistic[256:] = 10.0  # n_eff, count
    chooser, asked = _asked_with_chooser(statistic)
    assert len(asked) >= 3 and len(chooser.calls) == len(asked)
    for (q_now, goals, state), request in zip(chooser.calls, asked, strict=True):
        np.testing.assert_array_equal(state, statistic)
        nearest = goals[np.argmin(np.max(np.abs(goals - q_now), axis=1))]
        farthest = goals[np.argmax(np.max(np.abs(goals - q_now), axis=1))]
        np.testing.assert_array_equal(request, nearest)
        assert not np.array_equal(nearest, farthest)
    idle, asked = _asked_with_chooser(np.zeros(258))
    assert idle.calls == [] and len(asked) >= 3
    with pytest.raises(ValueError, match="postures chooses for 5 joints"):
        IdentifyingMotion(RANGES[:4], interval=1.0, postures=Recording())


class Arm(LeafSystem):
    """An arm answering ``confirm`` requests as the motion generator does, in outline: it goes to the
    requested posture at 0.2 rad/s (max-norm), and at a detector's posture (joint >= 0) rests 0.5 s
    and then makes its confirming move (0.15 rad of that joint)."""

    def __init__(self, start):
        super().__init__()
        self._request = self.DeclareVectorInputPort("confirm", 7)
        # [q (5), goal (5), last id, rest until, stepped]
        self._x = self.DeclareDiscreteState(np.concatenate([start, start, [0.0, np.inf, 1.0]]))
        self.DeclarePeriodicDiscreteUpdateEvent(0.1, 0.0, self._update)
        self.DeclareVectorOutputPort("q", 5, lambda c, o: o.SetFromVector(
            c.get_discrete_state(self._x).value()[:5]))  # fmt: skip

    def _update(self, context, state):
        x = context.get_discrete_state(self._x).value().copy()
        r, t = self._request.Eval(context), context.get_time()
        if r[0] != x[10]:
            x[5:10], x[10], x[11], x[12] = r[2:], r[0], np.inf, float(r[1] < 0)
        step = np.clip(x[5:10] - x[:5], -0.02, 0.02)
        x[:5] += step
        if not np.any(step) and not x[12]:  # at the detector's posture: rest, then the confirming move
            if not np.isfinite(x[11]):
                x[11] = t + 0.5
            elif t >= x[11]:
                x[5 + int(r[1])] += 0.15
                x[12] = 1.0
        state.get_mutable_vector(self._x).SetFromVector(x)


def _reach_and_one_request(more_motion: float) -> list:
    """``(t, request id, joint, the arm's distance from the detector's posture)`` every tick while
    the identifiers ask (``more_motion``) within a reach, the detector asking once (at 2 s, 0.3 rad
    from the arm)."""
    start = Q + np.array([0.3, 0.0, 0.0, 0.0, 0.0])
    builder = DiagramBuilder()
    scripted = builder.AddSystem(Scripted(t_observe=np.inf, t_request=np.inf))
    detector = builder.AddSystem(Chatty(lambda t: 2.0 <= t < 2.5))
    motion = builder.AddSystem(IdentifyingMotion(RANGES, interval=1.0, seed=3, period=0.1,
                                                 more_motion_reach=0.3))
    arm = builder.AddSystem(Arm(start))
    builder.Connect(motion.GetOutputPort("confirm"), arm.get_input_port())
    return [(t, out[0], out[1], np.max(np.abs(q - Q)))
            for t, out, q in _every_tick(builder, scripted, detector, motion, arm, lambda t: more_motion)]


def test_with_a_point_held_back_a_detectors_request_has_the_arm_until_its_confirming_move():
    """While a converged point is held back (``more_motion`` 2) and postures within a reach come
    every interval, the detector's one request keeps the arm until the arm has been there and made
    its confirming move: no posture of its own replaces it before, and one comes at once after (a
    posture every second would send the arm off before it got there). Before any point converged
    (``more_motion`` 1) the next posture within reach replaces the request before the arm is
    there: the trials' rests would repeat the first points' views."""
    log = _reach_and_one_request(2.0)
    forwarded = next(k for k, (_, _, joint, _) in enumerate(log) if joint == 2.0)
    after = log[forwarded:]
    arrived = next(k for k, entry in enumerate(after) if entry[3] <= 0.05)
    left = next(k for k in range(arrived, len(after)) if after[k][3] > 0.05)
    assert all(joint == 2.0 for _, _, joint, _ in after[:left])  # the detector's until its move
    assert after[left][0] - after[arrived][0] >= 0.5  # the rest at its posture (the trial's onset)
    own = next(k for k in range(left, len(after)) if after[k][2] == -1.0)
    assert own - left <= 1 and log[forwarded - 1][2] == -1.0  # own postures before and at once after
    first = _reach_and_one_request(1.0)
    forwarded = next(k for k, (_, _, joint, _) in enumerate(first) if joint == 2.0)
    replaced = next(k for k in range(forwarded, len(first)) if first[k][2] == -1.0)
    assert all(entry[3] > 0.05 for entry in first[forwarded:replaced + 1])  # before the arm got there
