"""Random disturbances drawn from a seed: the scenario section ``random_disturbances``.

A soak (``diagrams/soak.yaml``) disturbs the world every few minutes, at random: a tool slip or a
camera move of random size within the section's ranges. ``draw`` expands the section into a
concrete timeline, deterministically (a numpy ``Generator`` seeded with ``seed``), before the
diagram is built; ``station.scenario.timeline`` turns it into ``ToolSlip`` and ``HeadMove``
entries beside the scenario's own ``disturbances``, so the disturbance systems and the metrics see
a plain timeline. This module is pure (no Drake): the same section, run length and initial state
give the same list.

Each disturbance is a change from the state before it (the slip state and the head's angles carry
over from one to the next), of a size drawn within the section's ranges and a random sign or
direction; a change that would leave its limit (around the configured grasp and head angles) goes
the other way, so the tool stays in the grasp and the scene in view.
"""

import dataclasses
import math
from dataclasses import field

import numpy as np

# s: a change's detection (1 s) and re-convergence (15 s) targets (experiments.targets): the least
# spacing of random disturbances, and the time the last one has before the run ends, so each one
# settles before the next (tests/test_random_disturbances.py checks it against the targets).
SETTLE = 16.0
SLIP, HEAD_MOVE = "tool_slip", "head_move"


@dataclasses.dataclass
class RandomDisturbances:
    """Tool slips and camera moves at random times and of random sizes, drawn from a seed (a soak:
    ``diagrams/soak.yaml``); each is a change from the state before it, kept within limits."""

    enabled: bool = False  # draw the disturbances (added to the timeline of ``disturbances``)
    # seed of the draw: times, kinds, sizes and signs (any integer >= 0; simulate --seed and a
    # sweep's seed axis leave it: sweep random_disturbances.seed to vary the draw)
    seed: int = 0
    start_time: float = 120.0  # s: the first disturbance
    # s: [min, max] time from one disturbance to the next, drawn uniformly; min at least 16 s (the
    # detection and re-convergence targets), and the last one at least 16 s before the run ends
    interval: list[float] = field(default_factory=lambda: [120.0, 300.0])
    slip_probability: float = 0.5  # the chance a disturbance is a tool slip (else a camera move)
    # m: [min, max] size of a slip's slide along the grasp frame's z, drawn uniformly, random sign
    slide: list[float] = field(default_factory=lambda: [0.01, 0.04])
    # rad: [min, max] size of a slip's pivot about the grasp frame's x, drawn uniformly, random sign
    pivot: list[float] = field(default_factory=lambda: [0.1, 0.35])
    # m: the slide stays within tool.slide +- this (the tool in the grasp): a slip that would leave
    # it slides the other way; at least slide's max
    slide_limit: float = 0.05
    # rad: the pivot stays within tool.pivot +- this (the tool in view); at least pivot's max
    pivot_limit: float = 0.5
    slip_duration: float = 0.1  # s a slip takes
    # rad: [min, max] size of a camera move: the length of its [pan, tilt] change, drawn uniformly,
    # in a random direction
    turn: list[float] = field(default_factory=lambda: [0.03, 0.2])
    # rad: pan and tilt each stay within head.pan and head.tilt +- this (the scene in view): a turn
    # that would leave it turns the other way on that axis; at least turn's max
    turn_limit: float = 0.25
    turn_duration: float = 0.5  # s a camera move takes


@dataclasses.dataclass(frozen=True)
class Drawn:
    """One drawn disturbance: a slip to ``(slide, pivot)`` or a head move to ``(pan, tilt)``."""

    kind: str  # SLIP or HEAD_MOVE
    time: float  # s: when it starts
    state: tuple[float, float]  # the new (slide m, pivot rad) or (pan rad, tilt rad), absolute
    change: tuple[float, float]  # the change from the state before (same units)
    duration: float  # s it takes

    @property
    def size(self) -> float:
        """A head move's turn (rad: the length of its change); a slip's slide (m, unsigned)."""
        return math.hypot(*self.change) if self.kind == HEAD_MOVE else abs(self.change[0])


def draw(config: RandomDisturbances, duration: float, head: tuple[float, float] = (0.0, 0.1),
         tool: tuple[float, float] = (0.0, 0.0)) -> list[Drawn]:
    """The disturbances of ``config`` in a run of ``duration`` s, in time order, from the initial head
    angles ``head`` (pan, tilt) and slip state ``tool`` (slide, pivot): none when not enabled. The
    first at ``start_time``, each next one ``interval`` later, the last at least ``SETTLE`` s before
    the end. Assumes a validated section (``station.validation``)."""
    if not config.enabled:
        return []
    rng = np.random.default_rng(int(config.seed))
    head_now, tool_now = tuple(map(float, head)), tuple(map(float, tool))
    out: list[Drawn] = []
    t = float(config.start_time)
    while t <= duration - SETTLE:
        if rng.random() < config.slip_probability:
            change = (_signed(rng, config.slide), _signed(rng, config.pivot))
            limits = (config.slide_limit, config.pivot_limit)
            tool_now, change = _within(tool_now, change, tool, limits)
            out.append(Drawn(SLIP, t, tool_now, change, float(config.slip_duration)))
        else:
            size, direction = rng.uniform(*config.turn), rng.uniform(0.0, 2.0 * math.pi)
            change = (size * math.cos(direction), size * math.sin(direction))
            limits = (config.turn_limit, config.turn_limit)
            head_now, change = _within(head_now, change, head, limits)
            out.append(Drawn(HEAD_MOVE, t, head_now, change, float(config.turn_duration)))
        t += float(rng.uniform(*config.interval))
    return out


def _signed(rng: np.random.Generator, size_range) -> float:
    size = float(rng.uniform(*size_range))
    return size if rng.random() < 0.5 else -size


def _within(now, change, centre, limits) -> tuple[tuple[float, float], tuple[float, float]]:
    """The state after ``change`` and the change itself, each axis's change reversed when it would
    take the state beyond ``centre`` +- ``limits`` (the reversed one stays within: a change is at
    most its limit)."""
    state, kept = [], []
    for x, dx, c, limit in zip(now, change, centre, limits, strict=True):
        if abs(x + dx - c) > limit:
            dx = -dx
        state.append(x + dx)
        kept.append(dx)
    return tuple(state), tuple(kept)
