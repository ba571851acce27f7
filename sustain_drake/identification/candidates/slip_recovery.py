"""Recovery after a slip (beyond the paper, ``keep_camera``): a slipped tool leaves the camera where it
was, so after a reset that was not a camera move, a candidate that the abandoned model's camera explains
leads at once with that camera; only its ``p_HP`` (3 unknowns) is identified again.

That the camera stayed is known one of two ways: the static scene shows it unmoved since before the
reset (a ``CameraMotionDetector``'s ``scene_still_since``: still frames, joined across gaps its
reference shows no move in), or the samples since the reset show it themselves. A camera move
the detector missed (too few static anchors, a slow turn) resets the model like a slip; a point's own
``p_HP`` then absorbs much of the camera's error (a turn ``d`` shifts the point by about ``z d`` across
the view, which hand turns about that shift's axis leave unseen), so its fit alone does not tell the
cases apart. The points that fit the previous camera must then pin a camera of their own to the
accuracy asked for (``camera_accuracy``, ``camera_rotation_accuracy``: the joint fit's 95 % region)
and place it within that accuracy of the previous one."""

import math
from dataclasses import replace

import numpy as np

from sustain_drake.identification.candidates.bank import Adoption, Candidate, CandidateBank, with_camera
from sustain_drake.identification.candidates.fitting import joint_camera_sd, joint_refined, within_accuracy
from sustain_drake.identification.candidates.frame import Pool, SeenFrame
from sustain_drake.identification.candidates.observation import consistent
from sustain_drake.identification.candidates.params import CandidateParams
from sustain_drake.identification.rotation import nearest_rotation, rotation_angle


def recover(bank: CandidateBank, params: CandidateParams, seen: SeenFrame, pool: Pool) -> Pool:
    """With no leader and the abandoned model's camera (``bank.previous_x``): the candidate it
    explains best (``consistent``, with ``keep_camera_min_samples`` samples when the static scene
    stayed still since before the reset, else ``observe_min_samples`` and ``views_confirm``) leads
    with that camera and its own ``p_HP``. The pool unchanged when none fits."""
    kept = pool.kept
    scene_still = seen.given.scene_still_since <= bank.reset_time
    options = consistent(replace(bank, candidates=tuple(kept)), params, seen, bank.previous_x, min_samples=(
        params.keep_camera_min_samples if scene_still else params.observe_min_samples))
    if not options:
        return pool
    mse, leader, p_HP, _ = min(options, key=lambda o: o[0])
    best = next(c for c in kept if c.feature_id == leader)
    # Its expected error sets the allowable error (Eq. (2)'s sigma); with
    # keep_allowable_error, at most that of the identification whose camera is kept.
    expected = min(mse, bank.adopted_mse) if params.keep_allowable_error else mse
    best = with_camera(best, bank.previous_x, p_HP, expected)
    if not scene_still and not views_confirm(best, pool, params):
        return pool
    kept = [best if c.feature_id == leader else c for c in kept]
    adoptions = pool.adoptions + (Adoption(float(seen.time), leader, best.statistic.copy(),
                                           best.admitted, pool.round_start, best.solution.estimate,
                                           "previous camera"),)
    return replace(pool, kept=kept, leader=leader, adoptions=adoptions)


def views_confirm(best: Candidate, pool: Pool, params: CandidateParams) -> bool:
    """Whether the samples since the reset confirm the previous camera (``best``'s, with its own
    ``p_HP``): refined jointly with every candidate that fits it (``fitting.joint_refined``), the
    camera's 95 % region lies within ``camera_accuracy`` and ``camera_rotation_accuracy``
    (``fitting.within_accuracy``) and the refined camera within both of the previous one. True
    when both accuracies are off (inf): the fit alone decides, as with a still scene."""
    if math.isinf(params.camera_accuracy) and math.isinf(params.camera_rotation_accuracy):
        return True
    previous = best.solution.estimate
    refined, statistics, independent = joint_refined(best, pool.kept, pool.archive, params)
    estimate = refined.solution.estimate
    if not within_accuracy(joint_camera_sd(statistics, estimate, params, independent), params):
        return False
    turn = rotation_angle(nearest_rotation(previous.R_WC.T @ estimate.R_WC))
    return bool(np.linalg.norm(estimate.p_WC - previous.p_WC) <= params.camera_accuracy
                and turn <= params.camera_rotation_accuracy)
