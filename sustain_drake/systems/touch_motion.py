"""Touching motion with the paper's "keep touching" rule (§4.4), between the babbling generator and
the arm."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from sustain_drake.systems.motion_generator import quintic

# Phases of the touching program.
PASS, MOVE, REST, APPROACH, DESCEND, PRESS, KEEP, LIFT, RELEASE, HANDBACK, DONE = range(11)
PHASE_NAMES = ("PASS", "MOVE", "REST", "APPROACH", "DESCEND", "PRESS", "KEEP", "LIFT", "RELEASE", "HANDBACK",
               "DONE")
# Layout of the header of the discrete state.
_PHASE, _INDEX, _T0, _DURATION, _START_SINCE, _TOUCH_S, _DETECTED, _MISSED = range(8)
_HEADER = 8
# The peak speed of a quintic move is 15/8 of its mean speed.
_PEAK_OVER_MEAN = 15.0 / 8.0


@dataclass(frozen=True)
class TouchPosture:
    """One touch: the arm posture with the tool's touching feature ``approach_height`` above the
    table point (``q_above``), ``press_depth`` below it (``q_press``) and, for the moves between
    touches, ``retreat_height`` above it (``q_high``), rad."""

    q_above: tuple[float, ...]
    q_press: tuple[float, ...]
    q_high: tuple[float, ...]


class TouchMotion(LeafSystem):
    """Passes the babbling motion through until told to touch, then touches the table at each
    posture in turn, keeping the touch once it is felt.

    .. pydrake_system::

        name: TouchMotion
        input_ports:
        - babble_state
        - start (optional)
        - touch (optional)
        output_ports:
        - desired_state
        - phase

    ``babble_state`` is the ``MotionGenerator``'s ``[q_d, v_d]``; ``desired_state`` (2n) goes to
    the arm's PD controllers. While ``start`` (1) is below 0.5 (or unconnected) the babbling
    passes through. Once it has been above 0.5 for ``start_delay`` s (the pause after an
    identification), the program runs; each touch is:

    1. MOVE: a minimum-jerk move (peak joint speed ``max_speed``) to ``q_high``, well above the
       table (moves between touches change the tool's orientation, which sweeps its corners),
       REST there ``rest`` s (quasi-static samples: the identify <-> observe rule keeps
       observing the held body between touches), then APPROACH ``q_above``;
    2. DESCEND: towards ``q_press`` at a constant rate (``descend_duration`` s for the whole way);
    3. the "keep touching" rule (paper §4.4): when ``touch`` (1, the touch estimator's flag)
       rises, PRESS on by ``press_extra`` of the descent (a fraction, 0..1) and KEEP the
       posture for ``keep_touching`` s; a descent that ends with no touch felt is a miss;
    4. LIFT back to ``q_high``.

    After the last posture it starts again from the first if ``repeat``, else it holds (DONE).
    When ``start`` falls during the program (the body changed: identify again), the arm lifts
    (RELEASE, to ``q_high``) and the babbling takes over smoothly (HANDBACK: a 1 s blend).
    ``phase`` (4) is ``[phase, index of the touch, touches felt, misses]`` (phase: see
    ``PHASE_NAMES``).

    State: one discrete vector (phase, touch index, segment start time and duration, since when
    ``start`` is high, the descent fraction at the touch, counts, segment start and goal postures
    and start velocity), updated every ``period`` s.
    """

    def __init__(self, postures: list[TouchPosture], descend_duration: float, keep_touching: float,
                 press_extra: float, max_speed: float, start_delay: float = 3.0, repeat: bool = True,
                 period: float = 0.01, min_duration: float = 1.0, rest: float = 0.0):  # fmt: skip
        super().__init__()
        if not postures:
            raise ValueError("TouchMotion needs at least one touch posture")
        self._above = np.array([p.q_above for p in postures], dtype=float)
        self._press = np.array([p.q_press for p in postures], dtype=float)
        self._high = np.array([p.q_high for p in postures], dtype=float)
        n = self._above.shape[1]
        if (self._press.shape != self._above.shape or self._high.shape != self._above.shape
                or not np.all(np.isfinite(self._above + self._press + self._high))):
            raise ValueError("touch postures need finite q_above and q_press of the same length")
        if not (descend_duration > 0 and keep_touching >= 0 and 0 <= press_extra <= 1 and max_speed > 0
                and start_delay >= 0 and period > 0 and min_duration > 0 and rest >= 0):  # fmt: skip
            raise ValueError("TouchMotion: durations and speeds must be positive, press_extra in [0, 1]")
        self._n = n
        self._descend, self._keep, self._extra, self._rest = map(
            float, (descend_duration, keep_touching, press_extra, rest))
        self._max_speed, self._delay, self._min_duration = map(float, (max_speed, start_delay, min_duration))
        self._repeat = bool(repeat)
        x0 = np.zeros(_HEADER + 3 * n)
        x0[_START_SINCE] = -1.0
        x0[_TOUCH_S] = -1.0
        self._state = self.DeclareDiscreteState(x0)
        self._babble = self.DeclareVectorInputPort("babble_state", 2 * n)
        self._start_in = self.DeclareVectorInputPort("start", 1)
        self._touch_in = self.DeclareVectorInputPort("touch", 1)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareVectorOutputPort("desired_state", BasicVector(2 * n), self._calc_desired)
        self.DeclareVectorOutputPort(
            "phase", 4, lambda c, o: o.SetFromVector(self._x(c)[[_PHASE, _INDEX, _DETECTED, _MISSED]]),
            prerequisites_of_calc={self.xd_ticket()},
        )  # fmt: skip

    def postures(self) -> list[TouchPosture]:
        """The touch postures, in order."""
        return [TouchPosture(tuple(a), tuple(p), tuple(h))
                for a, p, h in zip(self._above, self._press, self._high, strict=True)]

    def _x(self, context) -> np.ndarray:
        return context.get_discrete_state(self._state).get_value()

    def _segment(self, x, t):
        """Desired (q, v) of the program's current segment at time t."""
        n, h = self._n, _HEADER
        q0, q1, v0 = x[h:h + n], x[h + n:h + 2 * n], x[h + 2 * n:]
        s = t - x[_T0]
        if x[_PHASE] == DESCEND:  # constant rate from q0 to q1
            a = min(max(s / x[_DURATION], 0.0), 1.0)
            v = (q1 - q0) / x[_DURATION] if a < 1.0 else np.zeros(n)
            return q0 + a * (q1 - q0), v
        return quintic(q0, q1, x[_DURATION], s, v0)

    def _desired(self, context, x, t):
        phase = x[_PHASE]
        babble = self._babble.Eval(context)
        if phase == PASS:
            return babble[:self._n], babble[self._n:]
        q, v = self._segment(x, t)
        if phase == HANDBACK:  # a smooth blend from the lifted posture to the babbling
            a = min(max((t - x[_T0]) / x[_DURATION], 0.0), 1.0)
            w, dw = a * a * (3 - 2 * a), 6 * a * (1 - a) / x[_DURATION]
            return ((1 - w) * q + w * babble[:self._n],
                    (1 - w) * v + w * babble[self._n:] + dw * (babble[:self._n] - q))
        return q, v

    def _calc_desired(self, context, output) -> None:
        q, v = self._desired(context, self._x(context), context.get_time())
        output.SetFromVector(np.concatenate([q, v]))

    def _start(self, x, t, phase, q0, q1, duration, v0=None) -> None:
        n, h = self._n, _HEADER
        x[_PHASE], x[_T0], x[_DURATION] = phase, t, duration
        x[h:h + n] = q0
        x[h + n:h + 2 * n] = q1
        x[h + 2 * n:] = 0.0 if v0 is None else v0

    def _move_duration(self, q0, q1) -> float:
        return max(self._min_duration, _PEAK_OVER_MEAN * float(np.max(np.abs(q1 - q0))) / self._max_speed)

    def _move_to(self, x, t, phase, q, v, goal) -> None:
        self._start(x, t, phase, q, goal, self._move_duration(q, goal), v)

    def _update(self, context, discrete_state) -> None:
        x = self._x(context).copy()
        t = context.get_time()
        start = self._start_in.HasValue(context) and self._start_in.Eval(context)[0] > 0.5
        touch = self._touch_in.HasValue(context) and self._touch_in.Eval(context)[0] > 0.5
        phase = x[_PHASE]
        x[_START_SINCE] = (x[_START_SINCE] if x[_START_SINCE] >= 0 else t) if start else -1.0
        q, v = self._desired(context, x, t)
        k = int(x[_INDEX])
        ended = t >= x[_T0] + x[_DURATION] - 1e-9
        if phase in (PASS, HANDBACK):
            if start and t - x[_START_SINCE] >= self._delay - 1e-9:
                x[_INDEX] = k = 0 if phase == PASS else k
                self._move_to(x, t, MOVE, q, v, self._high[k])
            elif phase == HANDBACK and ended:
                x[_PHASE] = PASS
        elif not start and phase != RELEASE:
            self._move_to(x, t, RELEASE, q, v, self._high[k])
        elif phase == MOVE and ended:
            self._start(x, t, REST, q, q, self._rest)
        elif phase == REST and ended:
            self._move_to(x, t, APPROACH, q, v, self._above[k])
        elif phase == APPROACH and ended:
            self._start(x, t, DESCEND, self._above[k], self._press[k], self._descend)
            x[_TOUCH_S] = -1.0
        elif phase == DESCEND and touch:
            # Keep touching: press on a little from where the touch was felt, then hold.
            a = min((t - x[_T0]) / self._descend, 1.0)
            x[_TOUCH_S] = a
            x[_DETECTED] += 1
            goal = self._above[k] + min(a + self._extra, 1.0) * (self._press[k] - self._above[k])
            self._start(x, t, PRESS, q, goal, max(self._extra * self._descend, 0.05), v)
        elif phase == DESCEND and ended:
            x[_MISSED] += 1
            self._move_to(x, t, LIFT, q, v, self._high[k])
        elif phase == PRESS and ended:
            self._start(x, t, KEEP, q, q, self._keep)
        elif phase == KEEP and ended:
            self._move_to(x, t, LIFT, q, v, self._high[k])
        elif phase == LIFT and ended:
            if k + 1 < len(self._above) or self._repeat:
                x[_INDEX] = k = (k + 1) % len(self._above)
                self._move_to(x, t, MOVE, q, v, self._high[k])
            else:
                self._start(x, t, DONE, q, q, 1.0)
        elif phase == RELEASE and ended:
            self._start(x, t, HANDBACK, q, q, 1.0)
        discrete_state.set_value(self._state, x)
