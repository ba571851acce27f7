"""The disturbance timeline: the tool slips in the gripper, the head moves, a touch pushes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.framework import BasicVector, LeafSystem

from sustain_drake.systems.motion_generator import quintic


@dataclass(frozen=True)
class Step:
    """At ``time`` a target vector starts moving to ``value`` and reaches it after
    ``duration`` (a minimum-jerk ramp, so the PD-tracked joints move smoothly but fast)."""

    time: float
    value: tuple[float, ...]
    duration: float


@dataclass(frozen=True)
class Push:
    """A force ``f_B`` (N, expressed in body B) applied at ``p_BQ`` (m, in B) during
    ``[time, time + duration)``."""

    time: float
    duration: float
    p_BQ: tuple[float, float, float]
    f_B: tuple[float, float, float]


def piecewise_target(initial, steps: list[Step], t: float):
    """Target position and velocity at ``t`` of a timeline of steps (sorted by time)."""
    q = np.asarray(initial, dtype=float)
    v = np.zeros_like(q)
    for step in steps:
        if t < step.time:
            break
        q, v = quintic(q, np.asarray(step.value, dtype=float), step.duration, t - step.time)
    return q, v


class DisturbanceScheduler(LeafSystem):
    """Plays a scenario's timeline of disturbances; a pure function of time (stateless).

    .. pydrake_system::

        name: DisturbanceScheduler
        input_ports:
        - body_poses
        output_ports:
        - head_desired_state
        - tool_desired_state
        - applied_forces
        - true_touch

    ``head_desired_state`` = ``[pan, tilt, pan_rate, tilt_rate]`` for the pan-tilt head's PD
    actuators (a head move). ``tool_desired_state`` = ``[slide, pivot, slide_rate,
    pivot_rate]`` for the stiff PD joints that hold the tool in the grasp (a tool slip).
    ``applied_forces`` is a list of ``ExternallyAppliedSpatialForce`` for the plant's
    ``applied_spatial_force`` input (touches on the held tool); the pushes are given in the
    tool's frame and turned into the world frame with ``body_poses`` (the plant's body poses
    output, which depends on state only, so there is no algebraic loop).

    ``true_touch`` (ground truth, for evaluating touch estimation) = ``[active, p_KQ, f_K]``:
    1 while a touch is applied (else all zeros), the touched point Q and the touch force in
    the sensor frame K (m, N), for the first active touch. K is ``X_SK`` on body S
    (``sensor_body``).
    """

    def __init__(self, head_initial, head_steps: list[Step], tool_initial,
                 tool_steps: list[Step], pushes: list[Push], tool_body: BodyIndex | None,
                 sensor_body: BodyIndex | None = None, X_SK: RigidTransform | None = None):
        super().__init__()
        self._head_initial = np.asarray(head_initial, dtype=float)
        self._tool_initial = np.asarray(tool_initial, dtype=float)
        self._head_steps = sorted(head_steps, key=lambda s: s.time)
        self._tool_steps = sorted(tool_steps, key=lambda s: s.time)
        self._pushes = list(pushes)
        if self._pushes and tool_body is None:
            raise ValueError("a touch needs a held tool")
        self._tool_body = tool_body
        self._sensor_body = sensor_body
        self._X_SK = RigidTransform() if X_SK is None else X_SK
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()]))
        time_only = {self.time_ticket()}
        self.DeclareVectorOutputPort(
            "head_desired_state", BasicVector(2 * self._head_initial.size),
            lambda c, o: o.SetFromVector(self._target(self._head_initial, self._head_steps, c)),
            time_only)
        self.DeclareVectorOutputPort(
            "tool_desired_state", BasicVector(2 * self._tool_initial.size),
            lambda c, o: o.SetFromVector(self._target(self._tool_initial, self._tool_steps, c)),
            time_only)
        self.DeclareAbstractOutputPort(
            "applied_forces", lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()]),
            self._calc_forces, {self.time_ticket(), self._poses.ticket()})
        if sensor_body is not None:
            self.DeclareVectorOutputPort("true_touch", BasicVector(7), self._calc_true_touch,
                                         {self.time_ticket(), self._poses.ticket()})

    @staticmethod
    def _target(initial, steps, context) -> np.ndarray:
        q, v = piecewise_target(initial, steps, context.get_time())
        return np.concatenate([q, v])

    def active_pushes(self, t: float) -> list[Push]:
        return [p for p in self._pushes if p.time <= t < p.time + p.duration]

    def _calc_forces(self, context, output) -> None:
        forces = []
        pushes = self.active_pushes(context.get_time())
        if pushes:
            R_WB = self._poses.Eval(context)[int(self._tool_body)].rotation()
        for push in pushes:
            force = ExternallyAppliedSpatialForce()
            force.body_index = self._tool_body
            force.p_BoBq_B = np.asarray(push.p_BQ, dtype=float)
            force.F_Bq_W = SpatialForce(np.zeros(3), R_WB @ np.asarray(push.f_B, dtype=float))
            forces.append(force)
        output.set_value(forces)

    def _calc_true_touch(self, context, output) -> None:
        pushes = self.active_pushes(context.get_time())
        if not pushes:
            output.SetFromVector(np.zeros(7))
            return
        poses = self._poses.Eval(context)
        X_KB = (poses[int(self._sensor_body)] @ self._X_SK).inverse() @ \
            poses[int(self._tool_body)]
        push = pushes[0]
        p_KQ = X_KB @ np.asarray(push.p_BQ, dtype=float)
        f_K = X_KB.rotation() @ np.asarray(push.f_B, dtype=float)
        output.SetFromVector(np.concatenate([[1.0], p_KQ, f_K]))
