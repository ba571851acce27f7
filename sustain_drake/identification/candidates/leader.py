"""The leader (paper Fig. 7): the first candidate whose verdict says converged (the smallest expected
error if several converge on the same frame) is the leader until the next reset; its solution is refined
(Gauss-Newton) and it is what a ``CoordinationStateMachine`` adopts. Beyond the paper: a second point
must confirm its camera (``confirm_with_witness``), the camera may be refined jointly with every point
it explains (``joint``, ``refine_interval``), and a leader whose views do not pin the camera's rotation
(``min_rotation_lever``, ``min_adopt_rotation_spread``) or whose camera's 95 % region exceeds the
accuracy asked for (``camera_accuracy``) waits for more motion. With no leader, the
recoveries after a slip and after a camera move may choose one, and with none converged, the
consensus of the tracks since the reset (``track_consensus``: tracks that end before any converges)."""

from dataclasses import replace

import numpy as np

from sustain_drake.identification.candidates import camera_move_recovery, slip_recovery, track_consensus
from sustain_drake.identification.candidates.admission import solve
from sustain_drake.identification.candidates.bank import Adoption, Candidate, CandidateBank
from sustain_drake.identification.candidates.fitting import (
    FIRST_CHOICE_POINTS,
    best_p_HP_given_camera,
    independent_of,
    joint_camera_sd,
    joint_refined,
    mean_squared_error_of,
    on_parent_link,
    rotation_spread,
    smallest_rotation_lever,
    within_accuracy,
)
from sustain_drake.identification.candidates.frame import Pool, SeenFrame
from sustain_drake.identification.candidates.observation import consistent, witnessed_by
from sustain_drake.identification.candidates.params import CandidateParams
from sustain_drake.identification.eye_to_hand import EyeToHandEstimate, pack_x
from sustain_drake.identification.sustainable_identifier import ConvergenceCriteria, Verdict

# s: a held-back leader's point missing this long is gone, not a flicker of the refiner (a saddle
# missed for 1-3 frames at 30 Hz; adopting on those took levers of 9 mm, not 15).
_HELD_UNSEEN_TIME = 0.3


def choose(bank: CandidateBank, params: CandidateParams, criteria: ConvergenceCriteria, seen: SeenFrame,
           pool: Pool) -> tuple[Pool, bool, int]:  # fmt: skip
    """The leader chosen among the pool's candidates when there is none: ``(pool, more_motion, the
    id of the candidate held back or -1)``, the pool with the leader, its adoption and its
    ``adopted_mse`` (unchanged when none leads)."""
    held_back, best = False, None
    # min_rotation_lever: the leader held back on an earlier frame waits for views only while its
    # point is seen; once it is not (its face turned away, its track ended: a tool's converged
    # points can all leave view within a second), the views it waited for are over and it is
    # adopted as it is.
    held = (next((c for c in pool.kept + pool.archive if c.feature_id == bank.held_back), None)
            if pool.leader < 0 and bank.held_back >= 0 else None)  # fmt: skip
    unseen = held is not None and (seen.row.get(held.feature_id) is None
                                   or seen.time - held.last_sample > _HELD_UNSEEN_TIME)
    adopt_held = unseen and held.solution.verdict.converged
    if adopt_held and all(c.feature_id != held.feature_id for c in pool.kept):  # its track ended:
        # from the archive
        pool = replace(pool, archive=[c for c in pool.archive if c.feature_id != held.feature_id],
                       kept=pool.kept + [held])
    # The first to converge leads (the smallest expected error among simultaneous ones). A leader
    # held back on an earlier frame is judged again only when a candidate gained a sample: else
    # the statistics, and so its lever, are as they were.
    converged = ([] if pool.leader >= 0 or (bank.held_back >= 0 and not pool.fed and not adopt_held)
                 else [c for c in pool.kept if c.solution.verdict.converged])
    # Precise points first: while a centrally symmetric point is a candidate that converges in time,
    # only such a point leads. A point anchored on its patch (a second choice) carries a
    # view-dependent bias of a tenth of a pixel or more on fine print, which the fit's noise cannot
    # show.
    if any(c.symmetric for c in converged) or _corner_in_time(converged, pool.kept, seen.time):
        converged = [c for c in converged if c.symmetric]
    forgetting_factor = seen.given.forgetting_factor
    if converged:
        if adopt_held:
            best = solve(held, criteria, forgetting_factor, refine=True)
            confirmed = True  # when it was held back
        else:
            best = min(converged, key=lambda c: c.solution.expected_mse)
            best = solve(best, criteria, forgetting_factor, refine=True)
            confirmed = _confirmed(best, pool, params, seen)
        if best.solution.verdict.converged and confirmed:
            pool, held_back = _adopt(best, params, seen, pool, unseen)
    elif pool.leader < 0 and params.keep_camera and bank.previous_x is not None:
        pool = slip_recovery.recover(bank, params, seen, pool)
    elif pool.leader < 0 and bank.known_points:
        pool = camera_move_recovery.recover(bank, params, seen, pool)
    if pool.leader < 0 and not converged and params.joint and track_consensus.due(bank.last_frame, seen.time):
        pool = track_consensus.recover(params, criteria, seen, pool)
    # Once a leader was held back (min_rotation_lever, min_adopt_rotation_spread), more motion is wanted
    # until one leads or no converged candidate is left (then the detector's trials must find new body
    # features).
    # An anchored point (the second choice) asks for it only where the frame shows fewer than two
    # symmetric points at all: on a tool with a checker its samples come before the detector's
    # confirming trials have flagged the corners, and the identifying motion's postures would cut
    # those trials short.
    few_corners = int(np.count_nonzero(seen.symmetric)) < FIRST_CHOICE_POINTS
    first_point = params.motion_min_samples > 0 and not pool.adoptions and any(
        (c.symmetric or few_corners) and c.solution.num_samples >= params.motion_min_samples
        for c in pool.kept)
    more_motion = pool.leader < 0 and (held_back or first_point or (bank.more_motion and any(
        c.solution.verdict.converged for c in pool.kept)))
    held_id = (best.feature_id if held_back
               else bank.held_back if pool.leader < 0 and held is not None and not unseen else -1)
    return pool, more_motion, held_id


