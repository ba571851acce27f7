"""Babbling: smooth random joint-space motions within joint ranges, with pause and confirm."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

# Layout of the discrete state vector (n = number of joints); see MotionGenerator.
(_T0, _DURATION, _SEGMENT, _KIND, _PAUSE_ID, _CONFIRM_ID, _CONFIRM_JOINT,
 _PAUSE_LEFT, _CONFIRM_PENDING) = range(9)
_HEADER = 9
# Segment kinds: a babbling move, a rest, the move back to a posture to confirm, braking, the
# rest at that posture before the confirming move, a confirming step.
_MOVE, _HOLD, _RETURN, _BRAKE, _CONFIRM_REST, _STEP = 0.0, 1.0, 2.0, 3.0, 4.0, 5.0
# Peak deceleration when a pause interrupts a move, rad/s^2.
_BRAKE_ACCELERATION = 3.0
# A confirming single-joint move covers at least this fraction of the joint's range.
_CONFIRM_MIN_FRACTION = 0.3


def quintic(q0: np.ndarray, q1: np.ndarray, duration: float, s: float, v0=None):
    """Minimum-jerk-like interpolation from ``q0`` (with velocity ``v0``, default 0) to ``q1``
    (at rest): position and velocity at time ``s`` into the move. Acceleration is zero at both
    ends and velocity continuous, so moves chain smoothly and requests never jerk the arm."""
    if duration <= 0:
        return q1.copy(), np.zeros_like(q1)
    x, V, c3, c4, c5 = _quintic_terms(q0, q1, duration, s, v0)
    q = q0 + V * x + c3 * x**3 + c4 * x**4 + c5 * x**5
    v = (V + 3 * c3 * x**2 + 4 * c4 * x**3 + 5 * c5 * x**4) / duration
    return q, v


def quintic_acceleration(q0: np.ndarray, q1: np.ndarray, duration: float, s: float, v0=None) -> np.ndarray:
    """The acceleration (rad/s^2) of ``quintic``'s move at time ``s`` into it."""
    if duration <= 0:
        return np.zeros_like(q1)
    x, _, c3, c4, c5 = _quintic_terms(q0, q1, duration, s, v0)
    return (6 * c3 * x + 12 * c4 * x**2 + 20 * c5 * x**3) / duration**2


def _quintic_terms(q0, q1, duration: float, s: float, v0):
    """``quintic``'s normalised time and polynomial coefficients."""
    x = min(max(s / duration, 0.0), 1.0)
    delta = q1 - q0
    V = np.zeros_like(q0) if v0 is None else np.asarray(v0) * duration
    return x, V, 10 * delta - 6 * V, -15 * delta + 8 * V, 6 * delta - 3 * V


# The peak speed of a quintic move is 15/8 of its mean speed.
_PEAK_OVER_MEAN = 15.0 / 8.0


class Pace(NamedTuple):
    """The babbling's pace: peak joint speed (rad/s), shortest move (s), rest after a move (s)."""

    max_speed: float
    min_duration: float
    dwell: float


# The pace of the scenarios' babbling (the station's ``MotionConfig`` defaults, which a test keeps
# equal): the one assumed for a motion generator of the user's own.
BABBLING_PACE = Pace(max_speed=0.6, min_duration=1.0, dwell=0.0)


def shortest_move_reach(max_speed: float, min_duration: float) -> float:
    """rad: the largest joint change a move of ``min_duration`` covers at ``max_speed`` (the
    inverse of ``move_duration``)."""
    return max_speed * min_duration / _PEAK_OVER_MEAN


def move_duration(q0: np.ndarray, q1: np.ndarray, max_speed: float, min_duration: float) -> float:
    """s: how long a babbling move from ``q0`` to ``q1`` lasts, ``max(min_duration, 15/8
    |q1 - q0|_max / max_speed)``, so no joint's peak speed exceeds ``max_speed`` (rad/s)."""
    return max(min_duration, _PEAK_OVER_MEAN * float(np.max(np.abs(np.asarray(q1) - q0))) / max_speed)


