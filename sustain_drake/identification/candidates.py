"""Candidate tracked points for eye-to-hand identification (paper Fig. 7, §4.3), pure numpy.

The paper runs one sustainable identifier per candidate corner that the coincidence detector
marks as body, and adopts the first one to converge. A corner on another link than the hand
does not satisfy Eq. (30) (its point is not fixed in H), so its residual stays large and its
verdict never says converged: the hand formulation is itself a filter.

This module is the bookkeeping, as a pure function of a ``CandidateBank`` (held by a Drake
system in an abstract state):

- admission: body features with a valid 3-D point become candidates, oldest track first, at most
  ``max_candidates`` at a time (a bounded cost per frame);
- feeding: each frame, each candidate's identifier gets the feature's ``p_CP`` and the hand pose
  ``X_WH`` at the frame's capture time (``PoseHistory``: the image is older than the encoders by
  a frame or two, and at 0.4 m/s a frame is 1.3 cm);
- a motion gate: a point fixed within ``max_hand_radius`` of the hand origin cannot move in the
  camera frame (a fixed camera) by more than the hand's translation plus its rotation angle times
  that radius; a sample that does (a depth value taken from the background at a silhouette, a
  track that jumped) is skipped;
- loss: a feature no longer tracked (the tracker never reuses an id) or without a valid depth
  (occluded) stops feeding its identifier; after ``max_lost_time`` s without a sample its slot is
  freed; a candidate still not converged after ``max_unconverged_time`` s is rejected (another
  link, a sliding silhouette corner) and its slot freed;
- the leader: the first candidate whose verdict says converged (the smallest expected error if
  several converge on the same frame) is the leader until the next reset; its solution is refined
  (Gauss-Newton) and it is what a ``CoordinationStateMachine`` adopts;
- observation: once there is a leader, its feature (the *observed* feature) gives one ``s_t`` per
  frame under the reference (adopted) estimate. When the observed feature is lost, the body
  feature nearest to where the adopted estimate puts the tracked point (within
  ``reacquire_radius``) takes its place, so a re-seeded track of the same point keeps the
  observation going;
- reset: a new reset value (a change was detected: the tool slipped or the camera moved) drops
  every candidate; identification starts again from the body features seen then, unless the
  abandoned model's camera explains a new point (``keep_camera``: a slip) or, after a camera move,
  the points it observed still fit one new camera with their ``p_HP`` (``keep_tool_points``);
- beyond the paper, the depth image checks the adopted tool point every frame
  (``free_space_radius``): a surface seen behind where the model puts it is a violation, tracked
  points or not.
"""

# No "from __future__ import annotations": yaml_load_typed reads CandidateParams' real field types.

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from sustain_drake.identification.coordination import CAMERA_MOVED, NO_RESET
from sustain_drake.identification.eye_to_hand import (
    EyeToHandEstimate,
    EyeToHandIdentifier,
    EyeToHandSolution,
    build_A,
    camera_after_turn,
    camera_given_points,
    pack_x,
    refine_joint,
    rotation_levers,
    spread_off_line,
)
from sustain_drake.identification.rotation import rotation_angle
from sustain_drake.identification.sustainable_identifier import (
    ConvergenceCriteria,
    SustainableIdentifier,
    Verdict,
)


@dataclass
class CandidateParams:
    """Bookkeeping thresholds of the candidate identifiers (SI units).

    ``p_HP`` is a candidate's tracked point in the hand frame H. A candidate *fits* a camera when
    its samples, under that camera and its own best ``p_HP``, have an RMS error at most
    ``observe_consistency`` times the adopted model's. Counts are samples (frames a point is tracked;
    with ``min_view_change``, those that fit a camera count views); a 0, False or inf turns off a
    rule that goes beyond the paper.
    """

    max_candidates: int = 8  # count: identifiers run at a time, one per candidate tracked point
    # m: farthest a tracked point on the hand or its tool lies from the hand origin (motion gate)
    max_hand_radius: float = 0.6
    gate_margin: float = 0.01  # m added to the motion gate's bound: the depth noise of two frames
    max_lost_time: float = 2.0  # s without a sample before a candidate's slot is freed
    # s after admission before a candidate that has not converged is rejected (until a reset)
    max_unconverged_time: float = 30.0
    # m: a body feature this near the adopted prediction takes over a lost observed feature
    reacquire_radius: float = 0.01
    # s: the most the nearest hand pose's time may differ from a frame's capture time
    pose_tolerance: float = 0.01
    # m: a candidate with min_samples whose expected RMS error exceeds this is rejected (not on the hand)
    reject_rms: float = 0.02
    # also admit features in body cells, after body features (the fit rejects the background among them)
    use_body_cells: bool = True
    # m over the motion gate: an observed point jumping more in a frame is a lost track (re-acquired)
    observation_jump: float = 0.15
    # count: samples a candidate needs to take over a lost observation, witness or observe
    observe_min_samples: int = 100
    # ratio: a candidate fits a camera when its RMS error is within this times the adopted one's
    observe_consistency: float = 3.0
    # count: samples the observed point alone violates the allowable error before its witness replaces it
    primary_failures: int = 10
    # after a reset, a candidate that fits the old camera leads at once with it (a slip moves only p_HP)
    keep_camera: bool = True
    # count: samples to lead with the kept camera when the static scene stayed still since
    # before the reset (else observe_min_samples); only p_HP (3 unknowns) is new then
    keep_camera_min_samples: int = 100
    # a converged candidate leads only if another one fits its camera (one track can fit a wrong camera)
    confirm_with_witness: bool = True
    # rad the hand turns over a candidate's samples before it can fit a camera (a translation fits any)
    min_rotation_spread: float = 0.15
    # refine the leader's camera jointly with all candidates that fit it (the paper uses one point)
    joint: bool = False
    joint_min_samples: int = 30  # count: samples a candidate needs to join the joint refinement
    # ratio: a candidate joins the joint refinement if its RMS error is within this times the leader's
    joint_consistency: float = 3.0
    # weight each point's samples by its inverse mean squared error (maximum likelihood); False: equal
    joint_weighted: bool = False
    # count: ended tracks kept for the joint refinement (still valid constraints), most samples first
    max_archived: int = 16
    max_observers: int = 0  # count: fitting points observed besides the observed point and its witness
    # s between joint refinements of the adopted camera while observing; 0: the paper's fixed model
    refine_interval: float = 0.0
    # m: a witness, observer or hand-over lies within this of the adopted tool point in H (on the
    # tool: a gripper point does not move when the tool slips); inf: anywhere on the hand
    observe_radius: float = math.inf
    # count: samples a candidate needs to be checked on frames with no observed point; 0: off, the paper's
    blind_min_samples: int = 0
    # m: joint-refinement tracks whose p_HP lie this close are one point (summed); 0: one point per track
    stitch_radius: float = 0.0
    # count: samples, taken while the adopted model is verified, that a candidate needs to witness,
    # observe or take over: a point learned blind would re-learn the tool point and hide a slip; 0: off
    verified_overlap: int = 0
    # on a blind frame, a tool candidate that fits but lacks verified_overlap is a sample over the
    # allowable error: the held tool point can no longer be checked; False: no sample
    unverified_evidence: bool = False
    # a kept-camera model's expected error is capped at that of the identification that found
    # the camera, so a worse fit does not widen the allowable error; False: its own error
    keep_allowable_error: bool = False
    # m: radius of the depth check of the adopted tool point (the camera must see no surface behind
    # it; the gap squared joins the frame's sample): a slip shows even with no point tracked; 0: off
    free_space_radius: float = 0.0
    # after a camera-move reset, the abandoned model's points keep their p_HP (a moved camera leaves
    # the held tool unchanged) and give the new camera in closed form (6 unknowns, not 15)
    keep_tool_points: bool = False
    # m: RMS distance from a line the known points' camera-frame samples need (keep_tool_points):
    # a p_HP error e turns the new camera by about e over this spread
    min_point_spread: float = 0.06
    # m: after the scene's turn, a new track matches the known point within this of its p_HP; the
    # rod's marks lie 15-20 mm apart, so only one mark lies within twice this
    turn_radius: float = 0.004
    # m: largest camera shift searched when matching new tracks to known points after a turn
    turn_max_shift: float = 0.03
    # count: samples each known point needs before the camera after a turn is solved
    turn_min_samples: int = 15
    # m: window around the scene's camera shift where the common offset is sought (below a mark spacing)
    turn_scene_shift: float = 0.01
    # after a turn, also admit tracks near where the turned camera sees a known point, body or not:
    # after a camera move the detector's body cells hold the static scene
    turn_admit_known: bool = False
    # m a point must move in the camera frame before its next sample; 0: every frame, the paper's.
    # Measurement errors repeat with the view, so held views would otherwise outweigh the others
    min_view_change: float = 0.0
    # m: least rotation lever of a converged leader's points before adoption (it waits for motion); 0: off
    min_rotation_lever: float = 0.0
    # rad the hand must turn over a converged leader's samples for adoption (the camera's
    # rotation shows only as the hand turns); it waits for motion while its point is seen; 0: off
    min_adopt_rotation_spread: float = 0.0
    # count: samples of a candidate after which more motion is asked for until the first
    # identification: the rotation is pinned only as the hand moves; 0: off
    motion_min_samples: int = 0

    def __post_init__(self):
        counts = (self.observe_min_samples, self.keep_camera_min_samples, self.primary_failures,
                  self.joint_min_samples, self.turn_min_samples)
        if not (min(counts) >= 1 and self.max_archived >= 0 and self.max_observers >= 0
                and self.blind_min_samples >= 0 and self.verified_overlap >= 0
                and self.motion_min_samples >= 0):
            raise ValueError("observe_min_samples, keep_camera_min_samples, primary_failures, "
                             "joint_min_samples and turn_min_samples must be >= 1; max_archived, "
                             "max_observers, blind_min_samples, verified_overlap and motion_min_samples "
                             f">= 0 ({self})")
        if not self.max_candidates >= 1:
            raise ValueError(f"max_candidates must be >= 1, got {self.max_candidates}")
        if not self.observe_radius > 0:
            raise ValueError(f"observe_radius must be positive, got {self.observe_radius}")
        if not (self.stitch_radius >= 0 and math.isfinite(self.stitch_radius)):
            raise ValueError(f"stitch_radius must be >= 0, got {self.stitch_radius}")
        for name in ("refine_interval", "free_space_radius", "min_view_change", "min_rotation_lever",
                     "min_adopt_rotation_spread"):
            value = getattr(self, name)
            if not (value >= 0 and math.isfinite(value)):
                raise ValueError(f"{name} must be >= 0, got {value}")
        for name in ("max_hand_radius", "gate_margin", "max_lost_time", "max_unconverged_time",
                     "reacquire_radius", "pose_tolerance", "reject_rms", "observation_jump",
                     "joint_consistency", "min_rotation_spread", "min_point_spread", "turn_radius",
                     "turn_max_shift", "turn_scene_shift"):
            value = getattr(self, name)
            if not (value > 0 and math.isfinite(value)):
                raise ValueError(f"{name} must be a positive number, got {value}")