def _corner_in_time(converged: list, kept: list, time: float) -> bool:
    """Whether a centrally symmetric candidate, sampled as it has been since its admission, gathers
    as many samples as the fastest-sampled converged candidate has within the time that one took
    (so it converges about as soon again). A corner seen only at a few poses (a sticker's print on
    a wooden handle: 6 samples a second against 30) would hold the converged points back for tens
    of seconds; one sampled like them is worth waiting for."""
    def age(c: Candidate) -> float:
        return max(time - c.admitted, 1e-9)

    if not converged:
        return False
    fastest = max(converged, key=lambda c: c.solution.num_samples / age(c))
    return any(c.symmetric and fastest.solution.num_samples - c.solution.num_samples
               <= c.solution.num_samples / age(c) * age(fastest) for c in kept)


def _adopt(best: Candidate, params: CandidateParams, seen: SeenFrame, pool: Pool,
           unseen: bool) -> tuple[Pool, bool]:  # fmt: skip
    """The converged, confirmed candidate ``best`` as the leader (its camera refined jointly with
    ``joint``), unless its points' views do not pin the camera's rotation: ``(pool, held back)``."""
    estimate = best.solution.estimate
    kind, statistics = "identified", [best.statistic]
    independent = None if estimate is None else independent_of([best], estimate.R_WC, estimate.p_WC, params)
    if params.joint:
        best, statistics, independent = joint_refined(best, pool.kept, pool.archive, params)
        if len(statistics) > 1:
            kind = f"identified, camera refined with {len(statistics)} points"
    lever = smallest_rotation_lever(statistics, best.solution.estimate)
    # min_rotation_lever, min_adopt_rotation_spread: the points' views must pin the
    # camera's rotation too.
    spread = rotation_spread(best.statistic)
    held_back = (lever < params.min_rotation_lever
                 or spread < params.min_adopt_rotation_spread) and not unseen
    # camera_accuracy: the camera's own 95 % region must lie within the accuracy asked for (not
    # computed for a leader already held back). A point no longer seen gives no more views: it is
    # not adopted, and no longer held.
    sd = None if held_back else joint_camera_sd(statistics, best.solution.estimate, params, independent)
    wide = not held_back and not within_accuracy(sd, params)
    if held_back or wide:
        return pool, not unseen
    kept = [best if c.feature_id == best.feature_id else c for c in pool.kept]
    leader = best.feature_id
    adoptions = pool.adoptions + (Adoption(float(seen.time), leader, best.statistic.copy(),
                                           best.admitted, pool.round_start, best.solution.estimate,
                                           kind, lever, sd),)
    return replace(pool, kept=kept, leader=leader, adopted_mse=best.solution.expected_mse,
                   adoptions=adoptions), False


def _confirmed(c: Candidate, pool: Pool, params: CandidateParams, seen: SeenFrame) -> bool:
    """Whether another candidate's samples agree with ``c``'s camera (with their own ``p_HP``),
    when ``params.confirm_with_witness`` asks for it: two points of the hand must tell the same
    camera pose before it is adopted. The witness is a point tracked now (``consistent``: its
    samples and this frame's point), else one whose track ended since the reset (``pool.archive``):
    its samples are as much a second view of the camera, and a tool's points leave view within
    seconds, so a converged point can outlive every other track by tens of seconds. An archived
    witness must fit the hand better than its parent link (``fitting.on_parent_link``): points on
    the wrist agree on a wrong camera among themselves."""
    if not params.confirm_with_witness:
        return True
    probe = CandidateBank(candidates=tuple(pool.kept), leader=c.feature_id,
                          adopted_mse=c.solution.expected_mse)
    if consistent(probe, params, seen, c.solution.x, exclude=(c.feature_id,)):
        return True
    return any(o.feature_id != c.feature_id and o.on_hand is not False
               and witnessed_by(o, params, c.solution.x, c.solution.expected_mse) and not on_parent_link(o)
               for o in pool.archive)


def refine_adopted(bank: CandidateBank, params: CandidateParams, reference_x, time: float) -> CandidateBank:
    """``refine_interval``: the adopted camera refined jointly with the leader and every candidate
    it explains (``joint_refined`` from the adopted camera), offered as a converged solution with
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
    refined, statistics, _ = joint_refined(seed, bank.candidates, bank.archive, params)
    num_points = len(statistics)
    if num_points < 2:
        return bank
    estimate = refined.solution.estimate
    verdict = Verdict(True, f"the adopted model refined jointly with {num_points - 1} other points")
    solution = replace(refined.solution, expected_mse=estimate.mean_squared_error, verdict=verdict,
                       refinement=bank.refinement + 1)
    return replace(bank, refined_solution=solution, refinement=bank.refinement + 1)
