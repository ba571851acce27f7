"""Synthetic per-cell signals for tests and benchmarks of the coincidence detector (no images).

A toy robot with ``n_a`` joints moves in random segments separated by pauses and honours the
detector's confirming-motion requests (back to ``q*``, hold, move again). Body cells show
visual motion one frame after any of their driving joints moves; distractor cells have visual
onsets at a fixed rate (a Poisson process), independent of the robot, each lasting a while.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .coincidence import CoincidenceParams, CoincidenceState, step


@dataclass
class SyntheticWorld:
    n_a: int = 6
    n_c: int = 40
    body_drivers: dict[int, tuple[int, ...]] = field(
        default_factory=lambda: {0: (0,), 1: (0, 1), 2: (1, 2), 3: (3,), 4: (4, 5)})
    distractor_cells: tuple[int, ...] = (20, 21, 22, 23, 24, 25, 26, 27)
    distractor_rate: float = 0.5        # visual onsets per second per distractor cell
    distractor_duration: tuple[float, float] = (0.2, 0.8)
    move_duration: tuple[float, float] = (0.4, 1.2)
    pause_duration: tuple[float, float] = (0.3, 1.0)
    joint_speed: float = 0.5            # rad/s while moving
    flow_px_s: float = 60.0             # ṡ of a moving cell, px/s
    initial_still: float = 3.0          # s the robot watches before its first motion


def run(world: SyntheticWorld, duration: float, seed: int, dt: float = 1.0 / 30.0,
        params: CoincidenceParams | None = None, honour_requests: bool = True):
    """Simulate ``duration`` s; returns (final state, times (T), body masks (T x n_c) and
    visual changes ṡ (T x n_c))."""
    params = CoincidenceParams() if params is None else params
    rng = np.random.default_rng(seed)
    q = np.zeros(world.n_a)
    state = CoincidenceState(world.n_a, world.n_c)
    velocity = np.zeros(world.n_a)
    segment_end = world.initial_still   # starts still: the detector learns each cell's rate
    moving_segment = False
    confirm_phase = None                # None, or ("return"|"hold", end time)
    last_request = 0
    hold = params.hold_min
    prev_moving = np.zeros(world.n_a, bool)
    distractor_until = np.full(world.n_c, -1.0)
    next_distractor = {j: rng.exponential(1 / world.distractor_rate)
                       for j in world.distractor_cells}
    times, masks, sdots = [], [], []
    t = 0.0
    while t < duration:
        t += dt
        if honour_requests and state.request_count > last_request and state.request_active:
            last_request = int(state.request_count)
            target = state.q_request.copy()
            velocity = (target - q) / 0.2
            confirm_phase = ("return", t + 0.2, target)
            hold = state.hold_time(params)
        if confirm_phase is not None:
            kind, end, target = confirm_phase
            if t >= end:
                if kind == "return":
                    q = target.copy()
                    velocity[:] = 0
                    confirm_phase = ("hold", t + hold, target)
                else:
                    confirm_phase = None
                    velocity = rng.choice([-1, 1], world.n_a) * world.joint_speed
                    moving_segment, segment_end = True, t + rng.uniform(*world.move_duration)
        elif t >= segment_end:
            moving_segment = not moving_segment
            if moving_segment:
                velocity = rng.choice([-1, 0, 1], world.n_a) * world.joint_speed
                segment_end = t + rng.uniform(*world.move_duration)
            else:
                velocity[:] = 0
                segment_end = t + rng.uniform(*world.pause_duration)
        q = q + velocity * dt
        moving = velocity != 0
        sdot = np.zeros(world.n_c)
        for j, drivers in world.body_drivers.items():
            if prev_moving[list(drivers)].any():      # one frame of camera latency
                sdot[j] = world.flow_px_s
        for j in world.distractor_cells:
            if t >= next_distractor[j]:
                distractor_until[j] = t + rng.uniform(*world.distractor_duration)
                next_distractor[j] = distractor_until[j] + rng.exponential(
                    1 / world.distractor_rate)
            if t < distractor_until[j]:
                sdot[j] = world.flow_px_s
        prev_moving = moving
        state = step(state, t, q, sdot, params)
        times.append(t)
        masks.append(state.body(params))
        sdots.append(sdot)
    return state, np.array(times), np.array(masks), np.array(sdots)