@dataclass(frozen=True)
class Candidate:
    """One candidate tracked point: its feature id, its identifier's statistic and solution."""

    feature_id: int
    statistic: np.ndarray
    solution: EyeToHandSolution
    admitted: float  # s
    last_sample: float  # s, the last sample fed or held view seen again (admission time before any)
    last_p_CP: np.ndarray | None = None  # the last measured point (accepted or not), for the gate
    last_X_WH: np.ndarray | None = None
    verified_samples: int = 0  # its samples taken up to the last frame the adopted model was verified
    sampled_p_CP: np.ndarray | None = None  # the point of its last sample (``min_view_change``)
    frames: int = 1  # frames it was fed (a new view or a held one): the observation's counts


@dataclass(frozen=True)
class Adoption:
    """A leader chosen (what the state machine adopts): when, which feature, its statistic, the
    estimate, and how it was identified (``"identified"``: all 16 unknowns, the paper's verdict;
    ``"previous camera"``: the camera of the model abandoned at the last reset explains the
    candidate's samples, only its ``p_HP`` is new)."""

    time: float
    feature_id: int
    statistic: np.ndarray
    admitted: float  # s, when this candidate was admitted
    round_start: float  # s, when the first candidate of this identification round was admitted
    estimate: EyeToHandEstimate | None = None
    kind: str = "identified"
    rotation_lever: float = math.nan  # m, the smallest (``smallest_rotation_lever``) when identified


@dataclass(frozen=True)
class CandidateBank:
    """Everything the candidates carry from frame to frame (immutable: ``step`` returns a new one,
    so a Drake context holding it clones safely).

    Attributes:
        candidates: in admission order.
        leader: feature id of the first candidate to converge since the last reset (-1: none).
        observed: feature id feeding the observation (the leader's, or a re-acquired one; -1).
        rejected: ids rejected since the last reset (only ids still tracked are kept).
        sample_count: samples since construction (never reset): frames that fed an identifier
            while there is no leader, then observations of the observed feature.
        sample_error: ``s_t`` of the newest observation sample, m^2.
        last_reset: the last reset value seen.
        last_frame: capture time of the last frame used, s.
        poses: recent hand poses ``(time, X_WH)``.
        adoptions: every leader chosen, in order.
        round_start: when the first candidate since the last reset was admitted (NaN: none yet).
    """

    candidates: tuple = ()
    leader: int = -1
    observed: int = -1
    rejected: frozenset = frozenset()
    sample_count: int = 0
    sample_error: float = math.inf
    last_reset: float = 0.0
    last_frame: float = -math.inf
    poses: tuple = ()
    adoptions: tuple = ()
    round_start: float = math.nan
    observed_last: tuple | None = None  # (p_CP, X_WH) of the observed feature's last frame
    observed_p_HP: np.ndarray | None = None  # the observed point in H when not the leader's own
    witness: int = -1  # a second observed feature (see ``step``), -1: none
    witness_p_HP: np.ndarray | None = None
    witness_last: tuple | None = None
    primary_failures: int = 0  # consecutive samples the observed point alone violated
    adopted_mse: float = math.inf  # a^2 lambda_N of the leader when it was chosen, m^2
    previous_x: np.ndarray | None = None  # the model abandoned at the last reset (Eq. (36))
    archive: tuple = ()  # candidates whose track ended, kept for the joint refinement
    observers: tuple = ()  # extra observed points: (feature_id, p_HP, (p_CP, X_WH) of the last frame)
    refined_solution: EyeToHandSolution | None = None  # the latest refinement of the adopted model
    refinement: int = 0  # refinements offered since construction (never reset)
    sample_errors: tuple = ()  # this frame's s_t of the observed point and its witness (m^2)
    last_refinement: float = -math.inf  # s
    tool_observed: bool = False  # a tool point gave this frame's observation sample
    model_x: np.ndarray | None = None  # the adopted estimate while there is a leader (Eq. (36))
    known_points: tuple = ()  # after a camera move: (feature_id, p_HP) the abandoned model observed
    moved_from_x: np.ndarray | None = None  # the model a camera move cleared (keep_tool_points)
    moved_at: float = math.nan  # s, when that reset came
    turn: object | None = None  # the static scene's turn across that move (``step``'s scene_turn)
    turned_R_WC: np.ndarray | None = None  # that camera turned as the scene shows (None: too few anchors)
    turned_p_WC: np.ndarray | None = None  # and where the scene's depth puts it (None: not known)
    reset_time: float = -math.inf  # s, when the last reset came
    more_motion: bool = False  # a leader was held back (lever or spread), none leads, one converged
    held_back: int = -1  # the feature id of the candidate held back (as above), -1: none

    def find(self, feature_id: int) -> Candidate | None:
        for c in self.candidates:
            if c.feature_id == feature_id:
                return c
        return None

    @property
    def shown(self) -> Candidate | None:
        """The candidate to report: the leader, else the one with the most samples."""
        if not self.candidates:
            return None
        leader = self.find(self.leader)
        if leader is not None:
            return leader
        return max(self.candidates, key=lambda c: c.solution.num_samples)


POSE_HISTORY = 8  # frames of hand poses kept (the image lags the encoders by one or two)


def empty_solution(criteria: ConvergenceCriteria | None = None) -> EyeToHandSolution:
    return EyeToHandIdentifier(criteria=criteria).solve(refine_estimate=False)


def record_pose(bank: CandidateBank, time: float, X_WH: np.ndarray) -> CandidateBank:
    """Adds the hand pose at ``time`` to the short history."""
    poses = (bank.poses + ((float(time), np.array(X_WH, dtype=float)),))[-POSE_HISTORY:]
    return replace(bank, poses=poses)


def pose_at(bank: CandidateBank, time: float, tolerance: float) -> np.ndarray | None:
    """The recorded hand pose nearest ``time`` if within ``tolerance`` s, else None."""
    best, best_dt = None, tolerance
    for t, X in bank.poses:
        dt = abs(t - time)
        if dt <= best_dt:
            best, best_dt = X, dt
    return best


def within_motion_gate(p_prev, X_prev, p, X, params: CandidateParams) -> bool:
    """Whether a point fixed on the hand could have moved from ``p_prev`` to ``p`` (camera frame)
    while the hand moved from ``X_prev`` to ``X`` (a fixed camera: camera-frame distances are
    world distances)."""
    if p_prev is None or X_prev is None:
        return True
    bound = (np.linalg.norm(X[:3, 3] - X_prev[:3, 3])
             + rotation_angle(X_prev[:3, :3].T @ X[:3, :3]) * params.max_hand_radius
             + params.gate_margin)
    return float(np.linalg.norm(p - p_prev)) <= bound


def x_is_set(x: np.ndarray | None) -> bool:
    return x is not None and np.all(np.isfinite(x)) and bool(np.any(x))


def predicted_p_CP(x: np.ndarray, X_WH: np.ndarray) -> np.ndarray:
    """Where estimate ``x`` (Eq. (36)) puts the tracked point in the camera frame (Eq. (30))."""
    return points_in_camera(x[0:9].reshape(3, 3, order="F"), x[9:12], x[12:15], X_WH)


def points_in_camera(R_WC: np.ndarray, p_WC: np.ndarray, p_HP: np.ndarray, X_WH: np.ndarray) -> np.ndarray:
    """Eq. (30): points of the hand (``p_HP``, 3 or K x 3) in the camera frame, the hand at ``X_WH``."""
    return (p_HP @ X_WH[:3, :3].T + X_WH[:3, 3] - p_WC) @ R_WC


