"""Recovery after a slip (beyond the paper, ``keep_camera``): a slipped tool leaves the camera where it
was, so after a reset that was not a camera move, a candidate that the abandoned model's camera explains
leads at once with that camera; only its ``p_HP`` (3 unknowns) is identified again."""

from dataclasses import replace

from sustain_drake.identification.candidates.bank import Adoption, CandidateBank, with_camera
from sustain_drake.identification.candidates.frame import Pool, SeenFrame
from sustain_drake.identification.candidates.observation import consistent
from sustain_drake.identification.candidates.params import CandidateParams


def recover(bank: CandidateBank, params: CandidateParams, seen: SeenFrame, pool: Pool) -> Pool:
    """With no leader and the abandoned model's camera (``bank.previous_x``): the candidate it
    explains best (``consistent``, with ``keep_camera_min_samples`` samples when the static scene
    stayed still since before the reset, else ``observe_min_samples``) leads with that camera and
    its own ``p_HP``. The pool unchanged when none fits."""
    kept = pool.kept
    # A slipped tool leaves the camera where it was: if the abandoned model's camera
    # explains a candidate's samples (with its own p_HP), only p_HP is re-identified.
    options = consistent(replace(bank, candidates=tuple(kept)), params, seen, bank.previous_x, min_samples=(
        params.keep_camera_min_samples if seen.given.scene_still_since <= bank.reset_time
        else params.observe_min_samples))
    if not options:
        return pool
    mse, leader, p_HP, _ = min(options, key=lambda o: o[0])
    best = next(c for c in kept if c.feature_id == leader)
    # Its expected error sets the allowable error (Eq. (2)'s sigma); with
    # keep_allowable_error, at most that of the identification whose camera is kept.
    expected = min(mse, bank.adopted_mse) if params.keep_allowable_error else mse
    best = with_camera(best, bank.previous_x, p_HP, expected)
    kept = [best if c.feature_id == leader else c for c in kept]
    adoptions = pool.adoptions + (Adoption(float(seen.time), leader, best.statistic.copy(),
                                           best.admitted, pool.round_start, best.solution.estimate,
                                           "previous camera"),)
    return replace(pool, kept=kept, leader=leader, adoptions=adoptions)
