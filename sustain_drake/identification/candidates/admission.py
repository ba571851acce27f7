"""Admission, feeding and loss of the candidates on a new frame (paper Fig. 7).

- admission: body features with a valid 3-D point become candidates, oldest track first, at most
  ``max_candidates`` at a time (a bounded cost per frame);
- feeding: each frame, each candidate's identifier gets the feature's ``p_CP`` and the hand pose
  ``X_WH`` at the frame's capture time;
- a motion gate: a point fixed within ``max_hand_radius`` of the hand origin cannot move in the
  camera frame (a fixed camera) by more than the hand's translation plus its rotation angle times
  that radius; a sample that does (a depth value taken from the background at a silhouette, a
  track that jumped) is skipped;
- loss: a feature no longer tracked (the tracker never reuses an id) or without a valid depth
  (occluded) stops feeding its identifier; after ``max_lost_time`` s without a sample its slot is
  freed; a candidate still not converged after ``max_unconverged_time`` s is rejected (another
  link, a sliding silhouette corner) and its slot freed;
- another link: with the parent link's pose known, a candidate whose samples, when it first
  converges, fit that link better than the hand (``fitting.on_parent_link``) is rejected.
"""

import math
from dataclasses import replace

import numpy as np

from sustain_drake.identification.candidates.bank import Candidate, CandidateBank
from sustain_drake.identification.candidates.camera_move_recovery import near_known_points
from sustain_drake.identification.candidates.fitting import (
    FIRST_CHOICE_POINTS,
    best_p_HP_given_camera,
    explained,
    on_parent_link,
    predicted_p_CP,
    rotation_spread,
    sample_error,
    x_is_set,
)
from sustain_drake.identification.candidates.frame import Pool, SeenFrame
from sustain_drake.identification.candidates.params import CandidateParams
from sustain_drake.identification.eye_to_hand import EyeToHandIdentifier, pack_x
from sustain_drake.identification.rotation import rotation_angle
from sustain_drake.identification.sustainable_identifier import ConvergenceCriteria
from sustain_drake.identification.view_correlation import _view_row


def gather(bank: CandidateBank, params: CandidateParams, criteria: ConvergenceCriteria,
           seen: SeenFrame) -> Pool:  # fmt: skip
    """The bank's candidates fed, lost or rejected on the new frame ``seen``, then new ones admitted
    (no leader chosen yet: ``Pool.leader`` is the bank's)."""
    rejected = frozenset(i for i in bank.rejected if i in seen.row)
    # Candidates are fed while searching: before a leader exists, or when the observed point is
    # lost (a new point to observe). Otherwise the leader alone keeps feeding, the others are frozen.
    # With observers (``max_observers``), candidates keep being found and fed while observing, so
    # that fresh points consistent with the adopted model are at hand when observed points are lost.
    searching = bank.leader < 0 or bank.observed < 0 or params.max_observers > 0
    observing = bank.leader >= 0 and params.max_observers > 0 and x_is_set(seen.given.reference_x)
    kept, archive, rejected, fed = _feed_tracked(bank, params, criteria, seen, searching, observing, rejected)
    round_start = bank.round_start
    if searching:
        kept, admitted, round_start = _admit_new(bank, params, criteria, seen, kept, rejected, observing)
        fed = fed or admitted
    return Pool(kept, _archived(archive, params), rejected, fed, round_start, bank.leader, bank.adoptions,
                bank.adopted_mse)