def step(
    bank: CandidateBank,
    params: CandidateParams,
    criteria: ConvergenceCriteria,
    time: float,
    reset: float,
    X_WH: np.ndarray,
    frame_time: float,
    ids: np.ndarray,
    p_CP: np.ndarray,
    valid: np.ndarray,
    on_body: np.ndarray,
    reference_x: np.ndarray | None = None,
    forgetting_factor: float = 1.0,
    in_body_cell: np.ndarray | None = None,
    allowable_error: float = math.inf,
    depth_gap: Callable[[np.ndarray], float] | None = None,
    scene_turn=None,
    scene_still_since: float = math.inf,
    reset_reason: int = NO_RESET,
) -> CandidateBank:
    """One tick at ``time``: the reset, the hand pose, then (on a new frame) admission, feeding,
    loss, the leader and the observation. Returns the new bank.

    Args:
        reset: the reset input; a value different from the last one seen drops every candidate.
        reset_reason: why that reset (``coordination.OBSERVATION_FAILED`` or ``CAMERA_MOVED``;
            ``NO_RESET`` when not known): after a camera move the model's camera is dropped and,
            with ``keep_tool_points``, its tool points are kept; after any other reset the model
            (``reference_x``) is kept as the previous camera that a slipped tool leaves in place.
        X_WH: the hand pose now (4 x 4).
        frame_time: the capture time of the features below (s).
        ids, p_CP, valid, on_body: per tracked feature (same order): id, point in the camera frame
            (m), whether the point is measured, whether the feature is body.
        in_body_cell: per tracked feature, whether it lies in a body cell (None: no such
            candidates).
        allowable_error: the state machine's sigma (m^2), to tell a tracking failure of the
            observed point from a change of the body (inf: never).
        reference_x: the adopted estimate (Eq. (36)); zeros or None while there is none. ``s_t`` of the
            observed feature is computed under it (under the leader's own estimate if unset).
        depth_gap: this frame's depth check (``free_space_radius``): for a point in the camera
            frame, how far behind it the camera sees a surface, m (NaN: cannot tell). None: no
            depth image for this frame.
        scene_turn: the static scene's correspondences across the last camera move (a
            ``perception.camera_motion.SceneTurn``: ``move``, ``start``, ``time``, ``b0``, ``q0``,
            ``b1``), or None. Used with ``keep_tool_points`` when the move it belongs to (its
            episode began before the reset that cleared the model and ended after) cleared the
            model: the camera is then the old one turned, its position from the tool points.
        scene_still_since: since when the static scene has been judged still (s; a
            ``CameraMotionDetector``'s; inf: not known): if since before the last reset, the
            camera did not move and the kept camera leads with ``keep_camera_min_samples``.
    """
    if reset != bank.last_reset:
        camera_moved = reset_reason == CAMERA_MOVED
        previous = np.array(reference_x, dtype=float) if x_is_set(reference_x) and not camera_moved else None
        known = () if previous is not None else bank.known_points
        # The camera before a move whose turn has not come yet: the resets that follow while the
        # camera still moves (no leader in between) keep it; one after the turn is a new change.
        moved_from, moved_at = (bank.moved_from_x, bank.moved_at) if bank.turn is None else (None, math.nan)
        if camera_moved and params.keep_tool_points and bank.leader >= 0 and bank.model_x is not None:
            known = _model_points(bank, params)  # the model cleared: the camera moved, the tool did not
            moved_from, moved_at = bank.model_x, float(time)
        elif previous is not None or bank.leader >= 0:
            moved_from, moved_at = None, math.nan
        bank = replace(bank, candidates=(), leader=-1, observed=-1, rejected=frozenset(), previous_x=previous,
                       known_points=known, model_x=None, moved_from_x=moved_from, moved_at=moved_at,
                       turn=None, turned_R_WC=None, turned_p_WC=None, reset_time=float(time),
                       last_reset=float(reset), round_start=math.nan,
                       observed_last=None, observed_p_HP=None,
                       witness=-1, witness_p_HP=None, witness_last=None, primary_failures=0, archive=(),
                       observers=(), refined_solution=None, last_refinement=-math.inf, more_motion=False,
                       held_back=-1)
    bank = record_pose(bank, time, X_WH)
    if (scene_turn is not None and bank.moved_from_x is not None and bank.turn is None and scene_turn.move > 0
            and scene_turn.start <= bank.moved_at <= scene_turn.time):
        # The turn of the move that cleared the model; the turned camera (at the old position) once,
        # to match new tracks to the known points on every frame until one leads.
        x0 = bank.moved_from_x
        turned = camera_after_turn(x0[0:9].reshape(3, 3, order="F"), x0[9:12], scene_turn.b0, scene_turn.q0,
                                   scene_turn.b1, [], [], q1=scene_turn.q1)
        bank = replace(bank, turn=scene_turn, turned_R_WC=None if turned is None else turned.R_WC,
                       turned_p_WC=turned.p_WC if turned is not None and turned.scene_shift else None)
    if bank.leader >= 0 and x_is_set(reference_x):
        bank = replace(bank, model_x=np.array(reference_x, dtype=float))
    if not frame_time > bank.last_frame:
        return bank  # no new frame (or none yet)
    X_frame = pose_at(bank, frame_time, params.pose_tolerance)
    if X_frame is None:
        return replace(bank, last_frame=float(frame_time))  # no pose for that frame: skip it
    ids = np.asarray(ids, np.int64).ravel()
    p_CP = np.asarray(p_CP, dtype=float).reshape(-1, 3)
    usable = np.asarray(valid, bool).ravel() & np.all(np.isfinite(p_CP), axis=1)
    on_body = np.asarray(on_body, bool).ravel()
    in_body_cell = (np.zeros_like(on_body) if in_body_cell is None or not params.use_body_cells
                    else np.asarray(in_body_cell, bool).ravel())
    row = {int(i): k for k, i in enumerate(ids)}
    rejected = frozenset(i for i in bank.rejected if i in row)

    # Candidates are fed while searching: before a leader exists, or when the observed point is
    # lost (a new point to observe). Otherwise the leader alone keeps feeding, the others are frozen.
    # With observers (``max_observers``), candidates keep being found and fed while observing, so
    # that fresh points consistent with the adopted model are at hand when observed points are lost.
    searching = bank.leader < 0 or bank.observed < 0 or params.max_observers > 0
    observing = bank.leader >= 0 and params.max_observers > 0 and x_is_set(reference_x)
    kept, fed, archive = [], False, list(bank.archive)
    for c in bank.candidates:
        k = row.get(c.feature_id)
        is_leader = c.feature_id == bank.leader
        if k is None and not is_leader:
            archive.append(c)  # no longer tracked: gone for good (ids are never reused)
            continue
        learning = (not searching and params.refine_interval > 0 and k is not None and usable[k]
                    and _fits(c, p_CP[k], X_frame, reference_x, allowable_error))
        if k is not None and usable[k] and (searching or is_leader or learning):
            num = c.solution.num_samples
            c = _feed(c, params, criteria, frame_time, p_CP[k], X_frame, forgetting_factor,
                      refine=is_leader)
            fed = fed or c.solution.num_samples > num
        if searching and not is_leader:
            if frame_time - c.last_sample > params.max_lost_time:
                archive.append(c)
                continue  # occluded too long: the slot is freed
            sol = c.solution
            too_long = frame_time - c.admitted > params.max_unconverged_time and not sol.verdict.converged
            misfit = sol.num_samples >= criteria.min_samples and not sol.expected_rms <= params.reject_rms
            # While observing (with observers), a point the adopted camera does not explain is not
            # of the hand (or not any more): its slot goes to a new point.
            misfit = misfit or (observing and c.frames >= params.observe_min_samples
                                and rotation_spread(c.statistic) >= params.min_rotation_spread
                                and not _explained(c, reference_x, bank.adopted_mse, params))
            if too_long or misfit:
                rejected = rejected | {c.feature_id}
                if too_long and not misfit:
                    archive.append(c)  # slow, not wrong: its samples still constrain the camera
                continue
        kept.append(c)

    # Admit new candidates: body features with a point, oldest track first.
    leader, adoptions, round_start = bank.leader, bank.adoptions, bank.round_start
    adopted_mse = bank.adopted_mse
    if searching:
        present = {c.feature_id for c in kept}
        # Confirmed body features first, then features in body cells; oldest track first. While
        # observing (with observers), alternately the nearest to where the adopted model puts the
        # tool point (the tool's points) and the oldest (long tracks: often the hand's own).
        near_known = (_near_known_points(bank, params, X_frame, p_CP, usable)
                      if params.turn_admit_known and leader < 0 else np.zeros_like(on_body))
        order = np.lexsort((ids, ~on_body, ~near_known, ~np.isin(ids, [i for i, _ in bank.known_points])))
        if observing:
            tool_point = predicted_p_CP(np.asarray(reference_x), X_frame)
            nearest = np.argsort(np.linalg.norm(p_CP - tool_point, axis=1))
            order = np.stack([nearest, order], axis=1).ravel()
        for k in order:
            if len(kept) >= params.max_candidates:
                break
            i = int(ids[k])
            if ((on_body[k] or in_body_cell[k] or near_known[k]) and usable[k] and i not in present
                    and i not in rejected):
                kept.append(_admit(i, criteria, frame_time, p_CP[k], X_frame))
                present.add(i)
                fed = True
                if math.isnan(round_start):
                    round_start = float(frame_time)
    archive = _archived(archive, params)
    held_back = False
    # min_rotation_lever: the leader held back on an earlier frame waits for views only while its
    # point is seen; once it is not (its face turned away, its track ended: seed 2's converged
    # points all went within 1 s), the views it waited for are over and it is adopted as it is.
    held = (next((c for c in kept + archive if c.feature_id == bank.held_back), None)
            if leader < 0 and bank.held_back >= 0 else None)  # fmt: skip
    unseen = held is not None and (row.get(held.feature_id) is None
                                   or frame_time - held.last_sample > _HELD_UNSEEN_TIME)
    adopt_held = unseen and held.solution.verdict.converged
    if adopt_held and all(c.feature_id != held.feature_id for c in kept):  # its track ended: from the archive
        archive = [c for c in archive if c.feature_id != held.feature_id]
        kept.append(held)
    # The first to converge leads (the smallest expected error among simultaneous ones). A leader
    # held back on an earlier frame is judged again only when a candidate gained a sample: else
    # the statistics, and so its lever, are as they were.
    converged = ([] if leader >= 0 or (bank.held_back >= 0 and not fed and not adopt_held)
                 else [c for c in kept if c.solution.verdict.converged])
    if converged:
            if adopt_held:
                best = _solve(held, criteria, forgetting_factor, refine=True)
                confirmed = True  # when it was held back
            else:
                best = min(converged, key=lambda c: c.solution.expected_mse)
                best = _solve(best, criteria, forgetting_factor, refine=True)
                confirmed = _confirmed(best, kept, params, row, usable, (p_CP, X_frame))
            if best.solution.verdict.converged and confirmed:
                kind, statistics = "identified", [best.statistic]
                if params.joint:
                    best, statistics = _joint_refined(best, kept, archive, params)
                    if len(statistics) > 1:
                        kind = f"identified, camera refined with {len(statistics)} points"
                lever = smallest_rotation_lever(statistics, best.solution.estimate)
                # min_rotation_lever, min_adopt_rotation_spread: the points' views must pin the
                # camera's rotation too.
                spread = rotation_spread(best.statistic)
                held_back = (lever < params.min_rotation_lever
                             or spread < params.min_adopt_rotation_spread) and not unseen
                if not held_back:
                    kept = [best if c.feature_id == best.feature_id else c for c in kept]
                    leader = best.feature_id
                    adopted_mse = best.solution.expected_mse
                    adoptions = adoptions + (Adoption(float(frame_time), leader, best.statistic.copy(),
                                                      best.admitted, round_start, best.solution.estimate,
                                                      kind, lever),)
    elif leader < 0 and params.keep_camera and bank.previous_x is not None:
            # A slipped tool leaves the camera where it was: if the abandoned model's camera
            # explains a candidate's samples (with its own p_HP), only p_HP is re-identified.
            options = _consistent(replace(bank, candidates=tuple(kept)), params, row, usable,
                                  bank.previous_x, (p_CP, X_frame), min_samples=(
                                      params.keep_camera_min_samples if scene_still_since <= bank.reset_time
                                      else params.observe_min_samples))
            if options:
                mse, leader, p_HP, _ = min(options, key=lambda o: o[0])
                best = next(c for c in kept if c.feature_id == leader)
                # Its expected error sets the allowable error (Eq. (2)'s sigma); with
                # keep_allowable_error, at most that of the identification whose camera is kept.
                expected = min(mse, bank.adopted_mse) if params.keep_allowable_error else mse
                best = _with_camera(best, bank.previous_x, p_HP, expected)
                kept = [best if c.feature_id == leader else c for c in kept]
                adoptions = adoptions + (Adoption(float(frame_time), leader, best.statistic.copy(),
                                                  best.admitted, round_start, best.solution.estimate,
                                                  "previous camera"),)
    elif leader < 0 and bank.known_points:
        # A moved camera: the points the abandoned model observed kept their p_HP; the static scene
        # turned with the camera.
        found, kind = None, "scene turn, tool points kept"
        if bank.turn is not None:
            found = _camera_from_turn(kept, bank, params)
        if found is None:
            kind = "previous tool points"
            found = _camera_from_known_points(kept, dict(bank.known_points), params, bank.adopted_mse)
        if found is not None:
            x, mse, leader = found
            best = next(c for c in kept if c.feature_id == leader)
            expected = min(mse, bank.adopted_mse) if params.keep_allowable_error else mse
            best = _with_camera(best, x, x[12:15].copy(), expected,
                                "converged: the tool points kept, the camera re-identified")
            kept = [best if c.feature_id == leader else c for c in kept]
            adoptions = adoptions + (Adoption(float(frame_time), leader, best.statistic.copy(),
                                              best.admitted, round_start, best.solution.estimate, kind),)
    # Before a leader, a frame that fed any identifier counts as a sample (the state machine
    # checks a solution's samples against the count since a reset); after, observations count.
    count = bank.sample_count + (1 if fed and bank.leader < 0 else 0)
    new_leader = leader != bank.leader
    # Once a leader was held back (min_rotation_lever, min_adopt_rotation_spread), more motion is wanted
    # until one leads or no converged candidate is left (then the detector's trials must find new body
    # features).
    first_point = params.motion_min_samples > 0 and not adoptions and any(
        c.solution.num_samples >= params.motion_min_samples for c in kept)
    more_motion = leader < 0 and (held_back or first_point or (bank.more_motion and any(
        c.solution.verdict.converged for c in kept)))
    held_id = (best.feature_id if held_back
               else bank.held_back if leader < 0 and held is not None and not unseen else -1)
    bank = replace(bank, candidates=tuple(kept), leader=leader, rejected=rejected, round_start=round_start,
                   sample_count=count, archive=tuple(archive),
                   last_frame=float(frame_time), adoptions=adoptions,
                   observed=bank.observed if leader == bank.leader else leader,
                   observed_last=bank.observed_last if leader == bank.leader else None,
                   observed_p_HP=bank.observed_p_HP if leader == bank.leader else None,
                   witness=bank.witness if leader == bank.leader else -1,
                   adopted_mse=adopted_mse, more_motion=more_motion, held_back=held_id)
    if new_leader:
        bank = replace(bank, refined_solution=None, last_refinement=float(frame_time))
        if leader >= 0:
            bank = _verified(bank)  # the candidates the new model was identified among
    elif (leader >= 0 and params.refine_interval > 0 and x_is_set(reference_x)
          and frame_time - bank.last_refinement >= params.refine_interval):
        bank = _refine_adopted(bank, params, reference_x, float(frame_time))
    return _observe(bank, params, frame_time, X_frame, ids, p_CP, usable, on_body | in_body_cell, row,
                    reference_x, allowable_error, depth_gap)


