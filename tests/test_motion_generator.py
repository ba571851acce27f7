"""The babbling motion generator: smooth, within ranges, paced; pause and confirm requests."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from sustain_drake.systems.motion_generator import MotionGenerator, move_duration, quintic

LOWER = np.array([-0.5, 0.0, 0.5])
UPPER = np.array([0.5, 0.8, 1.5])
START = np.array([0.0, 0.4, 1.0])


def _source(value):
    """A constant request, or a ``(times, values)`` one that changes at the given times."""
    if isinstance(value, tuple):
        times, values = value
        return TrajectorySource(PiecewisePolynomial.ZeroOrderHold(times, np.array(values).T))
    return ConstantVectorSource(value)


def run(generator: MotionGenerator, duration: float, dt: float = 0.01, pause=None, confirm=None, goal=None):
    builder = DiagramBuilder()
    builder.AddSystem(generator)
    for name, value in (("pause", pause), ("confirm", confirm), ("goal", goal)):
        if value is not None:
            source = builder.AddSystem(_source(value))
            builder.Connect(source.get_output_port(), generator.GetInputPort(name))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = generator.GetMyContextFromRoot(simulator.get_context())
    times, states = [], []
    for t in np.arange(0.0, duration, dt):
        simulator.AdvanceTo(t)
        times.append(t)
        states.append(generator.get_output_port().Eval(context).copy())
    return np.array(times), np.array(states)


def test_quintic_starts_and_ends_at_rest():
    q0, q1 = np.array([0.0, 1.0]), np.array([1.0, -1.0])
    for s, q_expected in ((0.0, q0), (2.0, q1), (3.0, q1)):
        q, v = quintic(q0, q1, 2.0, s)
        np.testing.assert_allclose(q, q_expected)
        np.testing.assert_allclose(v, 0.0, atol=1e-12)
    _, v_mid = quintic(q0, q1, 2.0, 1.0)
    np.testing.assert_allclose(v_mid, 15 / 8 * (q1 - q0) / 2.0)


def test_babbling_is_smooth_within_ranges_and_paced():
    gen = MotionGenerator(LOWER, UPPER, START, seed=1, max_speed=0.5, min_duration=0.5)
    times, x = run(gen, 20.0)
    q, v = x[:, :3], x[:, 3:]
    np.testing.assert_allclose(q[0], START)
    assert np.all(q >= LOWER - 1e-9) and np.all(q <= UPPER + 1e-9)
    assert np.max(np.abs(v)) <= 0.5 + 1e-9
    # Velocity is continuous (no jumps between moves): the finite difference matches v.
    dq = np.diff(q, axis=0) / 0.01
    np.testing.assert_allclose(dq, (v[1:] + v[:-1]) / 2, atol=0.02)
    # It explores: each joint covers most of its range in 20 s.
    assert np.all(q.max(axis=0) - q.min(axis=0) > 0.5 * (UPPER - LOWER))


def test_same_seed_same_motion_other_seed_other_motion():
    _, a = run(MotionGenerator(LOWER, UPPER, START, seed=3), 5.0)
    _, b = run(MotionGenerator(LOWER, UPPER, START, seed=3), 5.0)
    _, c = run(MotionGenerator(LOWER, UPPER, START, seed=4), 5.0)
    np.testing.assert_array_equal(a, b)
    assert np.max(np.abs(a - c)) > 0.05


def test_a_goal_input_sets_every_babbling_move_the_first_included():
    """Connected, ``goal`` is where each babbling move goes (clipped to the ranges), from the first
    move on, at the pace; its moves last as ``move_duration`` says."""
    goals = ([0.0, 1.8, 4.5, 20.0], [[0.3, 0.7, 0.6], [-0.4, 0.1, 1.4], [0.9, -1.0, 1.2], [0.9, -1.0, 1.2]])
    gen = MotionGenerator(LOWER, UPPER, START, seed=2, max_speed=0.5, min_duration=1.0, dwell=0.5)
    times, x = run(gen, 9.5, goal=goals)
    q = x[:, :3]
    first = move_duration(START, np.array(goals[1][0]), 0.5, 1.0)  # 15/8 0.4 / 0.5 = 1.5 s
    assert first == pytest.approx(1.5)
    at = int(round((first + 0.1) / 0.01))  # resting after the first move
    np.testing.assert_allclose(q[at], goals[1][0], atol=1e-9)
    # The next move starts after the rest (2.0 s), towards the goal read then (the second one).
    second = int(round((first + 0.5 + move_duration(np.array(goals[1][0]), np.array(goals[1][1]), 0.5, 1.0)
                        + 0.1) / 0.01))
    np.testing.assert_allclose(q[second], goals[1][1], atol=1e-9)
    # A goal outside the ranges is clipped to them.
    assert np.all(q >= LOWER - 1e-9) and np.all(q <= UPPER + 1e-9)
    np.testing.assert_allclose(q[-1], np.clip(goals[1][2], LOWER, UPPER), atol=1e-9)
    # Without the input the same generator babbles elsewhere.
    plain = MotionGenerator(LOWER, UPPER, START, seed=2, max_speed=0.5, min_duration=1.0, dwell=0.5)
    _, free = run(plain, 2.0)
    assert np.max(np.abs(free[at, :3] - goals[1][0])) > 0.05


def test_dwell_rests_after_each_move():
    gen = MotionGenerator(LOWER, UPPER, START, seed=2, min_duration=1.0, dwell=0.5)
    _, x = run(gen, 10.0)
    speed = np.max(np.abs(x[:, 3:]), axis=1)
    still = speed < 1e-9
    assert 0.15 < still.mean() < 0.6


def test_pause_holds_the_posture_for_its_duration():
    gen = MotionGenerator(LOWER, UPPER, START, seed=1, max_speed=0.5)
    times, x = run(gen, 3.0, pause=np.array([1.0, 2.0]))
    q = x[:, :3]
    # The request (id 1) arrives at the first update; the arm holds for 2 s, then moves on.
    held = (times > 0.05) & (times < 1.95)
    assert np.max(np.abs(q[held] - q[held][0])) < 1e-12
    assert np.max(np.abs(x[held, 3:])) == 0.0
    assert np.max(np.abs(q[times > 2.5] - q[held][0])) > 1e-3


def test_a_pause_during_a_move_brakes_smoothly_then_holds():
    gen = MotionGenerator(LOWER, UPPER, START, seed=1, max_speed=0.5, min_duration=0.5)
    # Request 1 (a 1 s pause) arrives at t = 0.6 s, in the middle of the first move.
    pause = ([0.0, 0.6, 100.0], [[0.0, 0.0], [1.0, 1.0], [1.0, 1.0]])
    times, x = run(gen, 3.0, dt=0.005, pause=pause)
    v = x[:, 3:]
    i = np.searchsorted(times, 0.6)
    assert np.max(np.abs(v[i])) > 0.1  # it was moving
    # The desired velocity has no jump and decelerates at no more than 3 rad/s^2.
    assert np.max(np.abs(np.diff(v, axis=0))) / 0.005 <= 3.0 * 1.05 + 1.0
    stopped = times[i + np.argmax(np.max(np.abs(v[i:]), axis=1) < 1e-12)]
    assert 0.6 < stopped < 0.6 + 0.35
    held = (times > stopped + 0.01) & (times < stopped + 0.99)
    assert np.max(np.abs(x[held, :3] - x[held][0, :3])) < 1e-12


def test_confirm_goes_back_to_the_posture_then_moves_again():
    target = np.array([0.4, 0.7, 0.6])
    gen = MotionGenerator(LOWER, UPPER, START, seed=1, max_speed=0.5, min_duration=0.5)
    times, x = run(gen, 6.0, confirm=np.concatenate([[1.0, -1.0], target]))
    q = x[:, :3]
    reached = np.linalg.norm(q - target, axis=1) < 1e-6
    assert reached.any()
    first = np.argmax(reached)
    assert times[first] < 3.0
    assert np.linalg.norm(q[-1] - target) > 0.05  # and it moved on (only once: edge-trigger)


@pytest.mark.parametrize("joint", [0, 1, 2])
def test_confirm_with_a_joint_moves_only_that_joint_after_returning(joint):
    target = np.array([0.4, 0.7, 0.6])
    gen = MotionGenerator(LOWER, UPPER, START, seed=1, max_speed=0.5, min_duration=0.5)
    _, x = run(gen, 10.0, confirm=np.concatenate([[1.0, joint], target]))
    q = x[:, :3]
    first = np.argmax(np.linalg.norm(q - target, axis=1) < 1e-6)
    assert np.linalg.norm(q[first] - target) < 1e-6
    after = q[first:]
    others = [i for i in range(3) if i != joint]
    # The other joints stay at the target during the confirming move, then babbling resumes.
    others_moved = np.max(np.abs(after[:, others] - target[others]), axis=1) > 1e-9
    assert others_moved.any()
    confirming = after[:np.argmax(others_moved), joint]
    assert np.max(np.abs(confirming - target[joint])) >= 0.3 * (UPPER[joint] - LOWER[joint])
    # It rests at the posture (confirm_hold, 0.5 s by default) before moving again.
    rest = np.abs(after[:, joint] - target[joint]) < 1e-12
    assert 0.45 <= np.argmin(rest) * 0.01 <= 0.56


def test_quick_confirm_answers_in_place_with_steps_of_confirm_step():
    # Request 1 while the first move has barely begun, 2 during the first step (a follow-up:
    # the step finishes first), 3 during the rest after the second step.
    step, hold = 0.05, 0.2
    gen = MotionGenerator(LOWER, UPPER, START, seed=1, max_speed=0.5, min_duration=0.2,
                          confirm_hold=hold, confirm_step=step, confirm_near=0.1)
    times_req = [0.0, 0.15, 0.45, 1.05, 3.0]    # zero-order hold: id i from times_req[i]
    values = [np.concatenate([[i, -1.0], START]) for i in (0, 1, 2, 3, 3)]
    times, x = run(gen, 3.0, confirm=(times_req, values))
    q, v = x[:, :3], x[:, 3:]
    moving = np.max(np.abs(v), axis=1) > 1e-9
    # No return: the arm brakes where it is, close to the posture, and stays within 1.5 steps
    # (plus the braking distance) around it while it confirms.
    window = times < 1.5
    assert np.max(np.abs(q[window] - START)) < 1.5 * step + 0.01
    # Moves start from rest: the first step after the hold at the braking posture, the next
    # ones one step (0.2 s, min_duration) and one hold later (the third request comes 0.09 s
    # into the rest after the second step: that rest counts).
    starts = times[1:][moving[1:] & ~moving[:-1]]
    starts = starts[starts > 0.1]             # after the first move's start at 0
    assert 0.15 + hold - 0.02 <= starts[0] <= 0.15 + hold + 0.08
    np.testing.assert_allclose(np.diff(starts[:3]), 0.2 + hold, atol=0.03)
    # Each step moves every joint by confirm_step.
    for k in range(2):
        i0, i1 = np.searchsorted(times, starts[k]), np.searchsorted(times, starts[k + 1])
        np.testing.assert_allclose(np.abs(q[i1 - 1] - q[i0 - 1]), step, atol=1e-6)
    # With no further request, the arm rests confirm_hold after its last step, then babbles on.
    assert np.max(np.abs(q[-1] - START)) > 0.1


def test_quick_confirm_far_from_the_posture_still_goes_back():
    target = np.array([0.4, 0.7, 0.6])
    gen = MotionGenerator(LOWER, UPPER, START, seed=1, max_speed=0.5, min_duration=0.2,
                          confirm_hold=0.2, confirm_step=0.05, confirm_near=0.1)
    times, x = run(gen, 4.0, confirm=np.concatenate([[1.0, -1.0], target]))
    q, v = x[:, :3], x[:, 3:]
    reached = np.flatnonzero(np.linalg.norm(q - target, axis=1) < 1e-6)
    assert reached.size
    # ... then, after the hold, one step of 0.05 rad per joint, and a rest at its end.
    after = reached[-1] + 1
    rest = after + np.argmax(np.max(np.abs(v[after:]), axis=1) < 1e-12)
    np.testing.assert_allclose(np.abs(q[rest] - target), 0.05, atol=1e-6)


@pytest.mark.parametrize("args", [
    (LOWER, UPPER[:2], START),
    (UPPER, LOWER, START),
    (LOWER, UPPER, [np.nan, 0, 0]),
])
def test_rejects_bad_ranges(args):
    with pytest.raises(ValueError):
        MotionGenerator(*args)


def test_the_babbling_pace_is_the_scenarios_default():
    """``BABBLING_PACE`` (assumed for a motion generator of the user's own) is the station's
    ``MotionConfig`` default pace."""
    from sustain_drake.station.scenario import MotionConfig
    from sustain_drake.systems.motion_generator import BABBLING_PACE

    m = MotionConfig()
    assert BABBLING_PACE == (m.max_speed, m.min_duration, m.dwell)