def _feed_tracked(bank, params, criteria, seen: SeenFrame, searching: bool, observing: bool,
                  rejected: frozenset) -> tuple[list, list, frozenset, bool]:  # fmt: skip
    """Each candidate fed (while searching, or the leader, or one the adopted model explains with
    ``refine_interval``), archived when lost, or rejected: ``(kept, archive, rejected, fed)``."""
    row, usable, p_CP, X_frame, frame_time = seen.row, seen.usable, seen.p_CP, seen.X_WH, seen.time
    reference_x = seen.given.reference_x
    kept, fed, archive = [], False, list(bank.archive)
    for c in bank.candidates:
        k = row.get(c.feature_id)
        is_leader = c.feature_id == bank.leader
        if k is None and not is_leader:
            archive.append(c)  # no longer tracked: gone for good (ids are never reused)
            continue
        learning = (not searching and params.refine_interval > 0 and k is not None and usable[k]
                    and _fits(c, p_CP[k], X_frame, reference_x, seen.given.allowable_error))
        if k is not None and usable[k] and (searching or is_leader or learning):
            num = c.solution.num_samples
            c = feed(c, params, criteria, frame_time, p_CP[k], X_frame, seen.given.forgetting_factor,
                     refine=is_leader, X_WL=seen.X_WL)
            fed = fed or c.solution.num_samples > num
        if searching and not is_leader:
            if frame_time - c.last_sample > params.max_lost_time:
                archive.append(c)
                continue  # occluded too long: the slot is freed
            sol = c.solution
            too_long = frame_time - c.admitted > params.max_unconverged_time and not sol.verdict.converged
            misfit = sol.num_samples >= criteria.min_samples and not sol.expected_rms <= params.reject_rms
            # A point that the hand's parent link explains better is fixed on that link: judged
            # once, when it first converges (two Gauss-Newton fits, a few ms).
            if sol.verdict.converged and c.on_hand is None and c.parent_statistic is not None:
                c = replace(c, on_hand=not on_parent_link(c))
            misfit = misfit or c.on_hand is False
            # While observing (with observers), a point the adopted camera does not explain is not
            # of the hand (or not any more): its slot goes to a new point.
            misfit = misfit or (observing and c.frames >= params.observe_min_samples
                                and rotation_spread(c.statistic) >= params.min_rotation_spread
                                and not explained(c, reference_x, bank.adopted_mse, params))
            if too_long or misfit:
                rejected = rejected | {c.feature_id}
                if too_long and not misfit:
                    archive.append(c)  # slow, not wrong: its samples still constrain the camera
                continue
        kept.append(c)
    return kept, archive, rejected, fed


def _admit_new(bank, params, criteria, seen: SeenFrame, kept: list, rejected: frozenset,
               observing: bool) -> tuple[list, bool, float]:  # fmt: skip
    """New candidates admitted up to ``max_candidates``: ``(kept, whether any was, round_start)``."""
    ids, p_CP, usable, X_frame, frame_time = seen.ids, seen.p_CP, seen.usable, seen.X_WH, seen.time
    on_body, in_body_cell = seen.on_body, seen.in_body_cell
    kept, admitted, round_start = list(kept), False, bank.round_start
    present = {c.feature_id for c in kept}
    # Confirmed body features first, then features in body cells; oldest track first. While
    # observing (with observers), alternately the nearest to where the adopted model puts the
    # tool point (the tool's points) and the oldest (long tracks: often the hand's own).
    near_known = (near_known_points(bank, params, X_frame, p_CP, usable & seen.symmetric)
                  if params.turn_admit_known and bank.leader < 0 else np.zeros_like(on_body))
    order = np.lexsort((ids, ~on_body, ~seen.symmetric, ~near_known,
                        ~np.isin(ids, [i for i, _ in bank.known_points])))
    symmetric_only = _enough_symmetric(seen, near_known, rejected)
    if observing:
        tool_point = predicted_p_CP(np.asarray(seen.given.reference_x), X_frame)
        nearest = np.argsort(np.linalg.norm(p_CP - tool_point, axis=1))
        order = np.stack([nearest, order], axis=1).ravel()
    for k in order:
        if len(kept) >= params.max_candidates:
            break
        i = int(ids[k])
        if ((on_body[k] or in_body_cell[k] or near_known[k]) and usable[k] and i not in present
                and i not in rejected and (seen.symmetric[k] or not symmetric_only)):
            kept.append(admit(i, criteria, frame_time, p_CP[k], X_frame, bool(seen.symmetric[k]), seen.X_WL))
            present.add(i)
            admitted = True
            if math.isnan(round_start):
                round_start = float(frame_time)
    return kept, admitted, round_start


