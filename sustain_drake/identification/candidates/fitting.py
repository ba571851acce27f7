"""A candidate's statistic and the model: where an estimate puts a point, how well a camera explains a
point's samples, how much the hand turned over them, and the joint refinement of one camera with
several points (tracks of one point stitched)."""

import math
from dataclasses import replace

import numpy as np

from sustain_drake.identification.candidates.bank import Candidate
from sustain_drake.identification.candidates.params import CandidateParams
from sustain_drake.identification.eye_to_hand import (
    EyeToHandEstimate,
    EyeToHandIdentifier,
    build_A,
    pack_x,
)
from sustain_drake.identification.eye_to_hand_points import joint_covariance, refine_joint, rotation_levers
from sustain_drake.identification.observability import region_95
from sustain_drake.identification.sustainable_identifier import SustainableIdentifier
from sustain_drake.identification.view_correlation import independent_samples


def x_is_set(x: np.ndarray | None) -> bool:
    return x is not None and np.all(np.isfinite(x)) and bool(np.any(x))


def predicted_p_CP(x: np.ndarray, X_WH: np.ndarray) -> np.ndarray:
    """Where estimate ``x`` (Eq. (36)) puts the tracked point in the camera frame (Eq. (30))."""
    return points_in_camera(x[0:9].reshape(3, 3, order="F"), x[9:12], x[12:15], X_WH)


def points_in_camera(R_WC: np.ndarray, p_WC: np.ndarray, p_HP: np.ndarray, X_WH: np.ndarray) -> np.ndarray:
    """Eq. (30): points of the hand (``p_HP``, 3 or K x 3) in the camera frame, the hand at ``X_WH``."""
    return (p_HP @ X_WH[:3, :3].T + X_WH[:3, 3] - p_WC) @ R_WC


def sample_error(p_CP, X_WH, x) -> float:
    return SustainableIdentifier.sample_error(build_A(p_CP, X_WH[:3, :3], X_WH[:3, 3]), x)


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


def on_parent_link(c: Candidate) -> bool:
    """Whether the candidate's samples fit the hand's parent link L (``parent_statistic``: the same
    samples with the pose of L) better than the hand: the mean squared error of its own
    Gauss-Newton fit (Eq. (30), each model with its own camera and point) under L's poses below
    the one under the hand's. Both models have the same unknowns (a camera and one point fixed on
    a body), so the smaller error is the likelier body: no threshold. The TLS expected error
    (Eq. (13)) cannot tell them apart: it is algebraic, and a wrong camera absorbs most of the
    difference. A point fixed on L near the axis of the hand's last joint moves almost like the
    hand and fits it under a camera off by centimetres (docs/hand_eye_record.md, "Points on the
    wrist"); nearer the axis the two fits are alike and the choice costs little either way. False
    when L's poses are not known (``parent_statistic`` None) or either fit has no solution."""
    if c.parent_statistic is None:
        return False
    errors = []
    for statistic in (c.statistic, c.parent_statistic):
        identifier = EyeToHandIdentifier()
        identifier.set_state(statistic)
        refined = identifier.solve(refine_estimate=True).refined
        if refined is None or not np.isfinite(refined.mean_squared_error):
            return False
        errors.append(refined.mean_squared_error)
    return bool(errors[1] < errors[0])


def explained(c: Candidate, x, adopted_mse: float, params: CandidateParams) -> bool:
    """Whether the camera of ``x`` explains the candidate's samples (its own best ``p_HP``) within
    ``observe_consistency`` times the adopted RMS error."""
    R_WC, p_WC = np.asarray(x)[0:9].reshape(3, 3, order="F"), np.asarray(x)[9:12]
    return own_fit(c.statistic, R_WC, p_WC)[1] <= params.observe_consistency**2 * adopted_mse


def core_of(statistic: np.ndarray):
    """The identifier core holding an identifier's state vector (its ``S``, weight and count)."""
    identifier = EyeToHandIdentifier()
    identifier.set_state(statistic)
    return identifier.core


def weight_of(statistic: np.ndarray) -> float:
    """The (forgetting-weighted) number of samples of an identifier's state vector."""
    return core_of(statistic).weight


def S_of(statistic: np.ndarray) -> np.ndarray:
    """``S = sum A_t^T A_t`` (16 x 16) from an identifier's state vector."""
    return core_of(statistic).S


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
            n_group, n = weight_of(group[1]), weight_of(statistic)
            pooled = (n_group * group[3] + n * mse) / (n_group + n)
            if merged_mse <= max_increase * pooled:
                group[0].append(i)
                group[1:] = [merged, q, merged_mse]
                break
        else:
            groups.append([[i], statistic.copy(), p_HP, mse])
    return [(group[0], group[1]) for group in groups]