class MotionGenerator(LeafSystem):
    """Smooth random joint-space motions (babbling) for identification, as in the paper.

    .. pydrake_system::

        name: MotionGenerator
        input_ports:
        - pause (optional)
        - confirm (optional)
        - goal (optional)
        output_ports:
        - desired_state

    ``desired_state`` is ``[q_d, v_d]`` (rad, rad/s) for the n joints, for PD tracking in the
    plant. The motion is a chain of minimum-jerk moves between random goals drawn uniformly
    within ``[lower, upper]``; each move lasts ``max(min_duration, 15/8 |dq|_max /
    max_speed)`` so no joint exceeds ``max_speed``, and may be followed by a rest of ``dwell``
    seconds (quasi-static samples for the inertia identification). The k-th goal is drawn
    from a generator seeded with ``(seed, k)``, so runs are reproducible. ``goal`` (n, rad;
    optional): when connected and finite, each babbling move goes there instead (clipped to the
    ranges), e.g. the posture an ``ExcitingPostures`` chose, the first move included (its goal is
    read at the first update); the confirming moves stay as they are.

    Requests are edge-triggered by an id, so holding a value does not repeat the request:

    - ``pause`` = ``[request_id, duration]``: when ``request_id`` changes, brake smoothly
      (peak deceleration 3 rad/s^2, so within about 0.3 s at the default pace), hold still for
      ``duration`` s, then continue babbling.
    - ``confirm`` = ``[request_id, joint, q_1, ..., q_n]``: when ``request_id`` changes, go
      back to the posture ``q`` (at the pace), rest there ``confirm_hold`` s (so the move
      again has a clear onset), and then move again from there: only joint
      ``joint`` (0-based, by at least 30 % of its range) when ``joint >= 0``, so the visual
      change can be attributed to that joint, or a usual random move when ``joint < 0`` (the
      paper's confirming motion after a coincidence).

    Quick confirming trials (both off by default): with ``confirm_near`` > 0, a request whose
    ``q`` is within ``confirm_near`` (rad, max-norm) of the current posture is answered where
    the arm is: it brakes (or finishes its confirming step) and rests there ``confirm_hold``
    s, counting the rest it already had, instead of moving back. With ``confirm_step`` > 0,
    the move again is a short step of ``confirm_step`` rad per joint (only ``joint`` if
    ``joint >= 0``), towards ``q`` for a joint more than half a step from it, and otherwise the
    way that joint moved when the request came (the move whose start raised it; seeded random
    if it was still), so the steps go out and back and the arm stays within 1.5 steps of
    ``q``, at the pace
    (``min_duration`` at least); after it the arm rests up to ``2 confirm_hold`` s, waiting for
    the next request (which then moves it again ``confirm_hold`` after the step's end or at
    once), then babbles on. A body detector can so test its candidate cells every
    ``step + hold`` seconds (:mod:`sustain_drake.perception.coincidence`).

    Every segment starts from the current desired position and velocity, so requests never
    make the desired state jump. Ids start at 0, so the first request uses 1. Unconnected
    inputs are ignored. The state is a discrete vector (segment start time, duration, index
    and kind, last request ids, pause time left, a confirm pending flag, segment start
    posture, goal and start velocity, the confirm posture and step direction), updated every
    ``period`` s.
    """

    def __init__(self, lower, upper, initial_posture, seed: int = 0, max_speed: float = 0.5,
                 min_duration: float = 1.0, dwell: float = 0.0, period: float = 0.01,
                 confirm_hold: float = 0.5, confirm_step: float = 0.0,
                 confirm_near: float = 0.0):
        super().__init__()
        self._lower = np.asarray(lower, dtype=float)
        self._upper = np.asarray(upper, dtype=float)
        q_init = np.asarray(initial_posture, dtype=float)
        n = self._lower.size
        if self._upper.shape != (n,) or q_init.shape != (n,) or n == 0:
            raise ValueError("lower, upper and initial_posture need the same length n > 0")
        if not (np.all(np.isfinite(self._lower)) and np.all(np.isfinite(self._upper))
                and np.all(self._lower <= self._upper) and np.all(np.isfinite(q_init))):
            raise ValueError("joint ranges must be finite with lower <= upper")
        if not (max_speed > 0 and min_duration > 0 and dwell >= 0 and period > 0
                and confirm_hold >= 0 and confirm_step >= 0 and confirm_near >= 0):
            raise ValueError("max_speed, min_duration, period must be > 0, dwell, "
                             "confirm_hold, confirm_step and confirm_near >= 0")
        self._n = n
        self._seed = int(seed)
        self._period, self._max_speed, self._min_duration, self._dwell = map(
            float, (period, max_speed, min_duration, dwell))
        self._confirm_hold, self._confirm_step, self._confirm_near = map(
            float, (confirm_hold, confirm_step, confirm_near))
        q_init = np.clip(q_init, self._lower, self._upper)

        # Start with a first move from the initial posture (segment 0 -> goal 0).
        x0 = np.zeros(_HEADER + 5 * n)
        goal = self._goal(0)
        x0[_DURATION] = self._move_duration(q_init, goal)
        x0[_SEGMENT] = 1
        x0[_KIND] = _MOVE
        # Request ids start at 0: the first request must use another id (1, 2, ...).
        x0[_PAUSE_ID] = x0[_CONFIRM_ID] = 0.0
        x0[_HEADER:_HEADER + n] = q_init
        x0[_HEADER + n:_HEADER + 2 * n] = goal
        self._state = self.DeclareDiscreteState(x0)
        self._pause = self.DeclareVectorInputPort("pause", 2)
        self._confirm = self.DeclareVectorInputPort("confirm", 2 + n)
        self._goal_in = self.DeclareVectorInputPort("goal", n)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareVectorOutputPort("desired_state", BasicVector(2 * n), self._calc_desired,
                                     {self.time_ticket(), self.xd_ticket()})

    def num_joints(self) -> int:
        return self._n

    def _goal(self, k: int) -> np.ndarray:
        rng = np.random.default_rng([self._seed, k])
        return rng.uniform(self._lower, self._upper)

    def _single_joint_goal(self, q: np.ndarray, j: int, random_goal: np.ndarray) -> np.ndarray:
        """``q`` with only joint j moved to a random value, far enough to be seen."""
        goal = q.copy()
        lo, hi = self._lower[j], self._upper[j]
        goal[j] = random_goal[j]
        if abs(goal[j] - q[j]) < _CONFIRM_MIN_FRACTION * (hi - lo):
            goal[j] = hi if hi - q[j] >= q[j] - lo else lo  # the farther end
        return goal

    def _step_goal(self, q: np.ndarray, q_ref: np.ndarray, direction: np.ndarray, joint: int,
                   k: int) -> np.ndarray:
        """A confirming step from ``q``: ``confirm_step`` per joint (only ``joint`` if >= 0),
        towards ``q_ref`` where a joint is more than half a step away, else along
        ``direction`` (signs; 0: seeded random); within the ranges."""
        d = self._confirm_step
        random = np.where(np.random.default_rng([self._seed, k, 1]).random(self._n) < 0.5,
                          -1.0, 1.0)
        sign = np.where(direction != 0, np.sign(direction), random)
        off = q - q_ref
        sign = np.where(np.abs(off) > d / 2, -np.sign(off), sign)
        goal = q + d * sign
        if joint >= 0:
            goal = np.where(np.arange(self._n) == joint, goal, q)
        return np.clip(goal, self._lower, self._upper)

    def _move_duration(self, q0: np.ndarray, q1: np.ndarray) -> float:
        return move_duration(q0, q1, self._max_speed, self._min_duration)

    def _desired(self, x: np.ndarray, t: float):
        n, h = self._n, _HEADER
        return quintic(x[h:h + n], x[h + n:h + 2 * n], x[_DURATION], t - x[_T0],
                       x[h + 2 * n:h + 3 * n])

    def _calc_desired(self, context, output) -> None:
        x = context.get_discrete_state(self._state).get_value()
        q, v = self._desired(x, context.get_time())
        output.SetFromVector(np.concatenate([q, v]))

    def _start(self, x: np.ndarray, t: float, q0, q1, duration: float, kind: float,
               v0=None) -> None:
        n, h = self._n, _HEADER
        x[_T0], x[_DURATION], x[_KIND] = t, duration, kind
        x[h:h + n] = q0
        x[h + n:h + 2 * n] = q1
        x[h + 2 * n:h + 3 * n] = 0.0 if v0 is None else v0

    def _brake(self, x: np.ndarray, t: float, q, v) -> None:
        """Stop smoothly from (q, v): the quintic from v to rest with goal q + v T / 2 has a
        monotone speed and peak deceleration 1.5 |v| / T."""
        duration = max(self._period, 1.5 * float(np.max(np.abs(v))) / _BRAKE_ACCELERATION)
        stop = np.clip(q + v * duration / 2, self._lower, self._upper)
        self._start(x, t, q, stop, duration, _BRAKE, v)

    def _confirm_request(self, x: np.ndarray, t: float, q_now, v_now, request) -> None:
        """A new confirm request: back to its posture, or (``confirm_near``) rest where the
        arm is."""
        x[_CONFIRM_ID] = request[0]
        x[_CONFIRM_JOINT] = int(request[1]) if 0 <= request[1] < self._n else -1
        target = np.clip(request[2:], self._lower, self._upper)
        n = self._n
        x[_HEADER + 3 * n:_HEADER + 4 * n] = target    # the steps' reference posture
        # The steps go out the way the arm was moving when the request came (the motion whose
        # start coincided with the candidate cells' onsets), and back.
        x[_HEADER + 4 * n:] = np.sign(v_now) if np.any(v_now != 0) else x[_HEADER + 4 * n:]
        x[_CONFIRM_PENDING] = 0.0
        if not (self._confirm_near > 0
                and np.max(np.abs(q_now - target)) <= self._confirm_near):
            self._start(x, t, q_now, target, self._move_duration(q_now, target), _RETURN, v_now)
            return
        moving = t < x[_T0] + x[_DURATION] and x[_KIND] not in (_HOLD, _CONFIRM_REST)
        if moving and x[_KIND] == _STEP:
            x[_CONFIRM_PENDING] = 1.0              # finish the step, then rest and step again
        elif moving:
            self._brake(x, t, q_now, v_now)
            x[_KIND] = _RETURN                     # braking ends in the confirming rest
        else:
            rested = t - x[_T0] if x[_KIND] in (_HOLD, _CONFIRM_REST) else 0.0
            self._start(x, t, q_now, q_now, max(self._confirm_hold - rested, self._period),
                        _CONFIRM_REST)

    def _update(self, context, discrete_state) -> None:
        x = context.get_discrete_state(self._state).get_value().copy()
        t = context.get_time()
        q_now, v_now = self._desired(x, t)
        if self._confirm.HasValue(context):
            request = self._confirm.Eval(context)
            if np.all(np.isfinite(request)) and request[0] != x[_CONFIRM_ID]:
                self._confirm_request(x, t, q_now, v_now, request)
                discrete_state.set_value(self._state, x)
                return
        if self._pause.HasValue(context):
            request = self._pause.Eval(context)
            if np.all(np.isfinite(request)) and request[0] != x[_PAUSE_ID]:
                x[_PAUSE_ID] = request[0]
                x[_PAUSE_LEFT] = max(float(request[1]), 0.0)
                self._brake(x, t, q_now, v_now)
                discrete_state.set_value(self._state, x)
                return
        if x[_SEGMENT] == 1 and x[_KIND] == _MOVE and t - x[_T0] < 0.5 * self._period \
                and self._goal_in.HasValue(context):
            # The first update: with a goal input, the first move too goes where it says.
            goal = self._babbling_goal(context, 0)
            self._start(x, t, x[_HEADER:_HEADER + self._n], goal,
                        self._move_duration(x[_HEADER:_HEADER + self._n], goal), _MOVE)
            discrete_state.set_value(self._state, x)
            return
        if t < x[_T0] + x[_DURATION]:
            return
        k = int(x[_SEGMENT])
        n = self._n
        if x[_KIND] == _STEP and x[_CONFIRM_PENDING] > 0:
            x[_CONFIRM_PENDING] = 0.0
            self._start(x, t, q_now, q_now, max(self._confirm_hold, self._period), _CONFIRM_REST)
        elif x[_KIND] == _STEP:
            # Rest, waiting for a follow-up request (answered in place, counting this rest),
            # then babble on. Twice the hold: the detector decides on a follow-up only when
            # the trial's response window has closed, and the arm lags its desired state.
            self._start(x, t, q_now, q_now, max(2 * self._confirm_hold, self._period), _HOLD)
        elif x[_KIND] in (_RETURN, _CONFIRM_REST) and self._confirm_step > 0 and not (
                x[_KIND] == _RETURN and self._confirm_hold > 0):
            h = _HEADER
            goal = self._step_goal(q_now, x[h + 3 * n:h + 4 * n], x[h + 4 * n:],
                                   int(x[_CONFIRM_JOINT]), k)
            x[_SEGMENT] = k + 1
            self._start(x, t, q_now, goal, self._move_duration(q_now, goal), _STEP)
        elif x[_KIND] == _BRAKE:
            self._start(x, t, q_now, q_now, x[_PAUSE_LEFT], _HOLD)
        elif x[_KIND] == _MOVE and self._dwell > 0:
            self._start(x, t, q_now, q_now, self._dwell, _HOLD)
        elif x[_KIND] == _RETURN and self._confirm_hold > 0:
            self._start(x, t, q_now, q_now, self._confirm_hold, _CONFIRM_REST)
        elif x[_KIND] in (_RETURN, _CONFIRM_REST) and x[_CONFIRM_JOINT] >= 0:
            goal = self._single_joint_goal(q_now, int(x[_CONFIRM_JOINT]), self._goal(k))
            x[_SEGMENT] = k + 1
            self._start(x, t, q_now, goal, self._move_duration(q_now, goal), _MOVE)
        else:
            goal = self._babbling_goal(context, k)
            x[_SEGMENT] = k + 1
            self._start(x, t, q_now, goal, self._move_duration(q_now, goal), _MOVE)
        discrete_state.set_value(self._state, x)

    def _babbling_goal(self, context, k: int) -> np.ndarray:
        """The next babbling move's goal: the ``goal`` input when connected and finite (within the
        ranges), else the k-th random goal."""
        if self._goal_in.HasValue(context):
            goal = self._goal_in.Eval(context)
            if np.all(np.isfinite(goal)):
                return np.clip(goal, self._lower, self._upper)
        return self._goal(k)
