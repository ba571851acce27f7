"""Identification from tracks that end before any converges (beyond the paper): a person walking
between the camera and the arm ends every track within seconds, so no point gathers the samples and
views the paper's rule needs on its own (``min_samples`` per point), and a high camera sees too
little of the static scene for a camera move to be declared and recovered from. The points tracked
since the reset, tracked or ended, share one camera: fitted together (``eye_to_hand_points.joint_tls``
then ``refine_joint``: 6 + 3K unknowns, no starting guess) they give it once all of them together
pin it (its 95 % region within ``camera_accuracy`` and ``camera_rotation_accuracy``).

What a short track cannot show is whether its point is fixed in H: a point of the forearm moves with
the hand while the wrist stands still, and over a few seconds of a track it fits a ``p_HP`` of its
own with a millimetre of error that a shared camera spreads over every point. So the camera is the
consensus of the points, not the fit of all of them: each group of tracks seen together
(``_cohorts``) proposes a camera, the points it explains within their limits (``_limits``: a
point's own error, the noise its statistic shows, capped at the members' median) are its inliers,
and a camera is adopted only when its inliers include tracks of different times (one group's
tracks share that group's motion; tracks of another time agree only on the true camera)."""

import math
from dataclasses import replace

import numpy as np

from sustain_drake.identification.candidates.bank import Adoption, with_camera
from sustain_drake.identification.candidates.fitting import (
    FIRST_CHOICE_POINTS,
    ROUND_OFF_MSE,
    S_of,
    camera_sd,
    independent_of,
    mean_squared_error_of,
    own_fit,
    rotation_spread,
    sd_within_targets,
)
from sustain_drake.identification.candidates.frame import Pool, SeenFrame
from sustain_drake.identification.candidates.params import CandidateParams
from sustain_drake.identification.eye_to_hand import pack_x
from sustain_drake.identification.eye_to_hand_points import joint_covariance, joint_tls, refine_joint
from sustain_drake.identification.sustainable_identifier import ConvergenceCriteria

KIND = "identified jointly from the tracks since the reset"

# s between consensus attempts: one costs 10-25 ms with 10-17 points, so about 4 % of a core while
# it is sought, and a camera waits at most this long for it
INTERVAL = 0.5


def due(last_frame: float, time: float) -> bool:
    """Whether a consensus is attempted on the frame at ``time`` (the previous one at ``last_frame``):
    on the first frame of each ``INTERVAL``."""
    return last_frame < INTERVAL * math.floor(time / INTERVAL)


def members_of(pool: Pool, params: CandidateParams) -> list:
    """The points that may join: tracked or ended since the reset, with ``observe_min_samples``
    samples over ``min_rotation_spread`` of hand rotation (else a point of any link fits) and a
    finite own error."""
    return [c for c in (*pool.kept, *pool.archive) if c.solution.num_samples >= params.observe_min_samples
            and math.isfinite(c.solution.expected_mse)
            and rotation_spread(c.statistic) >= params.min_rotation_spread]


def recover(params: CandidateParams, criteria: ConvergenceCriteria, seen: SeenFrame, pool: Pool) -> Pool:
    """With no leader and no candidate converged: a tracked inlier (the one with the most samples)
    leads with the consensus camera of the points since the reset and its own ``p_HP`` under it,
    once the inliers hold tracks of different times, ``criteria.min_samples`` samples in all, and
    pin the camera to the accuracy asked for. The pool unchanged otherwise."""
    members = members_of(pool, params)
    if len(members) < FIRST_CHOICE_POINTS or not _of_different_times(members):
        return pool
    found = consensus(members, params)
    if found is None:
        return pool
    # Precise points first (``fitting.first_choice``): the centrally symmetric inliers alone where
    # they are enough and agree.
    symmetric = [c for c in found[1] if c.symmetric]
    if len(symmetric) >= FIRST_CHOICE_POINTS and _of_different_times(symmetric):
        fit = _fit(symmetric, _limits(members, params))
        if fit is not None and len(fit[3]) == len(symmetric):
            found = fit[0:3], symmetric, fit[4]
    (R_WC, p_WC, P), inliers, errors = found
    ids = {c.feature_id for c in pool.kept}
    tracked = [k for k, c in enumerate(inliers) if c.feature_id in ids]
    if not tracked or sum(c.solution.num_samples for c in inliers) < criteria.min_samples:
        return pool
    sd = camera_sd(joint_covariance([S_of(c.statistic) for c in inliers], R_WC, p_WC, P,
                                    independent=independent_of(inliers, R_WC, p_WC, params)))
    if not sd_within_targets(sd, params):
        return pool
    k = max(tracked, key=lambda i: inliers[i].solution.num_samples)
    leader = inliers[k].feature_id
    x = pack_x(R_WC, p_WC, P[k])
    # Its error sets the allowable error; with keep_allowable_error, at most that of the model before.
    expected = min(float(errors[k]), pool.adopted_mse) if params.keep_allowable_error else float(errors[k])
    best = with_camera(inliers[k], x, P[k].copy(), expected,
                       f"converged: the camera identified jointly with {len(inliers)} points since the reset")
    kept = [best if c.feature_id == leader else c for c in pool.kept]
    adoptions = pool.adoptions + (Adoption(float(seen.time), leader, best.statistic.copy(), best.admitted,
                                           pool.round_start, best.solution.estimate, KIND,
                                           camera_sd=sd),)
    return replace(pool, kept=kept, leader=leader, adoptions=adoptions, adopted_mse=expected)


