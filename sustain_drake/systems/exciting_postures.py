"""The babbling's next posture chosen to excite what an identifier's statistic determines least
(issue 25; ``identification.excitation``)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from pydrake.systems.framework import LeafSystem

from sustain_drake.identification.excitation import best_candidate
from sustain_drake.systems.motion_generator import Pace, move_duration, shortest_move_reach


class ExcitingPostures(LeafSystem):
    """Chooses a ``MotionGenerator``'s next babbling goal for the information it adds.

    .. pydrake_system::

        name: ExcitingPostures
        input_ports:
        - statistic
        - joint_positions
        output_ports:
        - goal

    ``statistic`` (the identifier's state, ``[S | n_eff | count]``: a ``SustainableIdentifierSystem``'s
    ``statistic`` output), ``joint_positions`` (n, rad: the arm's encoders). ``goal`` (n, rad): of
    ``num_candidates`` postures (half drawn uniformly within ``ranges``, the babbling's own
    distribution; half within the reach of a shortest move around the current posture; from a
    generator seeded with ``(seed, t in ms)``, so runs are reproducible), the one whose samples
    add the most information per second of motion (``excitation.best_candidate``): the information
    of the samples at the posture (``information(statistic, [R_WK])`` gives the statistic's ``M``
    and each candidate's ``dM``, and ``information.num_unknowns`` is the statistic's N: e.g.
    ``payload.PostureInformation``) over the move's duration at
    the babbling's ``pace`` plus its rest (``pace.dwell``).

    Computed when evaluated, with no state: a ``MotionGenerator`` evaluates its ``goal`` input once
    per babbling move, so the kinematics of the candidates (``frame``'s orientation in the world,
    from ``plant``) cost a few milliseconds per move. The arm's other joints (and every other body
    of ``plant``) stay at their default positions, which must not move ``frame`` relative to the
    arm's last joint.
    """

    def __init__(self, plant, frame, joints, ranges: tuple, pace: Pace,
                 information: Callable, seed: int = 0, num_candidates: int = 16):  # fmt: skip
        super().__init__()
        lower, upper = (np.asarray(r, dtype=float) for r in ranges)
        n = len(joints)
        if lower.shape != (n,) or upper.shape != (n,) or not np.all(lower <= upper):
            raise ValueError(f"ranges must be two length-{n} vectors with lower <= upper")
        if not (num_candidates >= 1 and pace.max_speed > 0 and pace.min_duration > 0 and pace.dwell >= 0):
            raise ValueError("num_candidates >= 1, pace.max_speed and pace.min_duration > 0, pace.dwell >= 0")
        self._plant, self._frame = plant, frame
        self._positions = [j.position_start() for j in joints]
        self._lower, self._upper, self._pace = lower, upper, pace
        self._information, self._seed, self._k = information, int(seed), int(num_candidates)
        size = int(information.num_unknowns) ** 2 + 2
        self._statistic = self.DeclareVectorInputPort("statistic", size)
        self._q = self.DeclareVectorInputPort("joint_positions", n)
        self.DeclareVectorOutputPort("goal", n, self._calc_goal)

    def _calc_goal(self, context, output) -> None:
        q_now = self._q.Eval(context)
        rng = np.random.default_rng([self._seed, int(round(1000.0 * context.get_time()))])
        n, far = self._lower.size, (self._k + 1) // 2
        # Half the candidates are the babbling's own (anywhere within the ranges), half the shortest
        # moves' (within the reach of a move of min_duration at the pace): a near posture that turns
        # the sensor where it was never turned is worth more per second than a far one.
        reach = shortest_move_reach(self._pace.max_speed, self._pace.min_duration)
        near_lower = np.clip(q_now - reach, self._lower, self._upper)
        near_upper = np.clip(q_now + reach, self._lower, self._upper)
        candidates = np.vstack([rng.uniform(self._lower, self._upper, size=(far, n)),
                                rng.uniform(near_lower, near_upper, size=(self._k - far, n))])
        plant_context = self._plant.CreateDefaultContext()
        q = self._plant.GetPositions(plant_context)
        rotations = []
        for goal in candidates:
            q[self._positions] = goal
            self._plant.SetPositions(plant_context, q)
            rotations.append(self._frame.CalcPoseInWorld(plant_context).rotation().matrix())
        M, added = self._information(self._statistic.Eval(context), rotations)
        pace = self._pace
        durations = [move_duration(q_now, goal, pace.max_speed, pace.min_duration) + pace.dwell
                     for goal in candidates]
        output.SetFromVector(candidates[best_candidate(M, added, durations)])