def _explained(c: Candidate, x, adopted_mse: float, params: CandidateParams) -> bool:
    """Whether the camera of ``x`` explains the candidate's samples (its own best ``p_HP``) within
    ``observe_consistency`` times the adopted RMS error."""
    R_WC, p_WC = np.asarray(x)[0:9].reshape(3, 3, order="F"), np.asarray(x)[9:12]
    return own_fit(c.statistic, R_WC, p_WC)[1] <= params.observe_consistency**2 * adopted_mse


def _fits(c: Candidate, p_CP, X_WH, reference_x, allowable_error: float) -> bool:
    """Whether the adopted model (its camera, the candidate's own best ``p_HP``) explains this
    sample of the candidate within the allowable error."""
    if not (x_is_set(reference_x) and math.isfinite(allowable_error)) or c.solution.num_samples < 1:
        return False
    R_WC, p_WC = reference_x[0:9].reshape(3, 3, order="F"), reference_x[9:12]
    p_HP = best_p_HP_given_camera(c.statistic, R_WC, p_WC)
    return _error(p_CP, X_WH, pack_x(R_WC, p_WC, p_HP)) <= allowable_error


def _refine_adopted(bank: CandidateBank, params: CandidateParams, reference_x, time: float) -> CandidateBank:
    """``refine_interval``: the adopted camera refined jointly with the leader and every candidate
    it explains (``_joint_refined`` from the adopted camera), offered as a converged solution with
    the next ``refinement`` counter; unchanged when no other point joins."""
    bank = replace(bank, last_refinement=time)
    leader = bank.find(bank.leader)
    if leader is None:
        return bank
    R_WC, p_WC = reference_x[0:9].reshape(3, 3, order="F"), reference_x[9:12].copy()
    p_HP = best_p_HP_given_camera(leader.statistic, R_WC, p_WC)
    x = pack_x(R_WC, p_WC, p_HP)
    mse = mean_squared_error_of(leader.statistic, x)
    start = EyeToHandEstimate(R_WC, p_WC, p_HP, x, mse)
    seed = replace(leader, solution=replace(leader.solution, projected=start, refined=start,
                                            expected_mse=max(mse, bank.adopted_mse)))
    refined, statistics = _joint_refined(seed, bank.candidates, bank.archive, params)
    num_points = len(statistics)
    if num_points < 2:
        return bank
    estimate = refined.solution.estimate
    verdict = Verdict(True, f"the adopted model refined jointly with {num_points - 1} other points")
    solution = replace(refined.solution, expected_mse=estimate.mean_squared_error, verdict=verdict,
                       refinement=bank.refinement + 1)
    return replace(bank, refined_solution=solution, refinement=bank.refinement + 1)


def _archived(archive: list, params: CandidateParams) -> list:
    """The archive bounded to ``max_archived`` candidates with enough samples, the most first."""
    if not params.joint:
        return []
    useful = [c for c in archive if c.solution.num_samples >= params.joint_min_samples]
    return sorted(useful, key=lambda c: -c.solution.num_samples)[: params.max_archived]


# m^2 (1 um RMS): a mean squared error below this is round-off (noise-free data); the joint
# refinement's ratios (the members' limit, the weights) are taken against at least this.
_ROUND_OFF_MSE = 1e-12