def consensus(members: list, params: CandidateParams):
    """The camera most points agree on: each cohort's joint fit (``_fit``) proposes one; its inliers
    are the members it explains within their limits (``_limits``); the proposal with the most
    inliers of different times wins, refitted with them alone. Returns ``((R_WC, p_WC, p_HP K x 3),
    inliers, their mean squared errors)`` or None."""
    best, limits = [], _limits(members, params)
    for cohort in _cohorts(members):
        fit = _fit(cohort, limits)
        if fit is None:
            continue
        inliers = [c for c in members if _explains(fit[0], fit[1], c, limits)]
        if len(inliers) > len(best) and _of_different_times(inliers):
            best = inliers
    fit = _fit(best, limits) if best else None
    if fit is None or len(fit[3]) < len(best):
        return None  # the inliers together leave one out: no consensus
    return fit[0:3], best, fit[4]


def _limits(members: list, params: CandidateParams) -> dict:
    """m^2 per member (by feature id): the most a camera may leave of its mean squared error,
    ``joint_consistency^2`` times what its own best camera leaves (its TLS solution's expected
    error, at least ``ROUND_OFF_MSE``), at most the members' median of that. A point whose own
    camera explains it exactly (a point of a link that turned about one axis only: its statistic
    pins nothing) is explained by no other camera; a noisy one (a track sliding on its patch, a
    point of a link that moved under the hand) by no looser a camera than most points allow."""
    own = {c.feature_id: max(c.solution.expected_mse, ROUND_OFF_MSE) for c in members}
    median = float(np.median(list(own.values())))
    return {i: params.joint_consistency**2 * min(e, median) for i, e in own.items()}


def _explains(R_WC: np.ndarray, p_WC: np.ndarray, c, limits: dict) -> bool:
    """Whether the camera explains ``c`` with its own best ``p_HP`` within its limit (``_limits``)."""
    return own_fit(c.statistic, R_WC, p_WC)[1] <= limits[c.feature_id]


def _fit(points: list, limits: dict):
    """The joint fit of ``points`` (``joint_tls`` then ``refine_joint``), the point that most exceeds
    its limit (``_limits``) left out while one does, as long as ``FIRST_CHOICE_POINTS`` and more than half
    are left. Returns ``(R_WC, p_WC, P, points kept, their mean squared errors)`` or None."""
    total = len(points)
    while len(points) >= FIRST_CHOICE_POINTS and 2 * len(points) > total:
        S_list = [S_of(c.statistic) for c in points]
        start = joint_tls(S_list)
        fit = None if start is None else refine_joint(S_list, *start)
        if fit is None:
            return None
        R_WC, p_WC, P = fit
        errors = np.array([mean_squared_error_of(c.statistic, pack_x(R_WC, p_WC, P[k]))
                           for k, c in enumerate(points)])
        excess = errors / np.array([limits[c.feature_id] for c in points])
        worst = int(np.argmax(excess))
        if excess[worst] <= 1.0:
            return R_WC, p_WC, P, points, errors
        points = points[:worst] + points[worst + 1:]
    return None


def _cohorts(members: list) -> list:
    """The groups of tracks seen together: for each member, the members whose tracks overlap its
    own in time (``admitted`` to ``last_sample``), each distinct group once, the largest first."""
    groups = {frozenset(j for j, d in enumerate(members) if _overlap(c, d)) for c in members}
    return [[members[j] for j in sorted(g)] for g in sorted(groups, key=len, reverse=True)]


def _overlap(c, d) -> bool:
    return c.admitted <= d.last_sample and d.admitted <= c.last_sample


def _of_different_times(points: list) -> bool:
    """Whether two of the points' tracks do not overlap in time (one ended before the other began)."""
    first_end = min(c.last_sample for c in points)
    return any(c.admitted > first_end for c in points)
