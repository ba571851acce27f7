"""The babbling's next posture chosen to excite what an identifier's statistic determines least
(issue 25; ``identification.excitation``): ``ExcitingPostures`` for the payload's babbling,
``HandEyePostures`` for the hand-eye loop's identifying motion."""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import LeafSystem

from sustain_drake.identification.excitation import ranked_candidates
from sustain_drake.identification.eye_to_hand import EyeToHandIdentifier, path_information, predicted_points
from sustain_drake.identification.payload_dynamic import sensor_kinematics
from sustain_drake.systems.motion_generator import (
    Pace,
    move_duration,
    quintic,
    quintic_acceleration,
    shortest_move_reach,
)

# Postures drawn per choice: half the babbling's own, half the shortest moves'.
NUM_CANDIDATES = 16
# rad: a chosen move's path is checked every this much of its largest joint's travel (a point 0.4 m
# out moves 2 cm in it: the clearance's margin).
PATH_CHECK_STEP = 0.05
# Points at which a move's kinematics are predicted (the midpoints of as many equal parts of it): a
# quintic move's acceleration changes sign twice, so 8 points follow it to a few per cent.
MOVE_POINTS = 8


def move_times(duration: float) -> np.ndarray:
    """s: the ``MOVE_POINTS`` midpoints of as many equal parts of a move lasting ``duration`` s."""
    return (np.arange(MOVE_POINTS) + 0.5) / MOVE_POINTS * duration