def _joint_refined(best: Candidate, kept, archive, params: CandidateParams) -> tuple[Candidate, list]:
    """``params.joint``: the leader's camera refined jointly with every other candidate (tracked
    or archived, ``joint_min_samples`` samples) that it explains (``eye_to_hand.refine_joint``:
    one camera, one ``p_HP`` per point). Members are the points whose own mean squared error
    (with their best ``p_HP``) is within ``joint_consistency^2`` times the leader's, first under
    the leader's camera, then again under the joint one (three times with ``stitch_radius``: the
    groups of tracks of one point are formed again under each better camera). Returns the leader
    with the joint camera and its own ``p_HP`` (its group's, when stitched; its verdict and
    ``expected_mse`` unchanged: the paper's rule judges the leader), and the statistics of the
    points used (one per group when stitched; the leader's first)."""
    estimate = best.solution.estimate
    if estimate is None:
        return best, [best.statistic]
    others = [c for c in list(kept) + list(archive)
              if c.feature_id != best.feature_id and c.solution.num_samples >= params.joint_min_samples]
    R, p_WC = estimate.R_WC, estimate.p_WC
    limit = params.joint_consistency**2 * max(best.solution.expected_mse, _ROUND_OFF_MSE)
    members = []
    for _ in range(3 if params.stitch_radius > 0 else 2):
        members = [c for c in others if own_fit(c.statistic, R, p_WC)[1] <= limit]
        if not members:
            return best, [best.statistic]
        statistics = [c.statistic for c in [best] + members]
        if params.stitch_radius > 0:
            statistics = [s for _, s in stitch(statistics, R, p_WC, params.stitch_radius)]
        fits = [own_fit(s, R, p_WC) for s in statistics]
        P = np.array([p_HP for p_HP, _ in fits])
        weights = (_inverse_variance_weights(np.array([mse for _, mse in fits])) if params.joint_weighted
                   else np.ones(len(P)))
        refined = refine_joint([w * _S(s) for w, s in zip(weights, statistics, strict=True)], R, p_WC, P)
        if refined is None:
            return best, [best.statistic]
        R, p_WC, P = refined
    x = pack_x(R, p_WC, P[0])  # the leader's point (its group is the first)
    joint = EyeToHandEstimate(R, p_WC.copy(), P[0].copy(), x, mean_squared_error_of(best.statistic, x))
    solution = replace(best.solution, projected=joint, refined=joint)
    return replace(best, solution=solution), statistics


def _inverse_variance_weights(mse: np.ndarray) -> np.ndarray:
    """``joint_weighted``: each point's weight, the inverse of its own mean squared error (``own_fit``
    under the joint camera), scaled to a mean of 1."""
    weights = 1.0 / np.maximum(mse, _ROUND_OFF_MSE)
    return weights / weights.mean()


def smallest_rotation_lever(statistics: list, estimate: EyeToHandEstimate | None) -> float:
    """The smallest of ``eye_to_hand.rotation_levers`` of the points' statistics (each point with
    its best ``p_HP``) at the estimate's camera, m (0 without an estimate)."""
    if estimate is None:
        return 0.0
    P = [best_p_HP_given_camera(s, estimate.R_WC, estimate.p_WC) for s in statistics]
    return float(rotation_levers([_S(s) for s in statistics], estimate.R_WC, estimate.p_WC, P)[0])


# A merge of two tracks into one point may raise the mean squared error by this factor at most.
STITCH_MAX_INCREASE = 2.0


def stitch(statistics: list, R_WC: np.ndarray, p_WC: np.ndarray, radius: float,
           max_increase: float = STITCH_MAX_INCREASE) -> list:
    """Tracks of the same physical point, joined (beyond the paper). Statistics (the identifiers'
    state vectors, additive: ``S``, the weight and the count) are taken in order; each joins the
    first group whose point (the best ``p_HP`` of the group's summed statistic under the camera
    ``R_WC, p_WC``) is within ``radius`` of its own best ``p_HP``, if one point explains the union
    (the summed statistic's mean squared error with its best ``p_HP`` is at most ``max_increase``
    times the two parts' pooled errors, each with its own best ``p_HP``), else it starts a group.
    Returns ``[(member indices, summed statistic)]``; the first statistic's group is the first.

    Eq. (30) holds for every sample of a point fixed on the hand whichever track measured it, so
    the group's summed statistic is one identifier of that point over the union of the tracks'
    views: its ``p_HP`` is no longer traded off against the camera's position within one track's
    few tenths of a radian of hand rotation. Merging two marks ``d`` apart raises the error by the
    weighted variance of their positions (``w (1 - w) d^2``: 60 mm^2 for the rod's 18 mm spacing
    at a 3:1 split, against a per-sample noise of a few mm^2); the same point under a camera a few
    millimetres off raises it by a fraction."""
    groups = []  # [indices, summed statistic, its best p_HP, its mean squared error there]
    for i, statistic in enumerate(statistics):
        statistic = np.asarray(statistic, dtype=float)
        p_HP, mse = own_fit(statistic, R_WC, p_WC)
        for group in groups:
            if np.linalg.norm(group[2] - p_HP) > radius:
                continue
            merged = group[1] + statistic
            q = best_p_HP_given_camera(merged, R_WC, p_WC)
            merged_mse = mean_squared_error_of(merged, pack_x(R_WC, p_WC, q))
            n_group, n = _weight(group[1]), _weight(statistic)
            pooled = (n_group * group[3] + n * mse) / (n_group + n)
            if merged_mse <= max_increase * pooled:
                group[0].append(i)
                group[1:] = [merged, q, merged_mse]
                break
        else:
            groups.append([[i], statistic.copy(), p_HP, mse])
    return [(group[0], group[1]) for group in groups]


def _core(statistic: np.ndarray):
    """The identifier core holding an identifier's state vector (its ``S``, weight and count)."""
    identifier = EyeToHandIdentifier()
    identifier.set_state(statistic)
    return identifier.core


def _weight(statistic: np.ndarray) -> float:
    """The (forgetting-weighted) number of samples of an identifier's state vector."""
    return _core(statistic).weight


def _S(statistic: np.ndarray) -> np.ndarray:
    """``S = sum A_t^T A_t`` (16 x 16) from an identifier's state vector."""
    return _core(statistic).S


def _confirmed(c: Candidate, kept, params: CandidateParams, row, usable, frame) -> bool:
    """Whether another candidate's samples agree with ``c``'s camera (with their own ``p_HP``),
    when ``params.confirm_with_witness`` asks for it: two tracked points of the hand must tell the
    same camera pose before it is adopted."""
    if not params.confirm_with_witness:
        return True
    probe = CandidateBank(candidates=tuple(kept), leader=c.feature_id, adopted_mse=c.solution.expected_mse)
    return bool(_consistent(probe, params, row, usable, c.solution.x, frame, exclude=(c.feature_id,)))


def _with_camera(c: Candidate, x_previous: np.ndarray, p_HP: np.ndarray, mse: float,
                 verdict: str = "converged: the previous camera explains the samples, p_HP re-identified",
                 ) -> Candidate:  # fmt: skip
    """The candidate with the converged solution "the camera of ``x_previous`` and this p_HP"."""
    R_WC, p_WC = x_previous[0:9].reshape(3, 3, order="F"), x_previous[9:12]
    estimate = EyeToHandEstimate(R_WC, p_WC.copy(), p_HP, pack_x(R_WC, p_WC, p_HP), mse)
    verdict = Verdict(True, verdict)
    solution = replace(c.solution, projected=estimate, refined=estimate, expected_mse=mse, verdict=verdict)
    return replace(c, solution=solution)


def _model_points(bank: CandidateBank, params: CandidateParams) -> tuple:
    """``(feature_id, p_HP)`` of every point the adopted model holds (``keep_tool_points``): the
    leader first (the adopted tool point), the observed point, the witness, the observers, then
    every other candidate, tracked or archived (its track ended: a mark out of view now, which a
    new track may find again after the move), that the model's camera explains (``_explained``,
    with ``observe_min_samples`` samples and ``min_rotation_spread``) with its best ``p_HP`` under
    that camera: points of the hand as well as of the tool, all fixed in H, and the more of them,
    the more spread."""
    x = bank.model_x
    anchor = x[12:15].copy()
    points = [(bank.leader, anchor),
              (bank.observed, anchor if bank.observed_p_HP is None else bank.observed_p_HP),
              (bank.witness, bank.witness_p_HP)] + [(o[0], o[1]) for o in bank.observers]
    R_WC, p_WC = x[0:9].reshape(3, 3, order="F"), x[9:12]
    points += [(c.feature_id, best_p_HP_given_camera(c.statistic, R_WC, p_WC))
               for c in bank.candidates + bank.archive
               if c.frames >= params.observe_min_samples
               and rotation_spread(c.statistic) >= params.min_rotation_spread
               and _explained(c, x, bank.adopted_mse, params)]
    known = {}
    for feature_id, p_HP in points:
        if feature_id >= 0 and p_HP is not None and feature_id not in known:
            known[feature_id] = np.array(p_HP, dtype=float)
    return tuple(known.items())


def _fit_dropping_misfits(pairs: list, solve, limit: float):
    """Fit a camera to ``pairs`` (``(candidate, p_HP)``) with ``solve(pairs) -> (R_WC, p_WC, ...)``
    or None; while a point misfits (mean squared error over ``limit``: a track that slid onto
    another point, a point of a link that moved), leave out the worst and fit again, as long as the
    points that fit are more than half of them (a lone survivor fits anything near). Returns
    ``(found, pairs, errors)`` or None."""
    total = len(pairs)
    while 2 * len(pairs) > total:
        found = solve(pairs)
        if found is None:
            return None
        errors = [mean_squared_error_of(c.statistic, pack_x(found[0], found[1], p)) for c, p in pairs]
        if max(errors) <= limit:
            return found, pairs, errors
        pairs = [pair for k, pair in enumerate(pairs) if k != int(np.argmax(errors))]
    return None


def _leading(pairs: list, errors: list, found, anchor: np.ndarray):
    """``(x, mse, feature_id)`` of the fitted point nearest the adopted tool point ``anchor`` in H,
    with the fitted camera."""
    k = min(range(len(pairs)), key=lambda i: float(np.linalg.norm(pairs[i][1] - anchor)))
    return pack_x(found[0], found[1], pairs[k][1]), errors[k], pairs[k][0].feature_id


