"""The walking distractor: a person following a scripted floor path."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem


class DistractorPath(LeafSystem):
    """The desired planar state of the walking person, a pure function of time.

    .. pydrake_system::

        name: DistractorPath
        output_ports:
        - desired_state

    ``desired_state`` is ``[x, y, yaw, vx, vy, yaw_rate]`` (m, rad, m/s, rad/s) for the
    person's x-y-yaw joints (PD-tracked by the plant). Before ``start_time`` the person stands
    at the first waypoint; then it walks the waypoints at ``speed``, facing where it goes. With
    ``loop`` it walks back and forth forever, else it stops at the last waypoint. Stateless, so
    it needs no context beyond time.
    """

    def __init__(self, waypoints, speed: float, start_time: float = 0.0, loop: bool = True):
        super().__init__()
        points = np.asarray(waypoints, dtype=float)
        if points.ndim != 2 or points.shape[1] != 2 or len(points) < 2:
            raise ValueError("waypoints must be at least 2 [x, y] points")
        if not (np.all(np.isfinite(points)) and speed > 0 and np.isfinite(start_time)):
            raise ValueError("waypoints must be finite and speed > 0")
        if loop:  # back and forth: the path and its reverse
            points = np.vstack([points, points[-2::-1]])
        steps = np.diff(points, axis=0)
        lengths = np.linalg.norm(steps, axis=1)
        keep = lengths > 1e-9
        self._starts = points[:-1][keep]
        self._steps = steps[keep]
        self._lengths = lengths[keep]
        if len(self._lengths) == 0:
            raise ValueError("waypoints must not all coincide")
        self._cumulative = np.concatenate([[0.0], np.cumsum(self._lengths)])
        # Per segment, what state_at needs (evaluated at every physics step): its start, direction
        # and heading as Python floats, computed as state_at computed them per call.
        self._segments = []
        for start, step, length in zip(self._starts, self._steps, self._lengths, strict=True):
            direction = step / length
            self._segments.append((float(start[0]), float(start[1]), float(direction[0]),
                                   float(direction[1]), float(np.arctan2(direction[1], direction[0]))))
        self._speed = float(speed)
        self._start_time = float(start_time)
        self._loop = bool(loop)
        self.DeclareVectorOutputPort("desired_state", BasicVector(6), self._calc,
                                     {self.time_ticket()})

    def state_at(self, t: float) -> np.ndarray:
        """``[x, y, yaw, vx, vy, yaw_rate]`` at time ``t``."""
        distance = max(t - self._start_time, 0.0) * self._speed
        total = self._cumulative[-1]
        moving = t > self._start_time
        if self._loop:
            distance = distance % total
        elif distance >= total:
            distance, moving = total, False
        i = min(max(int(np.searchsorted(self._cumulative, distance, side="right")) - 1, 0),
                len(self._lengths) - 1)
        x0, y0, dx, dy, yaw = self._segments[i]
        along = distance - float(self._cumulative[i])
        v = (dx * self._speed, dy * self._speed) if moving else (0.0, 0.0)
        return np.array([x0 + dx * along, y0 + dy * along, yaw, v[0], v[1], 0.0])

    def _calc(self, context, output) -> None:
        output.SetFromVector(self.state_at(context.get_time()))