class Clearance(NamedTuple):
    """What the chosen moves keep clear: along the move (checked every ``PATH_CHECK_STEP`` of the
    largest joint's travel), no collision geometry of ``geometries`` (e.g. the held object's) comes
    within ``margin`` (m) of any other, by the signed distances of the SceneGraph that ``diagram``
    (holding the plant and its SceneGraph, e.g. the station) wires the plant to."""

    diagram: object
    geometries: frozenset
    margin: float


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
    ``NUM_CANDIDATES`` (16) postures (half drawn uniformly within ``ranges``, the babbling's own
    distribution; half within the reach of a shortest move around the current posture; from a
    generator seeded with ``(seed, t in ms)``, so runs are reproducible), the one whose samples
    add the most information per second of motion (``excitation.ranked_candidates``): the information
    of the samples at the posture (``information(statistic, [R_WK])`` gives the statistic's ``M``
    and each candidate's ``dM``, and ``information.num_unknowns`` is the statistic's N: e.g.
    ``payload.PostureInformation``) over the move's duration at
    the babbling's ``pace`` plus its rest (``pace.dwell``). An ``information`` whose ``along_move``
    is true (``payload_dynamic.MoveInformation``: samples during the motion count) is given instead
    the sensor's kinematics ``[w; alpha; a - g]`` in K at ``MOVE_POINTS`` points along each
    candidate's quintic move from rest to rest (the motion generator's), each standing for the
    samples at ``rate`` Hz of its part of the move: ``information(statistic, moves, samples)``.

    With a ``clearance``, the best candidate whose move keeps it (its straight joint-space path,
    which the motion generator's moves between rests follow) is chosen; when none does, ``goal`` is
    NaN and the motion generator takes its own random goal.

    Computed when evaluated, with no state: a ``MotionGenerator`` evaluates its ``goal`` input once
    per babbling move, so the kinematics of the candidates (``frame``'s orientation in the world,
    from ``plant``) cost about 1 ms per move, or about 12 ms along the moves (``along_move``: 16 x 8
    Jacobians). The arm's other joints (and every other body
    of ``plant``) stay at their default positions, which must not move ``frame`` relative to the
    arm's last joint.
    """

    def __init__(self, plant, frame, joints, ranges: tuple, pace: Pace, information: Callable,
                 clearance: Clearance | None = None, seed: int = 0, rate: float = 100.0):  # fmt: skip
        super().__init__()
        lower, upper = (np.asarray(r, dtype=float) for r in ranges)
        n = len(joints)
        if lower.shape != (n,) or upper.shape != (n,) or not np.all(lower <= upper):
            raise ValueError(f"ranges must be two length-{n} vectors with lower <= upper")
        if not (pace.max_speed > 0 and pace.min_duration > 0 and pace.dwell >= 0):
            raise ValueError("pace.max_speed and pace.min_duration must be > 0, pace.dwell >= 0")
        if not rate > 0:
            raise ValueError(f"rate must be > 0 Hz, got {rate}")
        self._plant, self._frame, self._rate = plant, frame, float(rate)
        self._positions = [j.position_start() for j in joints]
        self._velocities = [j.velocity_start() for j in joints]
        self._lower, self._upper, self._pace = lower, upper, pace
        self._information, self._clearance, self._seed = information, clearance, int(seed)
        self._k = NUM_CANDIDATES
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
        root = self._clearance.diagram.CreateDefaultContext() if self._clearance else None
        plant_context = (self._clearance.diagram.GetMutableSubsystemContext(self._plant, root)
                         if root is not None else self._plant.CreateDefaultContext())
        q = self._plant.GetPositions(plant_context)

        def X_WK(posture):
            q[self._positions] = posture
            self._plant.SetPositions(plant_context, q)
            return self._frame.CalcPoseInWorld(plant_context)

        pace = self._pace
        moves = [move_duration(q_now, goal, pace.max_speed, pace.min_duration) for goal in candidates]
        durations = [move + pace.dwell for move in moves]
        if getattr(self._information, "along_move", False):
            along = [self._along_move(q_now, goal, T, plant_context)
                     for goal, T in zip(candidates, moves, strict=True)]
            samples = [T * self._rate / MOVE_POINTS for T in moves]
            M, added = self._information(self._statistic.Eval(context), along, samples)
        else:
            M, added = self._information(self._statistic.Eval(context),
                                         [X_WK(goal).rotation().matrix() for goal in candidates])
        # The best first; with a clearance, the best whose path keeps it.
        for i in ranked_candidates(M, added, durations):
            if root is None or self._keeps_clear(q_now, candidates[i], X_WK, plant_context):
                output.SetFromVector(candidates[i])
                return
        output.SetFromVector(np.full(n, np.nan))  # none: the motion generator's own random goal

    def _along_move(self, q_now, goal, duration: float, plant_context) -> np.ndarray:
        """The sensor's kinematics ``[w; alpha; a - g]`` in K (``MOVE_POINTS`` x 9) at the midpoints of
        ``MOVE_POINTS`` equal parts of the quintic move from ``q_now`` to ``goal`` in ``duration``."""
        plant, frame, world, kV = self._plant, self._frame, self._plant.world_frame(), JacobianWrtVariable.kV
        q, v = plant.GetPositions(plant_context), np.zeros(plant.num_velocities())
        g_W, p_KoK = plant.gravity_field().gravity_vector(), np.zeros(3)
        vdot, rows = np.zeros_like(v), []
        for s in move_times(duration):
            q_arm, v_arm = quintic(q_now, goal, duration, s)
            q[self._positions], v[self._velocities] = q_arm, v_arm  # the other joints at rest
            vdot[self._velocities] = quintic_acceleration(q_now, goal, duration, s)
            plant.SetPositions(plant_context, q)
            plant.SetVelocities(plant_context, v)
            J = plant.CalcJacobianSpatialVelocity(plant_context, kV, frame, p_KoK, world, world)
            bias = plant.CalcBiasSpatialAcceleration(plant_context, kV, frame, p_KoK, world, world)
            V, A = J @ v, J @ vdot + bias.get_coeffs()
            R_WK = frame.CalcPoseInWorld(plant_context).rotation().matrix()
            rows.append(sensor_kinematics(R_WK, V[:3], A[:3], A[3:], g_W))
        plant.SetVelocities(plant_context, np.zeros(plant.num_velocities()))
        return np.array(rows)

    def _keeps_clear(self, q_now, goal, X_WK, plant_context) -> bool:
        """Whether the straight joint-space path from ``q_now`` to ``goal`` keeps the clearance."""
        clear = self._clearance
        steps = max(1, int(np.ceil(np.max(np.abs(goal - q_now)) / PATH_CHECK_STEP)))
        query_port = self._plant.get_geometry_query_input_port()
        for s in np.arange(1, steps + 1) / steps:
            X_WK(q_now + s * (goal - q_now))
            query = query_port.Eval(plant_context)
            for pair in query.ComputeSignedDistancePairwiseClosestPoints(clear.margin):
                ours = pair.id_A in clear.geometries or pair.id_B in clear.geometries
                if ours and pair.distance < clear.margin:
                    return False
        return True


class HandKinematics(NamedTuple):
    """What maps a posture to the hand's pose and a move to its duration: ``hand_frame``'s pose in
    ``plant`` at the positions of ``joints`` (the arm's, base to hand), and the ``pace`` of the moves
    that answer the requests (the motion generator's)."""

    plant: object
    hand_frame: object
    joints: list
    pace: Pace


class HandEyePostures:
    """Chooses, among postures an ``IdentifyingMotion`` drew, the one whose move adds the most to an
    eye-to-hand statistic per second, with the point kept in the camera's view (issue 25;
    ``identification.excitation``).

    The statistic's TLS solution (``EyeToHandIdentifier``, no refinement) predicts the point in the
    camera along each candidate's quintic move (the motion generator's) at ``MOVE_POINTS`` points,
    each standing for the samples at ``rate`` Hz of its part of the move, and at the goal for the
    rest after it (``pace.dwell``); ``eye_to_hand.path_information`` gives the information they add
    and ``excitation.ranked_candidates`` the best per second (the move's duration at ``pace`` plus
    its rest). A candidate whose predicted point comes nearer the image's border than ``margin_px``
    (the tracker's window must fit) or goes behind the camera is not chosen. The hand's pose comes
    from ``kinematics`` (``HandKinematics``; every joint but the arm's at its default: it must not
    move the hand relative to the arm's last joint); ``camera_info`` gives the intrinsics. Not a
    system: ``IdentifyingMotion`` calls ``choose`` in its update, with a plant context of its own
    per call (about 1 ms for 8 candidates).
    """

    def __init__(self, kinematics: HandKinematics, camera_info, rate: float, margin_px: float):
        pace = kinematics.pace
        if not (pace.max_speed > 0 and pace.min_duration > 0 and pace.dwell >= 0):
            raise ValueError("pace.max_speed and pace.min_duration must be > 0, pace.dwell >= 0")
        if not (rate > 0 and margin_px >= 0):
            raise ValueError(f"rate must be > 0 Hz and margin_px >= 0, got {rate} and {margin_px}")
        self._plant, self._frame, self._pace = kinematics.plant, kinematics.hand_frame, pace
        self._positions = [j.position_start() for j in kinematics.joints]
        self._rate, self._margin = float(rate), float(margin_px)
        self._size = (camera_info.width(), camera_info.height())
        self._K = np.array([[camera_info.focal_x(), 0.0, camera_info.center_x()],
                            [0.0, camera_info.focal_y(), camera_info.center_y()]])  # fmt: skip

    @property
    def num_joints(self) -> int:
        return len(self._positions)

    def choose(self, q_now: np.ndarray, goals: np.ndarray, state: np.ndarray) -> int | None:
        """The index in ``goals`` (k x n, rad) of the most informative move from ``q_now`` for the
        eye-to-hand statistic ``state`` (``[S | n_eff | count]``, 258), or None: no estimate yet (the
        rotation block of the solution is zero, or no samples) or no candidate keeps the point in view."""
        solver = EyeToHandIdentifier()
        solver.set_state(state)
        estimate = solver.solve(refine_estimate=False).projected
        if estimate is None:
            return None
        context = self._plant.CreateDefaultContext()
        q = self._plant.GetPositions(context)
        pace, visible, paths, durations = self._pace, [], [], []
        for i, goal in enumerate(goals):
            T = move_duration(q_now, goal, pace.max_speed, pace.min_duration)
            postures = [quintic(q_now, goal, T, s)[0] for s in move_times(T)]
            X_WH = []
            for posture in [*postures, goal]:
                q[self._positions] = posture
                self._plant.SetPositions(context, q)
                X_WH.append(self._frame.CalcPoseInWorld(context).GetAsMatrix4())
            X_WH = np.array(X_WH)
            p_CP = predicted_points(estimate, X_WH)
            if not self._in_view(p_CP):
                continue
            w = np.r_[np.full(MOVE_POINTS, T * self._rate / MOVE_POINTS), pace.dwell * self._rate]
            visible.append(i)
            paths.append((p_CP, X_WH, w))
            durations.append(T + pace.dwell)
        if not visible:
            return None
        M, added = path_information(state, paths)
        return visible[int(ranked_candidates(M, added, durations)[0])]

    def _in_view(self, p_CP: np.ndarray) -> bool:
        """Whether every point is in front of the camera and projects at least ``margin_px`` inside
        the image."""
        z = p_CP[:, 2]
        if not np.all(z > 0.0):
            return False
        uv = (p_CP / z[:, None]) @ self._K.T
        m, (width, height) = self._margin, self._size
        u, v = uv[:, 0], uv[:, 1]
        return bool(np.all((u >= m) & (u <= width - m) & (v >= m) & (v <= height - m)))