def _camera_from_known_points(kept, known: dict, params: CandidateParams, adopted_mse: float):
    """``keep_tool_points``: the camera that the known points' samples since the reset give
    (``camera_given_points``; ``known`` in the order of ``_model_points``, the adopted tool point
    first), from the points with ``observe_min_samples`` samples that fit it within
    ``observe_consistency`` of the adopted RMS error (``_fit_dropping_misfits``), if they spread
    ``min_point_spread`` off a line. Returns ``(x, mse, feature_id)`` (the estimate with the ``p_HP``
    of the point nearest the adopted tool point in H, its mean squared error, that point) or None."""
    pairs = [(c, known[c.feature_id]) for c in kept
             if c.feature_id in known and c.solution.num_samples >= params.observe_min_samples]
    fit = _fit_dropping_misfits(pairs, lambda ps: camera_given_points(
        [_S(c.statistic) for c, _ in ps], np.array([p for _, p in ps])),
        params.observe_consistency**2 * adopted_mse)  # fmt: skip
    if fit is None or not fit[0][2] >= params.min_point_spread:
        return None
    return _leading(fit[1], fit[2], fit[0], next(iter(known.values())))


def _camera_from_turn(kept, bank: CandidateBank, params: CandidateParams):
    """``keep_tool_points`` with the scene's turn: the camera that the move left turned as the
    static scene shows and placed where the known points' samples since the move put it
    (``camera_after_turn``). The points: candidates with ``turn_min_samples`` samples that are a
    known point, by id (tracked through the move) or by ``p_HP`` (``turn_radius``, see
    ``CandidateParams``), fitted with ``_fit_dropping_misfits``. Returns ``(x, mse, feature_id)``
    as ``_camera_from_known_points`` or None. With the scene's shift (``turned_p_WC``), the tracks
    are matched under the camera there, within ``turn_scene_shift``, one new track sufficing."""
    if bank.turned_R_WC is None:
        return None  # too few anchors in the turn
    known = dict(bank.known_points)
    x0, turn, R_turned = bank.moved_from_x, bank.turn, bank.turned_R_WC
    R_WC0, p_WC0 = x0[0:9].reshape(3, 3, order="F"), x0[9:12]
    shifted = bank.turned_p_WC is not None
    p_turned, window = _turn_window(bank, params)
    known_p = np.array(list(known.values()))
    ready = [c for c in kept if c.solution.num_samples >= params.turn_min_samples]
    pairs = [(c, known[c.feature_id]) for c in ready if c.feature_id in known]
    # A new track (the turn ended the old one) is a known point seen from the turned camera at
    # the old position: off by the camera's unknown shift, the same for every track (over the same
    # time), so the shift is the offset most new tracks agree on.
    new = [c for c in ready if c.feature_id not in known
           and rotation_spread(c.statistic) >= params.min_rotation_spread]  # else a point of any link fits
    guesses = np.array([best_p_HP_given_camera(c.statistic, R_turned, p_turned) for c in new]).reshape(-1, 3)
    tracked = [best_p_HP_given_camera(c.statistic, R_turned, p_turned) - p for c, p in pairs]
    offset = _common_offset(guesses, known_p, tracked, params, window, 1 if shifted else 2)
    if offset is not None:
        for c, guess in zip(new, guesses, strict=True):
            distance = np.linalg.norm(known_p - (guess - offset), axis=1)
            j = int(np.argmin(distance))
            # The nearest other mark (known points within turn_radius of it are tracks of it).
            others = distance[np.linalg.norm(known_p - known_p[j], axis=1) > params.turn_radius]
            if distance[j] <= params.turn_radius and not np.any(others <= 2.0 * params.turn_radius):
                pairs.append((c, known_p[j]))
    fit = _fit_dropping_misfits(pairs, lambda ps: camera_after_turn(
        R_WC0, p_WC0, turn.b0, turn.q0, turn.b1, [_S(c.statistic) for c, _ in ps],
        np.array([p for _, p in ps])), params.observe_consistency**2 * bank.adopted_mse)  # fmt: skip
    if fit is None:
        return None
    if not shifted and not tracked and _on_a_line([p for _, p in fit[1]], params.turn_radius):
        # Matched by the offset most new tracks agree on, with the shift unknown: along a row of
        # marks (the rod's) an offset of one spacing maps tracks of marks never known onto their
        # known neighbours and the camera follows it (17.7 mm in the tests); points off the line
        # leave no such offset.
        return None
    return _leading(fit[1], fit[2], fit[0], known_p[0])


def _turn_window(bank: CandidateBank, params: CandidateParams) -> tuple[np.ndarray, float]:
    """Where the turned camera is taken to be and how far off that may be (m): at the shift the
    scene's depth gave, within ``turn_scene_shift``, else at the old position, within
    ``turn_max_shift``."""
    if bank.turned_p_WC is not None:
        return bank.turned_p_WC, params.turn_scene_shift
    return bank.moved_from_x[9:12], params.turn_max_shift


def _near_known_points(bank: CandidateBank, params: CandidateParams, X_WH: np.ndarray, p_CP: np.ndarray,
                       usable: np.ndarray) -> np.ndarray:
    """``turn_admit_known``: per tracked feature, whether its point lies within the turned camera's
    window plus ``turn_radius`` of where that camera, posed as ``_turn_window`` says, sees a known
    point of the hand at ``X_WH`` (all False before a turn). The detector's body cells are fixed in
    the image, so after a camera move they hold the static scene and its trials must find the
    body's features again (seed 5: 10.7 s without a candidate while tracks lay 5-6 mm from where
    the known marks were predicted); the model says where they are. A point of the static scene
    admitted so is left out by the camera's fit: with the hand turning, its samples fit no point
    of H."""
    near = np.zeros(len(usable), bool)
    if bank.turned_R_WC is None or not bank.known_points or not np.any(usable):
        return near
    p_WC, window = _turn_window(bank, params)
    p_CQ = points_in_camera(bank.turned_R_WC, p_WC, np.array([p for _, p in bank.known_points]), X_WH)
    distance = np.linalg.norm(p_CP[usable][:, None, :] - p_CQ[None, :, :], axis=2).min(axis=1)
    near[usable] = distance <= window + params.turn_radius
    return near


def _on_a_line(points: list, tolerance: float) -> bool:
    """Whether the points lie within ``tolerance`` (RMS, m) of one line (one or two always do)."""
    return len(points) < 3 or spread_off_line(np.cov(np.array(points).T, bias=True)) <= tolerance


def _common_offset(guesses: np.ndarray, known_p: np.ndarray, tracked: list, params: CandidateParams,
                   max_shift: float, min_support: int):
    """The offset (in H) between new tracks' ``p_HP`` under the turned camera (``guesses``) and the
    known points: the median offset of the points tracked through the move (``tracked``, their
    own offsets) if any; else, among the offsets within ``max_shift`` of a guess to a known
    point, the one that the most guesses fit within ``turn_radius`` (at least ``min_support``: with
    the camera's shift unknown, two, as one track fits some mark for many shifts), the smallest of
    those. None if none."""
    if tracked:
        return np.median(np.array(tracked), axis=0)
    options = (guesses[:, None, :] - known_p[None, :, :]).reshape(-1, 3)
    options = options[np.linalg.norm(options, axis=1) <= max_shift]
    best, support = None, min_support - 1
    for o in sorted(options, key=lambda o: float(np.linalg.norm(o))):
        fits = np.linalg.norm(guesses[:, None, :] - o - known_p[None, :, :], axis=2).min(axis=1)
        n = int(np.count_nonzero(fits <= params.turn_radius))
        if n > support:
            best, support = o, n
    return best


def _admit(feature_id, criteria, time, p_CP, X_WH) -> Candidate:
    identifier = EyeToHandIdentifier(criteria=criteria)
    identifier.add(p_CP, X_WH[:3, :3], X_WH[:3, 3])
    return Candidate(feature_id, identifier.state, identifier.solve(refine_estimate=False), float(time),
                     float(time), np.array(p_CP), np.array(X_WH), sampled_p_CP=np.array(p_CP))


def _identifier(c: Candidate, criteria, forgetting_factor) -> EyeToHandIdentifier:
    identifier = EyeToHandIdentifier(forgetting_factor, criteria)
    identifier.set_state(c.statistic)
    return identifier


def _solve(c: Candidate, criteria, forgetting_factor, refine: bool) -> Candidate:
    solution = _identifier(c, criteria, forgetting_factor).solve(refine_estimate=refine)
    return replace(c, solution=solution)


def _feed(c: Candidate, params, criteria, time, p_CP, X_WH, forgetting_factor, refine) -> Candidate:
    gated = within_motion_gate(c.last_p_CP, c.last_X_WH, p_CP, X_WH, params)
    c = replace(c, last_p_CP=np.array(p_CP), last_X_WH=np.array(X_WH))
    if not gated:
        return c
    c = replace(c, frames=c.frames + 1)
    if not _new_view(c, p_CP, params):
        return replace(c, last_sample=float(time))  # seen where it was: held, not lost
    identifier = _identifier(c, criteria, forgetting_factor)
    identifier.add(p_CP, X_WH[:3, :3], X_WH[:3, 3])
    return replace(c, statistic=identifier.state, last_sample=float(time), sampled_p_CP=np.array(p_CP),
                   solution=identifier.solve(refine_estimate=refine))


def _new_view(c: Candidate, p_CP, params: CandidateParams) -> bool:
    """``min_view_change``: whether the point moved at least that far in the camera frame since its
    last sample. A point's errors repeat with its view (the same pose of the tool, the same error),
    so a view held for a second is one error counted thirty times: Eq. (1)'s sum then weighs the
    views by how long the arm held them (the detector's trials and the pause after a convergence
    hold it), and the camera leans towards the few held views."""
    return (params.min_view_change <= 0 or c.sampled_p_CP is None
            or float(np.linalg.norm(np.asarray(p_CP) - c.sampled_p_CP)) >= params.min_view_change)


