"""``IdentifyingMotion``: while the hand-eye loop identifies, ask the babbling for far postures
(richer motion), between the coincidence detector's confirming requests (beyond the paper)."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem

from sustain_drake.identification import coordination
from sustain_drake.identification.eye_to_hand import N_UNKNOWNS
from sustain_drake.systems.exciting_postures import HandEyePostures

# State vector: [output id, last detector id seen, time of the last request (own or detector's),
# own requests so far, since when the arm stays near one posture, time of the last request made
# over the detector's, 1 once the state machine has observed, 1 while the postures within reach are
# drawn about the anchor, when the detector's turn began (-inf: none), 1 once the arm reached its
# posture], that posture (n), the anchor (n), then the output request [joint, q_1..q_n].
(_ID, _DETECTOR_ID, _LAST_TIME, _OWN, _NEAR_SINCE, _LAST_FORCED, _HAS_OBSERVED, _ANCHORED, _TURN,
 _TURN_REACHED) = range(10)
_POSTURE = 10
_REACHED = 0.05  # rad (max-norm): the arm is at a requested posture
_NEAR = 0.2  # rad (max-norm): the arm stays near one posture (the confirming trials' reach)


class IdentifyingMotion(LeafSystem):
    """Forwards the ``MotionCoincidenceDetector``'s confirming requests to the motion generator and,
    while the state machine is in IDENTIFY and no request came for ``interval`` s, adds its own:
    go to the farthest (max-norm, rad) of ``num_draws`` postures drawn uniformly in
    ``joint_ranges`` from the current one. Eq. (30)'s statistic converges when the hand turns
    through several axes (a gap ``lambda_15 / lambda_16`` and a rotation, SSD); the random babbling
    sometimes stays near one posture for tens of seconds. When, while identifying again (after a
    first convergence), the arm has stayed within 0.2 rad (max-norm) of one posture for ``max_hold``
    s (default: three intervals), it asks for one however often the detector asks, and holds the
    detector's requests back until the arm is there (0.05 rad, or ``max_hold`` s): the detector's
    confirming trials can follow each other for tens of seconds (after a slip, the arm can stay
    within 0.1 rad of one posture for most of a minute), and then nothing converges.
    Before the first convergence only while the identifiers ask for more motion (``more_motion``:
    a point has been tracked for a while, or points converged that do not pin the camera's
    rotation yet): until then the body features
    the candidates come from are what those trials find (forcing far postures from the start
    delays the first tool point and the first convergence by tens of seconds;
    docs/hand_eye_record.md has the runs).
    With ``more_motion_reach`` (rad), postures asked for while ``more_motion`` is set are drawn
    within that reach (max-norm) of the posture the arm had when it was set (the anchor: there the
    points were seen; a walk from posture to posture drifts until their faces turn away), the
    farthest from the current one of ``num_draws``, and come after one ``interval`` near a posture,
    not ``max_hold``: the far postures end the tracks of the points that want more motion. Once a
    converged point is held back (``more_motion`` 2: it wants more points, not only more views of
    its own), a detector's request forwarded has the arm until its confirming move (the arm reached
    its posture and left it again), ``max_hold`` at most, before the next posture within reach: a
    posture asked for every interval would otherwise replace each request before the arm is there,
    and no trial, so no new body feature, would come (tens of seconds where the first points see
    the hand turn too little). Before any point converged the postures go first: the trials' rests
    would repeat the first points' views (docs/hand_eye_record.md).

    .. pydrake_system::

        name: IdentifyingMotion
        input_ports:
        - detector_confirm (optional)
        - mode
        - joint_positions
        - more_motion (optional)
        - statistic (optional)
        output_ports:
        - confirm

    Inputs: ``detector_confirm`` (``[request_id, joint, q_1..q_n]``, the detector's ``confirm``),
    ``mode`` (the ``CoordinationStateMachine``'s), ``joint_positions`` (n, rad), ``more_motion`` (1:
    > 0 while a ``CandidateIdentifiers``' ``more_motion`` asks for it, 2 while a converged point is
    held back; unconnected: never before the
    first convergence), ``statistic`` (258: the eye-to-hand statistic ``[S | n_eff | count]`` of the
    candidate that wants the motion, a ``CandidateIdentifiers``' ``motion_statistic``; unconnected or
    without samples: the farthest draw). With ``postures`` (a ``HandEyePostures``), the draw whose
    move adds the most to ``statistic`` per second with the point kept in view is asked for, not the
    farthest (issue 25; the farthest when none keeps it in view or there is no estimate yet). Output:
    ``confirm`` (``[request_id, joint, q_1..q_n]``, the motion generator's ``confirm`` format: a new
    id is a new request; connect to the station's ``motion_confirm``). Every ``period`` s a
    periodic discrete update; the draws come from a generator seeded with (``seed``, request
    number), so runs reproduce and contexts clone.
    """

    def __init__(self, joint_ranges, interval: float = 2.5, num_draws: int = 8, seed: int = 0,
                 period: float = 1.0 / 30.0, max_hold: float | None = None,
                 more_motion_reach: float | None = None,
                 postures: HandEyePostures | None = None):  # fmt: skip
        super().__init__()
        ranges = np.asarray(joint_ranges, float)
        if ranges.ndim != 2 or ranges.shape[1] != 2 or not np.all(ranges[:, 1] > ranges[:, 0]):
            raise ValueError(f"IdentifyingMotion: joint_ranges must be n x [lower, upper], got "
                             f"{joint_ranges}")
        max_hold = 3.0 * interval if max_hold is None else max_hold
        if not (interval > 0 and num_draws >= 1 and period > 0 and max_hold >= interval):
            raise ValueError("IdentifyingMotion: interval and period must be > 0, num_draws >= 1, "
                             "max_hold >= interval")
        if more_motion_reach is not None and not more_motion_reach > 0:
            raise ValueError(f"IdentifyingMotion: more_motion_reach must be > 0 rad, got {more_motion_reach}")
        self._reach = None if more_motion_reach is None else float(more_motion_reach)
        self._ranges, self._interval, self._max_hold = ranges, float(interval), float(max_hold)
        self._draws, self._seed = int(num_draws), int(seed)
        n = ranges.shape[0]
        self._detector = self.DeclareVectorInputPort("detector_confirm", 2 + n)
        self._mode = self.DeclareVectorInputPort("mode", 1)
        self._q = self.DeclareVectorInputPort("joint_positions", n)
        self._more = self.DeclareVectorInputPort("more_motion", 1)
        if postures is not None and postures.num_joints != n:
            raise ValueError(f"IdentifyingMotion: postures chooses for {postures.num_joints} joints, the "
                             f"ranges have {n}")
        self._postures = postures
        self._statistic = self.DeclareVectorInputPort("statistic", N_UNKNOWNS * N_UNKNOWNS + 2)
        self._anchor = _POSTURE + n
        self._request = self._anchor + n  # where the output request starts in the state
        initial = np.zeros(self._request + 1 + n)
        initial[self._request] = -1.0  # the output request's joint: -1, a usual move
        initial[_LAST_FORCED] = initial[_TURN] = -np.inf
        initial[_POSTURE:self._anchor] = np.inf  # no posture yet: the first sets it
        self._state = self.DeclareDiscreteState(initial)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareVectorOutputPort(
            "confirm", 2 + n, lambda c, o: o.SetFromVector(
                np.concatenate([[self._vector(c)[_ID]], self._vector(c)[self._request:]])),
            prerequisites_of_calc={self.discrete_state_ticket(self._state)})  # fmt: skip

    def _vector(self, context) -> np.ndarray:
        return context.get_discrete_state(self._state).value()

    def _update(self, context, state) -> None:
        x = self._vector(context).copy()
        t = context.get_time()
        request = self._detector.Eval(context) if self._detector.HasValue(context) else x[[_DETECTOR_ID]]
        identifying = int(self._mode.Eval(context)[0]) == coordination.IDENTIFY
        q = np.asarray(self._q.Eval(context), float)
        if not np.max(np.abs(q - x[_POSTURE:self._anchor])) <= _NEAR:
            x[_POSTURE:self._anchor], x[_NEAR_SINCE] = q, t  # the arm left: a new posture
        # While identifying again, a far posture when the arm stayed near one for max_hold (however often
        # the detector asks); it has the arm until it is there (the detector's request stays
        # pending till then), for max_hold at most.
        x[_HAS_OBSERVED] = max(x[_HAS_OBSERVED], float(not identifying))
        more = float(self._more.Eval(context)[0]) if self._more.HasValue(context) else 0.0
        asked, held = more > 0, more > 1
        # With a reach, the identifiers' ask is met at once (after one interval near a posture) by
        # postures within reach: their points' tracks must live through it.
        gentle = asked and self._reach is not None
        if not gentle:
            x[_ANCHORED] = 0.0
        elif not x[_ANCHORED]:  # where the points that want more motion are seen
            # (an arm just outside its ranges still gets a box in them)
            x[self._anchor:self._request], x[_ANCHORED] = np.clip(q, *self._ranges.T), 1.0
        hold = self._interval if gentle else self._max_hold
        at_request = np.max(np.abs(q - x[self._request + 1:])) <= _REACHED
        if not (gentle and held):
            x[_TURN] = -np.inf  # a turn ends with the hold it was for
        detectors_turn = gentle and held and self._detectors_turn(x, t, at_request)
        overdue = (identifying and (x[_HAS_OBSERVED] > 0 or asked) and t - x[_NEAR_SINCE] >= hold
                   and t - x[_LAST_FORCED] >= hold and not detectors_turn)
        on_its_way = t - x[_LAST_FORCED] < hold and not at_request and not detectors_turn
        waits = identifying and (overdue or on_its_way)
        if request[0] != x[_DETECTOR_ID] and not waits:  # the detector's first (body detection, §3.3)
            x[_DETECTOR_ID] = request[0]
            x[_ID] += 1
            x[_LAST_TIME] = t
            x[self._request:] = request[1:]
            if gentle and held and not detectors_turn:  # a follow-up in the turn does not lengthen it
                x[_TURN], x[_TURN_REACHED] = t, 0.0
        elif identifying and not detectors_turn and (overdue or (t - x[_LAST_TIME] >= self._interval
                                                                 and request[0] == x[_DETECTOR_ID])):
            rng = np.random.default_rng([self._seed, int(x[_OWN])])
            low, high = self._ranges[:, 0], self._ranges[:, 1]
            if gentle:
                centre = x[self._anchor:self._request]
                low, high = np.maximum(low, centre - self._reach), np.minimum(high, centre + self._reach)
            draws = rng.uniform(low, high, (self._draws, q.size))
            far = self._chosen(context, q, draws)
            x[_ID] += 1
            x[_OWN] += 1
            x[_LAST_TIME] = t
            if overdue:
                x[_LAST_FORCED] = t
            x[self._request] = -1.0  # a usual move after the rest there
            x[self._request + 1:] = far
        state.get_mutable_vector(self._state).SetFromVector(x)

    def _detectors_turn(self, x: np.ndarray, t: float, at_request: bool) -> bool:
        """Whether the detector's forwarded request still has the arm (updating ``x``): from its
        forwarding until the arm, having reached its posture (``at_request``), leaves it (the
        confirming move that the trial times), ``max_hold`` at most."""
        if not t - x[_TURN] < self._max_hold:
            x[_TURN] = -np.inf
            return False
        if at_request:
            x[_TURN_REACHED] = 1.0
        elif x[_TURN_REACHED]:
            x[_TURN] = -np.inf  # the confirming move began
            return False
        return True

    def _chosen(self, context, q: np.ndarray, draws: np.ndarray) -> np.ndarray:
        """The draw whose move adds the most to the ``statistic`` per second (``postures``), else the
        farthest (max-norm) from ``q``."""
        if self._postures is not None and self._statistic.HasValue(context):
            statistic = self._statistic.Eval(context)
            if statistic[N_UNKNOWNS * N_UNKNOWNS] > 0:  # samples behind it
                i = self._postures.choose(q, draws, statistic)
                if i is not None:
                    return draws[i]
        return draws[np.argmax(np.max(np.abs(draws - q), axis=1))]