def _enough_symmetric(seen: SeenFrame, near_known: np.ndarray, rejected: frozenset) -> bool:
    """Whether the frame has ``FIRST_CHOICE_POINTS`` centrally symmetric body points not rejected
    (then only such points are admitted)."""
    first = seen.symmetric & (seen.body | near_known) & ~np.isin(seen.ids, list(rejected))
    return int(np.count_nonzero(first)) >= FIRST_CHOICE_POINTS


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


def _fits(c: Candidate, p_CP, X_WH, reference_x, allowable_error: float) -> bool:
    """Whether the adopted model (its camera, the candidate's own best ``p_HP``) explains this
    sample of the candidate within the allowable error."""
    if not (x_is_set(reference_x) and math.isfinite(allowable_error)) or c.solution.num_samples < 1:
        return False
    R_WC, p_WC = reference_x[0:9].reshape(3, 3, order="F"), reference_x[9:12]
    p_HP = best_p_HP_given_camera(c.statistic, R_WC, p_WC)
    return sample_error(p_CP, X_WH, pack_x(R_WC, p_WC, p_HP)) <= allowable_error


def _archived(archive: list, params: CandidateParams) -> list:
    """The archive bounded to ``max_archived`` candidates with enough samples, the most first."""
    if not params.joint:
        return []
    useful = [c for c in archive if c.solution.num_samples >= params.joint_min_samples]
    return sorted(useful, key=lambda c: -c.solution.num_samples)[: params.max_archived]


def admit(feature_id, criteria, time, p_CP, X_WH, symmetric: bool = False, X_WL=None) -> Candidate:
    """A new candidate, its identifier fed its first sample (and, with the parent link's pose
    ``X_WL``, its ``parent_statistic``)."""
    identifier = EyeToHandIdentifier(criteria=criteria)
    identifier.add(p_CP, X_WH[:3, :3], X_WH[:3, 3])
    return Candidate(feature_id, identifier.state, identifier.solve(refine_estimate=False), float(time),
                     float(time), np.array(p_CP), np.array(X_WH), sampled_p_CP=np.array(p_CP),
                     symmetric=symmetric, view_list=view_of(p_CP, X_WH)[None, :],
                     view_sums=_view_row(p_CP, X_WH[:3, :3], X_WH[:3, 3])[None, :],
                     parent_statistic=_with_sample(None, p_CP, X_WL))


def identifier_of(c: Candidate, criteria, forgetting_factor) -> EyeToHandIdentifier:
    """An identifier holding the candidate's statistic."""
    identifier = EyeToHandIdentifier(forgetting_factor, criteria)
    identifier.set_state(c.statistic)
    return identifier


def solve(c: Candidate, criteria, forgetting_factor, refine: bool) -> Candidate:
    solution = identifier_of(c, criteria, forgetting_factor).solve(refine_estimate=refine)
    return replace(c, solution=solution)


def _with_sample(statistic, p_CP, X_WL, forgetting_factor: float = 1.0):
    """``Candidate.parent_statistic`` with the sample ``p_CP`` at the parent link's pose ``X_WL``
    (None when that pose is not known; from a first sample when ``statistic`` is None), forgotten
    as the candidate's own statistic is."""
    if X_WL is None:
        return None
    identifier = EyeToHandIdentifier(forgetting_factor)
    if statistic is not None:
        identifier.set_state(statistic)
    identifier.add(p_CP, X_WL[:3, :3], X_WL[:3, 3])
    return identifier.state


