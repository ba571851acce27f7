"""Which wrench samples the payload identifier may use: quasi-static (the static formulation) and
not touched (§4.4)."""

from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import LeafSystem

# Layout of the discrete state: the verdict, since when still, since when touched (-1: not
# touched), when a touch was last seen, then the previous joint velocities.
_VALID, _STILL_SINCE, _TOUCH_SINCE, _TOUCH_LAST = range(4)
_HEADER = 4


class QuasiStaticGate(LeafSystem):
    """``sample_valid`` for the payload identifier (the formulation of Eq. (37) is static).

    .. pydrake_system::

        name: QuasiStaticGate
        input_ports:
        - joint_velocities
        - touch (optional)
        output_ports:
        - sample_valid

    The rule, checked every ``period`` s from the joint encoders only (as on a real arm):

    1. *Quasi-static*: every joint speed is below ``max_speed`` (rad/s) and every joint
       acceleration (the difference of successive velocity readings over ``period``) below
       ``max_acceleration`` (rad/s^2), and has been so for at least ``window`` s. The payload's
       inertial wrench then stays far below the sensor noise: at 0.6 kg and 0.5 m from the
       shoulder, 0.02 rad/s^2 is 6 mN, 0.02 rad/s gives a centripetal 0.1 mN.
    2. *Not touched*: the touch estimator's ``touch`` (1, optional) is 0 and has been 0 for
       ``touch_holdoff`` s. A touch is a contact, not a change of the held body, so its samples
       are kept out of both the statistic and the observation (else the identify <-> observe
       rule would count a sustained touch as violations and re-identify). A "touch" that lasts
       longer than ``max_touch_duration`` s is no longer treated as one: its samples pass, so
       that a real change of the body (an object stuck to the tool) is observed and re-identified.

    With ``require_still`` False, rule 1 is off and only rule 2 applies: the dynamic payload
    formulation (``identification.payload_dynamic``) models the motion, so moving samples count,
    from ``window`` s after the start on.

    ``sample_valid`` (1) is 1 or 0, from the state (one ``period`` behind the inputs).
    """

    def __init__(self, num_joints: int, period: float = 0.01, max_speed: float = 0.02,
                 max_acceleration: float = 0.05, window: float = 0.2, touch_holdoff: float = 0.5,
                 max_touch_duration: float = 20.0, require_still: bool = True):  # fmt: skip
        super().__init__()
        self._require_still = bool(require_still)
        values = (period, max_speed, max_acceleration, max_touch_duration)
        if not (all(v > 0 and math.isfinite(v) for v in values) and window >= 0 and touch_holdoff >= 0):
            raise ValueError("QuasiStaticGate: period, thresholds and max_touch_duration must be > 0")
        self._n = int(num_joints)
        self._period, self._max_speed, self._max_acceleration = map(
            float, (period, max_speed, max_acceleration))
        self._window, self._holdoff, self._max_touch = map(float, (window, touch_holdoff, max_touch_duration))
        x0 = np.zeros(_HEADER + self._n)
        x0[_TOUCH_SINCE] = -1.0
        x0[_TOUCH_LAST] = -math.inf
        self._state = self.DeclareDiscreteState(x0)
        self._velocities = self.DeclareVectorInputPort("joint_velocities", self._n)
        self._touch = self.DeclareVectorInputPort("touch", 1)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._update)
        self.DeclareVectorOutputPort(
            "sample_valid", 1, lambda c, o: o.SetAtIndex(0, self._x(c)[_VALID]),
            prerequisites_of_calc={self.xd_ticket()},
        )  # fmt: skip

    def _x(self, context) -> np.ndarray:
        return context.get_discrete_state(self._state).get_value()

    def _update(self, context, discrete_state) -> None:
        x = self._x(context).copy()
        t = context.get_time()
        v = np.asarray(self._velocities.Eval(context), dtype=float)
        a = (v - x[_HEADER:]) / self._period
        first = t < 0.5 * self._period  # no previous reading yet
        still = not self._require_still or (
            np.all(np.abs(v) < self._max_speed) and np.all(np.isfinite(v))
            and (first or np.all(np.abs(a) < self._max_acceleration)))  # fmt: skip
        if not still:
            x[_STILL_SINCE] = math.inf
        elif not math.isfinite(x[_STILL_SINCE]) or first:
            # A still start counts as still for the window already, except without rule 1: then the
            # first window is left out (the simulated reading before the plant's first step, the
            # grip settling under the payload's weight).
            x[_STILL_SINCE] = t if not first or not self._require_still else t - self._window
        touched = self._touch.HasValue(context) and self._touch.Eval(context)[0] > 0.5
        if touched:
            x[_TOUCH_SINCE] = x[_TOUCH_SINCE] if x[_TOUCH_SINCE] >= 0 else t
            x[_TOUCH_LAST] = t
        else:
            x[_TOUCH_SINCE] = -1.0
        sustained = touched and t - x[_TOUCH_SINCE] > self._max_touch
        untouched = sustained or (not touched and t - x[_TOUCH_LAST] >= self._holdoff)
        x[_VALID] = 1.0 if (still and t - x[_STILL_SINCE] >= self._window - 1e-9 and untouched) else 0.0
        x[_HEADER:] = v
        discrete_state.set_value(self._state, x)
