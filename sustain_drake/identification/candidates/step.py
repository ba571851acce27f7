"""The per-frame tick of the candidates (paper Fig. 7): the reset, the hand pose, then, on a new frame,
admission, feeding, loss, the leader and the observation."""

import math
from dataclasses import replace

import numpy as np

from sustain_drake.identification.candidates.admission import gather
from sustain_drake.identification.candidates.bank import (
    CandidateBank,
    ClearedModel,
    mark_verified,
    poses_at,
    record_pose,
)
from sustain_drake.identification.candidates.camera_move_recovery import model_points, with_scene_turn
from sustain_drake.identification.candidates.fitting import x_is_set
from sustain_drake.identification.candidates.frame import FrameInput, SeenFrame
from sustain_drake.identification.candidates.leader import choose, refine_adopted
from sustain_drake.identification.candidates.observation import observe
from sustain_drake.identification.candidates.params import CandidateParams
from sustain_drake.identification.coordination import CAMERA_MOVED
from sustain_drake.identification.sustainable_identifier import ConvergenceCriteria


def step(bank: CandidateBank, params: CandidateParams, criteria: ConvergenceCriteria,
         frame: FrameInput) -> CandidateBank:  # fmt: skip
    """One tick at ``frame.time``: the reset, the hand pose, then (on a new frame) admission, feeding,
    loss, the leader and the observation. Returns the new bank."""
    if frame.reset != bank.last_reset:
        bank = _after_reset(bank, params, frame)
    elif frame.reset_reason == CAMERA_MOVED and bank.last_reason != CAMERA_MOVED:
        bank = _found_camera_move(bank, params, frame)
    bank = record_pose(bank, frame.time, frame.X_WH, frame.X_WL)
    bank = with_scene_turn(bank, frame.scene_turn)
    reference_x = frame.reference_x
    if bank.leader >= 0 and x_is_set(reference_x):
        bank = replace(bank, model_x=np.array(reference_x, dtype=float))
    if not frame.frame_time > bank.last_frame:
        return bank  # no new frame (or none yet)
    found = poses_at(bank, frame.frame_time, params.pose_tolerance)
    if found is None:
        return replace(bank, last_frame=float(frame.frame_time))  # no pose for that frame: skip it
    seen = SeenFrame.of(frame, found[0], params, found[1])
    pool = gather(bank, params, criteria, seen)
    pool, more_motion, held_id = choose(bank, params, criteria, seen, pool)
    leader, frame_time = pool.leader, seen.time
    # Before a leader, a frame that fed any identifier counts as a sample (the state machine
    # checks a solution's samples against the count since a reset); after, observations count.
    count = bank.sample_count + (1 if pool.fed and bank.leader < 0 else 0)
    new_leader = leader != bank.leader
    bank = replace(bank, candidates=tuple(pool.kept), leader=leader, rejected=pool.rejected,
                   round_start=pool.round_start, sample_count=count, archive=tuple(pool.archive),
                   first_found=pool.round_start if math.isnan(bank.first_found) else bank.first_found,
                   last_frame=float(frame_time), adoptions=pool.adoptions,
                   observed=bank.observed if leader == bank.leader else leader,
                   observed_last=bank.observed_last if leader == bank.leader else None,
                   observed_p_HP=bank.observed_p_HP if leader == bank.leader else None,
                   witness=bank.witness if leader == bank.leader else -1,
                   adopted_mse=pool.adopted_mse, more_motion=more_motion, held_back=held_id)
    if new_leader:
        bank = replace(bank, refined_solution=None, last_refinement=float(frame_time))
        if leader >= 0:
            bank = mark_verified(bank)  # the candidates the new model was identified among
    elif (leader >= 0 and params.refine_interval > 0 and x_is_set(reference_x)
          and frame_time - bank.last_refinement >= params.refine_interval):
        bank = refine_adopted(bank, params, reference_x, float(frame_time))
    return observe(bank, params, seen)