def feed(c: Candidate, params, criteria, time, p_CP, X_WH, forgetting_factor, refine, X_WL=None) -> Candidate:
    """The candidate given this frame's point: skipped outside the motion gate, held (not lost) when
    seen where it was (``min_view_change``), else one sample more (in ``parent_statistic`` too, at
    the parent link's pose ``X_WL``, while it is known from the admission on)."""
    gated = within_motion_gate(c.last_p_CP, c.last_X_WH, p_CP, X_WH, params)
    c = replace(c, last_p_CP=np.array(p_CP), last_X_WH=np.array(X_WH))
    if not gated:
        return c
    c = replace(c, frames=c.frames + 1)
    if not _new_view(c, p_CP, params):
        return replace(c, last_sample=float(time))  # seen where it was: held, not lost
    identifier = identifier_of(c, criteria, forgetting_factor)
    identifier.add(p_CP, X_WH[:3, :3], X_WH[:3, 3])
    c = _with_view(c, p_CP, X_WH, params)
    parent = (None if c.parent_statistic is None
              else _with_sample(c.parent_statistic, p_CP, X_WL, forgetting_factor))
    return replace(c, statistic=identifier.state, parent_statistic=parent, last_sample=float(time),
                   sampled_p_CP=np.array(p_CP), solution=identifier.solve(refine_estimate=refine))


def _with_view(c: Candidate, p_CP, X_WH, params: CandidateParams) -> Candidate:
    """``view_angle``: the candidate with this sample in its views (``Candidate.view_list``,
    ``view_sums``): a new view when it lies at least that far from each of them, else added to the
    nearest (0: not kept, every sample counts as its own view)."""
    if params.view_angle <= 0:
        return c
    views, sums = with_view(c.view_list, c.view_sums, p_CP, X_WH, params.view_angle)
    return replace(c, view_list=views, view_sums=sums)


def with_view(views: np.ndarray, sums: np.ndarray, p_CP, X_WH, view_angle: float):
    """A point's views (V x 12, ``view_of``) and their sums (V x 16, ``view_correlation.view_row``)
    with one more sample: a new view when it lies at least ``view_angle`` (rad) from each, else
    added to the nearest. New arrays; the inputs are left as they were."""
    view, row = view_of(p_CP, X_WH), _view_row(p_CP, X_WH[:3, :3], X_WH[:3, 3])
    distances = view_distance(views, view) if len(views) else np.zeros(0)
    if not len(distances) or distances.min() >= view_angle:
        return np.vstack([views, view]), np.vstack([sums, row])
    sums = sums.copy()
    sums[int(np.argmin(distances))] += row
    return views, sums


def view_of(p_CP, X_WH) -> np.ndarray:
    """A sample's view (12): the hand's orientation ``R_WH`` (column-major) and the point's
    direction from the camera (the unit ray in C). With the camera fixed these say how the camera
    sees the point's patch: its face's angle, its turn in the image, its place in the image."""
    p, R_WH = np.asarray(p_CP, dtype=float), np.asarray(X_WH, dtype=float)[:3, :3]
    return np.concatenate([R_WH.reshape(9, order="F"), p / np.linalg.norm(p)])


def view_distance(views: np.ndarray, view: np.ndarray) -> np.ndarray:
    """rad from each of ``views`` (V x 12) to ``view`` (``view_of``; or V x 12, pairwise): the hand's
    turn between them plus the angle between the rays, an upper bound of how far the camera's line
    of sight moved over the patch."""
    cosines = (np.sum(views[..., :9] * view[..., :9], axis=-1) - 1.0) / 2.0  # tr(R_a^T R_b) = 1 + 2 cos
    rays = np.sum(views[..., 9:] * view[..., 9:], axis=-1)
    return np.arccos(np.clip(cosines, -1.0, 1.0)) + np.arccos(np.clip(rays, -1.0, 1.0))


def _new_view(c: Candidate, p_CP, params: CandidateParams) -> bool:
    """``min_view_change``: whether the point moved at least that far in the camera frame since its
    last sample. A point's errors repeat with its view (the same pose of the tool, the same error),
    so a view held for a second is one error counted thirty times: Eq. (1)'s sum then weighs the
    views by how long the arm held them (the detector's trials and the pause after a convergence
    hold it), and the camera leans towards the few held views."""
    return (params.min_view_change <= 0 or c.sampled_p_CP is None
            or float(np.linalg.norm(np.asarray(p_CP) - c.sampled_p_CP)) >= params.min_view_change)