def _observe(bank, params, time, X_WH, ids, p_CP, usable, body, row, reference_x,
             allowable_error=math.inf, depth_gap=None) -> CandidateBank:
    """``_observe_primary`` (the observed point and its witness), then the extra observers
    (``params.max_observers``, the points nearest the adopted tool point first): every consistent
    point tracked now gives its own ``s_t`` under the adopted camera with its own ``p_HP``. The
    points within ``observe_radius`` of the tool point (the tool's) and the others (the hand's) are
    two groups; the reported ``s_t`` is the larger of the groups' lower medians (the hand's, when it
    is one point, only in a frame without a tool point). A change of the body moves every point of
    its group (a slipped tool the tool's, a moved camera all), a tracking failure one; and while
    the observed point is lost (its face turned away, or its track ended in the change itself) the
    observers keep the observation going, so a change is not missed for want of the one point the
    paper observes.

    A frame whose sample includes a tool point within the allowable error *verifies* the model:
    every candidate's samples so far count as taken under a verified model (``verified_overlap``).
    A frame with no sample may count as a violation (``unverified_evidence``). The adopted tool
    point's depth check (``free_space_radius``) joins the frame's sample."""
    before = bank.sample_count
    bank = _observe_points(bank, params, time, X_WH, ids, p_CP, usable, body, row, reference_x,
                           allowable_error)  # fmt: skip
    if params.free_space_radius > 0 and depth_gap is not None:
        bank = _free_space_sample(bank, reference_x, X_WH, depth_gap, before)
    if bank.leader < 0 or bank.sample_count > before:
        if bank.leader >= 0 and bank.tool_observed and bank.sample_error <= allowable_error:
            bank = _verified(bank)  # a tool point the model holds was seen where the model puts it
        return bank
    x = _model_in_use(bank, reference_x)
    if x is not None and params.unverified_evidence and _unverified_tool(bank, params, row, usable, x,
                                                                          (p_CP, X_WH)):
        return replace(bank, sample_count=before + 1, sample_error=math.inf, sample_errors=())
    return bank


def _free_space_sample(bank, reference_x, X_WH, depth_gap, before: int) -> CandidateBank:
    """``free_space_radius``: the depth behind the adopted tool point gives ``s_t =
    max(gap, 0)^2``, the larger with the points' sample of this frame, or this frame's only one."""
    x = _model_in_use(bank, reference_x)
    if x is None:
        return bank
    gap = depth_gap(predicted_p_CP(x, X_WH))
    if math.isnan(gap):
        return bank  # the tool point out of view: no evidence either way
    s_t = max(gap, 0.0) ** 2
    if bank.sample_count > before:
        return replace(bank, sample_error=max(bank.sample_error, s_t))
    return replace(bank, sample_count=before + 1, sample_error=s_t, sample_errors=())


def _verified(bank: CandidateBank) -> CandidateBank:
    """Every candidate's samples so far were taken while the model was verified (``verified_overlap``)."""
    return replace(bank, candidates=tuple(c if c.verified_samples == c.frames
                                          else replace(c, verified_samples=c.frames)
                                          for c in bank.candidates))


def _unverified_tool(bank, params, row, usable, x, frame) -> bool:
    """``unverified_evidence``: whether a tool candidate (within ``observe_radius`` of the adopted
    tool point) is explained by the adopted camera with its own ``p_HP`` but lacks the
    ``verified_overlap`` samples to observe."""
    if params.verified_overlap == 0:
        return False
    options = _near_tool(_consistent(bank, params, row, usable, x, frame), x[12:15].copy(), params)
    return any(bank.find(o[1]).verified_samples < params.verified_overlap for o in options)


def _observe_points(bank, params, time, X_WH, ids, p_CP, usable, body, row, reference_x,
                    allowable_error=math.inf) -> CandidateBank:
    """The observed, witness and observer points' ``s_t`` (see ``_observe``); ``tool_observed``
    says whether a tool point gave one this frame."""
    before = bank.sample_count
    bank = _observe_primary(bank, params, time, X_WH, ids, p_CP, usable, body, row, reference_x,
                            allowable_error)  # fmt: skip
    bank = replace(bank, tool_observed=bank.sample_count > before)  # the observed point is the tool's
    if params.max_observers == 0:
        return bank
    x = _model_in_use(bank, reference_x)
    if x is None:
        return bank
    anchor = x[12:15].copy()  # the adopted tool point
    errors, observers = [], []  # errors: (s_t, on the tool)
    for feature_id, p_HP, last in bank.observers:
        k = _gated_row(feature_id, last, row, p_CP, X_WH, params)
        if k is None or feature_id in (bank.observed, bank.witness):
            continue  # lost, jumped, or observed already: dropped
        if usable[k]:
            x[12:15] = p_HP
            errors.append((_error(p_CP[k], X_WH, x), _on_tool(p_HP, anchor, params)))
            last = (p_CP[k].copy(), X_WH)
        observers.append((feature_id, p_HP, last))
    if len(observers) < params.max_observers:
        taken = {o[0] for o in observers} | {bank.observed, bank.witness}
        options = _consistent(bank, params, row, usable, x, (p_CP, X_WH), exclude=tuple(taken), verified=True)
        # The tool's points first (nearest the adopted tool point), then the hand's.
        for _, feature_id, p_HP, k in sorted(options, key=lambda o: float(np.linalg.norm(o[2] - anchor))):
            if len(observers) >= params.max_observers:
                break
            observers.append((feature_id, p_HP, (p_CP[k].copy(), X_WH)))
    bank = replace(bank, observers=tuple(observers))
    if not errors and bank.sample_count == before and params.blind_min_samples > 0:
        return _blind_evidence(bank, params, row, usable, x, allowable_error, before)
    if bank.sample_count > before:  # the observed point (or its witness) gave a sample too
        primary = [bank.observed_p_HP if bank.observed_p_HP is not None else anchor, bank.witness_p_HP]
        errors += [(e, p is not None and _on_tool(p, anchor, params))
                   for e, p in zip(bank.sample_errors, primary, strict=False)]
    if not errors:
        return bank
    # Per group (the tool's points, the hand's), the lower median: one point (the smallest of
    # two) is the paper's; with three or more, a point that fails alone (a track that slid, a
    # point re-acquired near the prediction by chance) moves it neither up nor down. The larger of
    # the two groups' is reported: a slipped tool moves the tool's points only, a moved camera all.
    # The hand's points fail only with a moved camera, which moves the tool's too: while a tool
    # point is seen, a hand group of one point speaks only with the tool's (its track sliding onto
    # the background is not a change).
    tool = [e for e, on_tool in errors if on_tool]
    hand = [e for e, on_tool in errors if not on_tool]
    reported = max(_lower_median(tool), _lower_median(hand) if len(hand) >= 2 or not tool else -math.inf)
    return replace(bank, sample_count=before + 1, sample_error=reported,
                   tool_observed=bool(tool))


def _blind_evidence(bank, params, row, usable, x, allowable_error: float, before: int) -> CandidateBank:
    """No observed point this frame (``blind_min_samples``): the candidates tracked now with at
    least that many samples are asked instead. When at least two are and NONE is explained by the
    adopted camera within the allowable error (its mean squared error with its own best ``p_HP``),
    the frame counts as a sample of that size (the smallest): every point in view disagrees with
    the model, as after a moved camera; one point of the hand or tool that fits (any point fits
    while the hand only translates) keeps the frame silent."""
    R_WC, p_WC = x[0:9].reshape(3, 3, order="F"), x[9:12]
    misfits = []
    for c in bank.candidates:
        k = row.get(c.feature_id)
        if k is None or not usable[k] or c.frames < params.blind_min_samples:
            continue
        misfits.append(own_fit(c.statistic, R_WC, p_WC)[1])
    if len(misfits) < 2 or not min(misfits) > allowable_error:
        return bank
    return replace(bank, sample_count=before + 1, sample_error=float(min(misfits)))


def _on_tool(p_HP, anchor, params: CandidateParams) -> bool:
    return float(np.linalg.norm(np.asarray(p_HP) - anchor)) <= params.observe_radius