def _after_reset(bank: CandidateBank, params: CandidateParams, frame: FrameInput) -> CandidateBank:
    """A new reset value: every candidate dropped. The adopted model is kept as the previous camera
    (``keep_camera``) unless the camera moved; after a camera move, with ``keep_tool_points``, its
    points are kept with their ``p_HP`` (``known_points``). A camera move declared after another
    reset cleared the model, with no leader since, is that model's camera move (the tracks lost the
    move and the observation found it first: ``cleared``)."""
    time, reference_x = frame.time, frame.reference_x
    camera_moved = frame.reset_reason == CAMERA_MOVED
    previous = np.array(reference_x, dtype=float) if x_is_set(reference_x) and not camera_moved else None
    known = () if previous is not None else bank.known_points
    corners = frozenset() if previous is not None else bank.known_corners
    known_at = math.nan if previous is not None else bank.known_at
    # The camera before a move whose turn has not come yet: the resets that follow while the
    # camera still moves (no leader in between) keep it; one after the turn is a new change.
    moved = ((bank.moved_from_x, bank.moved_at, bank.moved_since) if bank.turn is None
             else (None, math.nan, -math.inf))
    has_model = params.keep_tool_points and bank.leader >= 0 and bank.model_x is not None
    cleared = None if camera_moved else bank.cleared
    if camera_moved and has_model:
        known, corners = model_points(bank, params), None  # the camera moved, the tool did not
        moved, known_at = (bank.model_x, float(time), bank.reset_time), float(time)
    elif camera_moved and params.keep_tool_points and bank.leader < 0 and bank.cleared is not None:
        known, corners, moved, known_at = _moved_from(bank.cleared, time)
    elif previous is not None or bank.leader >= 0:
        moved = (None, math.nan, -math.inf)
        if has_model:
            points = model_points(bank, params)
            cleared = ClearedModel(bank.model_x, points, _corners(bank, points), bank.reset_time, float(time))
    if corners is None:
        corners = _corners(bank, known)
    return replace(bank, candidates=(), leader=-1, observed=-1, rejected=frozenset(), previous_x=previous,
                   known_points=known, known_corners=corners, known_at=known_at, model_x=None,
                   moved_from_x=moved[0], moved_at=moved[1], moved_since=moved[2], cleared=cleared,
                   turn=None, turned_R_WC=None, turned_p_WC=None, turn_rotation_sd=math.inf,
                   reset_time=float(time), last_reset=float(frame.reset), last_reason=frame.reset_reason,
                   round_start=math.nan,
                   observed_last=None, observed_p_HP=None,
                   witness=-1, witness_p_HP=None, witness_last=None, primary_failures=0, archive=(),
                   observers=(), refined_solution=None, last_refinement=-math.inf, more_motion=False,
                   held_back=-1)


def _found_camera_move(bank: CandidateBank, params: CandidateParams, frame: FrameInput) -> CandidateBank:
    """The last reset found to be a camera move's (``coordination.step``'s ``camera_move_start``: the
    move was declared after the reset for it): the candidates since are of the moved camera and stay;
    the previous camera is dropped, and with ``keep_tool_points`` and no leader the model that reset
    cleared gives its points and its camera before the move, as a camera-move reset would
    (``_after_reset``)."""
    cleared = bank.cleared
    bank = replace(bank, previous_x=None, last_reason=frame.reset_reason, cleared=None)
    if not (params.keep_tool_points and bank.leader < 0 and cleared is not None):
        return bank
    known, corners, moved, known_at = _moved_from(cleared, frame.time)
    return replace(bank, known_points=known, known_corners=corners, known_at=known_at, moved_from_x=moved[0],
                   moved_at=moved[1], moved_since=moved[2], turn=None, turned_R_WC=None, turned_p_WC=None,
                   turn_rotation_sd=math.inf)


def _moved_from(cleared: ClearedModel, time: float) -> tuple:
    """``(known points, their corners, (camera before the move, now, since), known_at)``: what a
    camera move found after another reset takes from the model that reset cleared."""
    return cleared.points, cleared.corners, (cleared.x, float(time), cleared.since), cleared.at


def _corners(bank: CandidateBank, points: tuple) -> frozenset:
    """The ids among ``points`` of the bank's centrally symmetric candidates (tracked or archived)."""
    symmetric = {c.feature_id for c in (*bank.candidates, *bank.archive) if c.symmetric}
    return frozenset(i for i, _ in points if i in symmetric)