def independent_of(candidates, R_WC: np.ndarray, p_WC: np.ndarray, params: CandidateParams) -> list:
    """Per candidate, how many independent samples its samples count as at the camera ``(R_WC,
    p_WC)``: ``view_correlation.independent_samples`` of its views (``view_angle``), each with its
    own best ``p_HP`` under that camera; its samples when views are not kept (``view_angle`` 0)."""
    if params.view_angle <= 0:
        return [float(c.solution.num_samples) for c in candidates]
    out = []
    for c in candidates:
        p_HP = best_p_HP_given_camera(c.statistic, R_WC, p_WC)
        out.append(independent_samples(c.view_sums, S_of(c.statistic), R_WC, p_WC, p_HP))
    return out


# m^2 (1 um RMS): a mean squared error below this is round-off (noise-free data); the joint
# refinement's ratios (the members' limit, the weights) are taken against at least this.
ROUND_OFF_MSE = 1e-12


def joint_refined(best: Candidate, kept, archive, params: CandidateParams) -> tuple[Candidate, list, list]:
    """``params.joint``: the leader's camera refined jointly with every other candidate (tracked
    or archived, ``joint_min_samples`` samples) that it explains (``eye_to_hand_points.refine_joint``:
    one camera, one ``p_HP`` per point). Members are the points whose own mean squared error
    (with their best ``p_HP``) is within ``joint_consistency^2`` times the leader's, first under
    the leader's camera, then again under the joint one (three times with ``stitch_radius``: the
    groups of tracks of one point are formed again under each better camera). Returns the leader
    with the joint camera and its own ``p_HP`` (its group's, when stitched; its verdict and
    ``expected_mse`` unchanged: the paper's rule judges the leader), the statistics of the
    points used (one per group when stitched; the leader's first) and their independent samples
    (``independent_of``, summed over a group)."""
    estimate = best.solution.estimate
    if estimate is None:
        return best, [best.statistic], None
    alone = best, [best.statistic], independent_of([best], estimate.R_WC, estimate.p_WC, params)
    others = [c for c in list(kept) + list(archive)
              if c.feature_id != best.feature_id and c.solution.num_samples >= params.joint_min_samples]
    R, p_WC = estimate.R_WC, estimate.p_WC
    limit = params.joint_consistency**2 * max(best.solution.expected_mse, ROUND_OFF_MSE)
    members = []
    for _ in range(3 if params.stitch_radius > 0 else 2):
        members = first_choice([c for c in others if own_fit(c.statistic, R, p_WC)[1] <= limit], best)
        if not members:
            return alone
        statistics = [c.statistic for c in [best] + members]
        groups = [[i] for i in range(len(statistics))]
        if params.stitch_radius > 0:
            stitched = stitch(statistics, R, p_WC, params.stitch_radius)
            groups, statistics = [g for g, _ in stitched], [s for _, s in stitched]
        P, weights = _points_and_weights(statistics, R, p_WC, params)
        refined = refine_joint([w * S_of(s) for w, s in zip(weights, statistics, strict=True)], R, p_WC, P)
        if refined is None:
            return alone
        R, p_WC, P = refined
    independent = independent_of([best] + members, R, p_WC, params)
    independent = [sum(independent[i] for i in g) for g in groups]
    x = pack_x(R, p_WC, P[0])  # the leader's point (its group is the first)
    joint = EyeToHandEstimate(R, p_WC.copy(), P[0].copy(), x, mean_squared_error_of(best.statistic, x))
    solution = replace(best.solution, projected=joint, refined=joint)
    return replace(best, solution=solution), statistics, independent


# count: centrally symmetric points (a leader and the witness that confirms its camera,
# ``confirm_with_witness``) that, where there are as many, keep the points anchored on their patch
# out of the candidates (``admission``) and out of the joint refinement: a symmetric corner is
# found again to a few hundredths of a pixel under any view, an anchored point on fine print moves
# by a tenth of a pixel or more with the view (docs/hand_eye.md, "The points")
FIRST_CHOICE_POINTS = 2