def _lower_median(values: list) -> float:
    """The lower median (-inf for none): the smaller of two, the middle of three."""
    if not values:
        return -math.inf
    values = sorted(v if math.isfinite(v) else math.inf for v in values)
    return values[(len(values) - 1) // 2]


def _model_in_use(bank: CandidateBank, reference_x) -> np.ndarray | None:
    """The model observations are judged against: the adopted ``x`` (reference) if set, else the
    leader's solution; None when there is no leader or no model yet. A copy."""
    if bank.leader < 0:
        return None
    x = reference_x if x_is_set(reference_x) else bank.find(bank.leader).solution.x
    return np.array(x, dtype=float) if x_is_set(x) else None


def _observe_primary(bank, params, time, X_WH, ids, p_CP, usable, body, row, reference_x,
                     allowable_error=math.inf) -> CandidateBank:
    """The observed point's ``s_t`` (Eq. (2)) under the reference estimate, confirmed by a witness;
    when it is lost, re-acquisition near the prediction or another consistent candidate.

    The witness is a second candidate consistent with the adopted camera (nearest in H to the
    observed point, so on the same part of the tool when there is one). The reported ``s_t`` is
    the smaller of the two: a change of the body (the tool slipped, the camera moved) moves both
    points, a tracking failure (a corner sliding along a silhouette onto the background) only one.
    When the observed point alone violates ``allowable_error`` for ``primary_failures`` samples
    while the witness does not, the witness becomes the observed point."""
    x = _model_in_use(bank, reference_x)
    if x is None:
        return bank
    anchor = x[12:15].copy()  # the adopted tool point
    if bank.observed_p_HP is not None:
        x[12:15] = bank.observed_p_HP
    k = _gated_row(bank.observed, bank.observed_last, row, p_CP, X_WH, params)
    if k is None:
        return _reacquire(bank, params, X_WH, ids, p_CP, usable, body, row, x, anchor)
    if not usable[k]:
        return bank
    error = _error(p_CP[k], X_WH, x)
    bank = replace(bank, observed_last=(p_CP[k].copy(), X_WH))
    if bank.witness < 0 or bank.witness not in row:
        bank = _choose_witness(bank, params, row, usable, x, (p_CP, X_WH), anchor)
    w = _gated_row(bank.witness, bank.witness_last, row, p_CP, X_WH, params) if bank.witness >= 0 else None
    reported, failures, errors = error, 0, (error,)
    if w is not None and usable[w]:
        x_w = x.copy()
        x_w[12:15] = bank.witness_p_HP
        witness_error = _error(p_CP[w], X_WH, x_w)
        bank = replace(bank, witness_last=(p_CP[w].copy(), X_WH))
        reported = min(error, witness_error)
        errors = (error, witness_error)
        if error > allowable_error >= witness_error:
            failures = bank.primary_failures + 1
    elif w is None and bank.witness >= 0:
        bank = replace(bank, witness=-1, witness_p_HP=None, witness_last=None)
    bank = replace(bank, sample_count=bank.sample_count + 1, primary_failures=failures,
                   sample_error=reported if math.isfinite(reported) else math.inf, sample_errors=errors)
    if failures >= params.primary_failures:
        bank = replace(bank, observed=bank.witness, observed_p_HP=bank.witness_p_HP,
                       observed_last=bank.witness_last, witness=-1, witness_p_HP=None,
                       witness_last=None, primary_failures=0)
    return bank


def _error(p_CP, X_WH, x) -> float:
    return SustainableIdentifier.sample_error(build_A(p_CP, X_WH[:3, :3], X_WH[:3, 3]), x)


def _gated_row(feature_id, last, row, p_CP, X_WH, params):
    """The feature's row if tracked and its point did not jump (a tracking failure), else None."""
    k = row.get(feature_id)
    if k is not None and last is not None:
        p_prev, X_prev = last
        jump = replace(params, gate_margin=params.gate_margin + params.observation_jump)
        if not within_motion_gate(p_prev, X_prev, p_CP[k], X_WH, jump):
            return None
    return k


def _consistent(bank, params, row, usable, x, frame, exclude=(), verified=False, min_samples=None):
    """Candidates tracked now with ``min_samples`` samples (None: ``observe_min_samples``) whose
    samples the adopted camera explains (each with its own best ``p_HP``, least squares from its
    statistic), and whose point in this ``frame`` (``(p_CP, X_WH)``) too (a frozen candidate's track
    may have slid onto the background since): ``[(mse, feature_id, p_HP, row)]``. ``verified``:
    only candidates with ``verified_overlap`` samples taken while the adopted model was verified
    (the points that may observe it)."""
    p_now, X_now = frame
    R_WC, p_WC = x[0:9].reshape(3, 3, order="F"), x[9:12]
    limit = params.observe_consistency**2 * bank.adopted_mse
    out = []
    for c in bank.candidates:
        k = row.get(c.feature_id)
        if k is None or not usable[k] or c.feature_id in exclude:
            continue
        if c.frames < (params.observe_min_samples if min_samples is None else min_samples):
            continue
        if verified and c.verified_samples < params.verified_overlap:
            continue  # first tracked while the model was not verified: its p_HP is unchecked
        if rotation_spread(c.statistic) < params.min_rotation_spread:
            continue  # the hand hardly turned: any point, even on another link, would fit
        p_HP, mse = own_fit(c.statistic, R_WC, p_WC)
        if mse <= limit and _error(p_now[k], X_now, pack_x(R_WC, p_WC, p_HP)) <= _NOW_FACTOR * limit:
            out.append((mse, c.feature_id, p_HP, k))
    return out


# s: a held-back leader's point missing this long is gone, not a flicker of the refiner (a saddle
# missed for 1-3 frames at 30 Hz; adopting on those took levers of 9 mm, not 15).
_HELD_UNSEEN_TIME = 0.3

# A single sample's squared error may exceed the mean squared limit by this much (its chi-square
# tail with three degrees of freedom: P(s > 10 mse) < 1e-3 for Gaussian noise).
_NOW_FACTOR = 10.0


def _near_tool(options, anchor, params: CandidateParams) -> list:
    """The consistent points (``_consistent``'s options) within ``observe_radius`` of the adopted
    tool point ``anchor`` in H, nearest first: a change of the held tool moves only the tool's
    points (a point of the gripper stays where the model puts it after the tool slipped)."""
    near = [(float(np.linalg.norm(o[2] - anchor)), o) for o in options]
    return [o for d, o in sorted(near, key=lambda n: n[0]) if d <= params.observe_radius]


def _choose_witness(bank, params, row, usable, x, frame, anchor) -> CandidateBank:
    options = _consistent(bank, params, row, usable, x, frame, exclude=(bank.observed, bank.leader),
                          verified=True)  # fmt: skip
    options = _near_tool(options, anchor, params)
    if not options:
        return replace(bank, witness=-1, witness_p_HP=None, witness_last=None)
    _, feature_id, p_HP, _ = options[0]
    return replace(bank, witness=feature_id, witness_p_HP=p_HP, witness_last=None)


def _reacquire(bank, params, X_WH, ids, p_CP, usable, body, row, x, anchor) -> CandidateBank:
    """A new observed point: a body feature where ``x`` puts the observed point (a new track of
    the same point), else the consistent candidate nearest to it in H (with its own ``p_HP``),
    else none."""
    near = np.flatnonzero(usable & body)
    if near.size:
        distance = np.linalg.norm(p_CP[near] - predicted_p_CP(x, X_WH), axis=1)
        best = int(np.argmin(distance))
        if distance[best] <= params.reacquire_radius:
            k = int(near[best])
            bank = replace(bank, observed=int(ids[k]), observed_last=(p_CP[k].copy(), X_WH))
            if bank.observed == bank.witness:
                bank = replace(bank, witness=-1, witness_p_HP=None, witness_last=None)
            return bank
    options = _consistent(bank, params, row, usable, x, (p_CP, X_WH), exclude=(bank.observed,), verified=True)
    # The consistent point nearest in H to the adopted tool point: the observation stays on the
    # tool (a chain of hand-overs must not drift onto the hand, which does not see the tool slip).
    options = _near_tool(options, anchor, params)
    if not options:
        return replace(bank, observed=-1, observed_last=None)
    _, feature_id, p_HP, k = options[0]
    witness = (dict(witness=-1, witness_p_HP=None, witness_last=None) if feature_id == bank.witness else {})
    return replace(bank, observed=feature_id, observed_p_HP=p_HP, observed_last=(p_CP[k].copy(), X_WH),
                   **witness)


def rotation_spread(statistic: np.ndarray) -> float:
    """How much the hand turned over a candidate's samples, rad (about the RMS angle from the mean
    orientation): ``sqrt((3 - ||mean R_WH||_F^2) / 2)``, from the statistic alone
    (``S[9:12, 12:15] = -sum R_WH``). Zero when the hand only translated."""
    n = EyeToHandIdentifier().core.num_unknowns
    S = np.asarray(statistic, dtype=float)[: n * n].reshape(n, n)
    count = S[9, 9]
    if count <= 0:
        return 0.0
    M = -S[9:12, 12:15] / count
    return math.sqrt(max(3.0 - float(np.sum(M * M)), 0.0) / 2.0)


def mean_squared_error_of(statistic: np.ndarray, x: np.ndarray) -> float:
    """``x^T C x`` (Eq. (3)): the mean of ``s_t`` over the samples behind ``statistic``, m^2."""
    identifier = EyeToHandIdentifier()
    identifier.set_state(statistic)
    return identifier.core.mean_squared_error(x)


@dataclass(frozen=True)
class BankSummary:
    """A small view of the bank for outputs and logs."""

    num_candidates: int
    leader: int
    observed: int
    feature_ids: tuple = field(default_factory=tuple)


def summary(bank: CandidateBank) -> BankSummary:
    return BankSummary(len(bank.candidates), bank.leader, bank.observed,
                       tuple(c.feature_id for c in bank.candidates))


def best_p_HP_given_camera(statistic: np.ndarray, R_WC: np.ndarray, p_WC: np.ndarray) -> np.ndarray:
    """The tracked point in H that best explains a candidate's samples when the camera pose is
    known (least squares from the statistic alone: ``x^T S x`` is quadratic in ``p_HP``).

    Used for evaluation: with the true camera pose it gives the true position of the image
    feature the identifier tracked (a corner on a silhouette is not a fixed mark on the tool)."""
    n = EyeToHandIdentifier().core.num_unknowns
    S = np.asarray(statistic, dtype=float)[: n * n].reshape(n, n)
    x = np.concatenate([np.asarray(R_WC).reshape(9, order="F"), p_WC, np.zeros(3), [1.0]])
    H = S[12:15, 12:15]
    g = S[12:15, :] @ x
    return -np.linalg.lstsq(H, g, rcond=None)[0]


def own_fit(statistic: np.ndarray, R_WC: np.ndarray, p_WC: np.ndarray) -> tuple[np.ndarray, float]:
    """A point's own fit under a camera: its best ``p_HP`` (``best_p_HP_given_camera``) and the mean
    squared error (m^2) of its samples with it."""
    p_HP = best_p_HP_given_camera(statistic, R_WC, p_WC)
    return p_HP, mean_squared_error_of(statistic, pack_x(R_WC, p_WC, p_HP))