def first_choice(members: list, best: Candidate) -> list:
    """The joint refinement's members without those anchored on their patch
    (``Candidate.symmetric`` False) when, with the leader, ``FIRST_CHOICE_POINTS`` symmetric ones
    join: a few points that stay put under any view outweigh many that move a little."""
    symmetric = [c for c in members if c.symmetric]
    if len(symmetric) + int(best.symmetric) >= FIRST_CHOICE_POINTS:
        return symmetric
    return members


def _points_and_weights(statistics: list, R_WC: np.ndarray, p_WC: np.ndarray, params: CandidateParams):
    """Each point's own ``p_HP`` under the camera ``(R_WC, p_WC)`` (K x 3) and its weight in the joint
    fit (``joint_weighted``: ``inverse_variance_weights`` of their own fits; else all 1)."""
    fits = [own_fit(s, R_WC, p_WC) for s in statistics]
    P = np.array([p_HP for p_HP, _ in fits])
    weights = (inverse_variance_weights(np.array([mse for _, mse in fits])) if params.joint_weighted
               else np.ones(len(P)))
    return P, weights


def inverse_variance_weights(mse: np.ndarray) -> np.ndarray:
    """``joint_weighted``: each point's weight, the inverse of its own mean squared error (``own_fit``
    under the joint camera), scaled to a mean of 1."""
    weights = 1.0 / np.maximum(mse, ROUND_OFF_MSE)
    return weights / weights.mean()


def smallest_rotation_lever(statistics: list, estimate: EyeToHandEstimate | None) -> float:
    """The smallest of ``eye_to_hand_points.rotation_levers`` of the points' statistics (each point with
    its best ``p_HP``) at the estimate's camera, m (0 without an estimate)."""
    if estimate is None:
        return 0.0
    P = [best_p_HP_given_camera(s, estimate.R_WC, estimate.p_WC) for s in statistics]
    return float(rotation_levers([S_of(s) for s in statistics], estimate.R_WC, estimate.p_WC, P)[0])


def joint_camera_sd(statistics: list, estimate: EyeToHandEstimate | None, params: CandidateParams,
                    independent=None):
    """The 1 sd of the camera that ``joint_refined`` fitted to ``statistics`` (its returned points,
    the leader's first, and their ``independent`` samples; None: all) at ``estimate``: ``(position
    m, rotation rad)``, each the RMS of the 3-D error, from the joint fit's Gauss-Newton covariance
    (``eye_to_hand_points.joint_covariance``, each point with its own ``p_HP`` under that camera,
    the fit's weights and its independent samples). None without an estimate or when the fit is
    undetermined. A measure of the views themselves, not a count of samples
    (docs/hand_eye_record.md, "The joint fit's own uncertainty")."""
    if estimate is None:
        return None
    P, weights = _points_and_weights(statistics, estimate.R_WC, estimate.p_WC, params)
    S_list = [S_of(s) for s in statistics]
    return camera_sd(joint_covariance(S_list, estimate.R_WC, estimate.p_WC, P, weights,
                                      independent=independent))


def camera_sd(covariance: np.ndarray | None):
    """``(position m, rotation rad)``: the RMS of the 3-D error of a camera whose covariance (a joint
    fit's, ``eye_to_hand_points.joint_covariance``) starts with its turn (rad) and its position (m);
    None when the covariance is (None: the fit undetermined)."""
    if covariance is None:
        return None
    d = np.diagonal(covariance)
    return math.sqrt(float(d[3:6].sum())), math.sqrt(float(d[0:3].sum()))


# the radius that holds 95 % of an isotropic 3-D normal error over the error's RMS: 1.614
REGION_95 = region_95(3)


def within_accuracy(sd, params: CandidateParams) -> bool:
    """``camera_accuracy``, ``camera_rotation_accuracy``: whether the 95 % region of a camera whose
    1 sd is ``sd`` (``joint_camera_sd`` of its fit; None: undetermined) lies within both. True when
    both are off (inf). The joint fit's sd measures the views themselves: a camera from a few
    points seen from too few sides, or with too few samples, waits (docs/hand_eye_record.md, "The
    joint fit's own uncertainty")."""
    if math.isinf(params.camera_accuracy) and math.isinf(params.camera_rotation_accuracy):
        return True
    return sd_within_targets(sd, params)


def sd_within_targets(sd, params: CandidateParams) -> bool:
    """Whether a camera's 95 % region (its ``camera_sd`` times ``REGION_95``) lies within
    ``camera_accuracy`` and ``camera_rotation_accuracy``; False for None (undetermined)."""
    return (sd is not None and REGION_95 * sd[0] <= params.camera_accuracy
            and REGION_95 * sd[1] <= params.camera_rotation_accuracy)
