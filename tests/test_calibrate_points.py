"""Several points fixed on the hand at once (``calibrate_eye_to_hand_points``, issue 26 item 5): one
camera and one ``p_HP`` per point, against a known truth, with its verdicts and covariance."""

from __future__ import annotations

import numpy as np
import pytest
from eye_to_hand_data import make_points, make_samples, make_truth, point_identifiers, rotation_error_deg
from scipy.spatial.transform import Rotation

from sustain_drake.identification import (
    EyeToHandIdentifier,
    calibrate_eye_to_hand,
    calibrate_eye_to_hand_points,
    observability,
)
from sustain_drake.identification import eye_to_hand_points as points
from sustain_drake.identification.errors import IdentificationError

P_HP = np.array([[0.05, 0.02, 0.12], [-0.08, 0.04, 0.10], [0.0, -0.09, 0.15]])  # m, in the hand


def rms(a) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


def camera_errors(X_WC, truth) -> tuple[float, float]:
    """Position (m) and rotation (deg) of ``X_WC`` from the true camera."""
    return (float(np.linalg.norm(X_WC[:3, 3] - truth.X_WC[:3, 3])),
            rotation_error_deg(X_WC[:3, :3], truth.X_WC[:3, :3]))  # fmt: skip


def test_joint_recovers_the_camera_and_every_point_better_than_one_point_alone():
    """1 mm noise, 30 poses, each point missing from 30 % of them, 20 cameras and motions: the joint
    camera within 2.5 mm and 0.15 deg, every ``p_HP`` within 1.5 mm, and its RMS error over the runs
    at most 0.75 of one point's alone (three points of equal noise: 1/sqrt(3) = 0.58 expected;
    measured 0.59 for the position, 0.58 for the rotation)."""
    joint, alone = [], []
    for seed in range(20):
        truth = make_truth(seed)
        data, X_WH = make_points(truth, P_HP, 30, noise_m=1e-3, missing=0.3, seed=seed + 50)
        result = calibrate_eye_to_hand_points(data, X_WH)
        assert result.converged, result.verdict
        position, angle = camera_errors(result.X_WC, truth)
        assert position <= 2.5e-3 and angle <= 0.15
        assert position <= 4.0 * result.standard_errors[1]
        assert np.linalg.norm(result.p_HP - P_HP, axis=1).max() <= 1.5e-3
        for k, (samples, _) in enumerate(data.values()):
            assert np.array_equal(result.samples[k], samples) and len(result.residuals[k]) == len(samples)
        joint.append((position, angle))
        alone += [camera_errors(r.X_WC, truth) for r in result.single]
    joint, alone = np.array(joint), np.array(alone)
    assert rms(joint[:, 0]) <= 0.75 * rms(alone[:, 0])
    assert rms(joint[:, 1]) <= 0.75 * rms(alone[:, 1])


def test_points_of_different_noise_weigh_by_it():
    """One point measured to 0.5 mm, two to 4 mm (like the real data set's corner and codes): each
    weighs the inverse of its variance (64 times the others, found within 30-120), and the joint
    camera is as good as the precise point's alone (within 5 %; measured 0.626 against 0.628 mm RMS
    over 40 runs), not pulled off by the noisy ones (4.4-4.7 mm alone)."""
    joint, alone, ratios = [], [], []
    for seed in range(40):
        truth = make_truth(seed)
        data, X_WH = make_points(truth, P_HP, 40, noise_m=[0.5e-3, 4e-3, 4e-3], seed=seed + 900)
        result = calibrate_eye_to_hand_points(data, X_WH)
        assert result.converged, result.verdict
        assert result.seed == 0  # the precise point's camera is the best determined
        joint.append(camera_errors(result.X_WC, truth)[0])
        alone.append([camera_errors(r.X_WC, truth)[0] for r in result.single])
        ratios += list(result.weights[0] / result.weights[1:])
    alone = np.array(alone)
    assert rms(joint) <= 1.05 * rms(alone[:, 0])
    assert rms(alone[:, 1]) >= 5.0 * rms(joint)
    assert 30.0 <= min(ratios) and max(ratios) <= 120.0


def test_the_covariance_is_the_spread_of_the_errors():
    """Over 100 runs, the errors of (camera turn, camera position, every p_HP) against the joint
    covariance have the mean Mahalanobis square of a chi-square of 15 degrees of freedom (within 4
    of its standard errors of the mean, +-2.2; measured 14.95)."""
    squares = []
    for seed in range(100):
        truth = make_truth(seed)
        data, X_WH = make_points(truth, P_HP, 30, noise_m=1e-3, missing=0.3, seed=seed + 500)
        result = calibrate_eye_to_hand_points(data, X_WH)
        turn = Rotation.from_matrix(result.X_WC[:3, :3].T @ truth.X_WC[:3, :3]).as_rotvec()
        d = np.concatenate([turn, truth.X_WC[:3, 3] - result.X_WC[:3, 3], (P_HP - result.p_HP).ravel()])
        squares.append(d @ np.linalg.solve(result.covariance, d))
    assert abs(np.mean(squares) - 15.0) <= 2.2


def test_one_point_is_the_single_point_path():
    truth = make_truth(3)
    p_C, X_WH = make_samples(truth, 25, noise_m=1e-3, seed=8)
    old = calibrate_eye_to_hand(p_C, X_WH)
    order = np.random.default_rng(0).permutation(25)  # any order of the samples
    new = calibrate_eye_to_hand_points({"tip": (order, p_C[order])}, X_WH)
    assert old.converged and new.verdict == old.verdict and new.seed == 0
    assert np.array_equal(new.X_WC, old.X_WC) and np.array_equal(new.p_HP, old.p_HP[None])
    assert np.array_equal(new.residuals[0], old.residuals) and np.array_equal(new.samples[0], np.arange(25))
    assert np.array_equal(new.covariance, old.covariance) and new.rms[0] == old.rms
    assert new.single[0].X_WC.tolist() == old.X_WC.tolist()
    subset = np.arange(3, 25, 2)  # a point seen at some poses: its own samples only
    part = calibrate_eye_to_hand_points({7: (subset, p_C[subset])}, X_WH)
    assert np.array_equal(part.X_WC, calibrate_eye_to_hand(p_C[subset], X_WH[subset]).X_WC)
    assert part.num_samples == len(subset) and part.labels == (7,)


def test_points_that_do_not_converge_alone_converge_together():
    """Each point seen at 8 poses of its own (fewer than the 10 a fit needs): no point converges
    alone, the three together do, within 2.5 mm and 0.15 deg."""
    truth = make_truth(7)
    data, X_WH = make_points(truth, P_HP, 24, noise_m=1e-3, seed=9)
    order = np.random.default_rng(3).permutation(24)
    data = {label: (np.sort(order[8 * k:8 * k + 8]), None) for k, label in enumerate(data)}
    rng = np.random.default_rng(4)
    for k, (label, (samples, _)) in enumerate(data.items()):
        p_W = np.einsum("nij,j->ni", X_WH[samples, :3, :3], P_HP[k]) + X_WH[samples, :3, 3]
        data[label] = (samples, (p_W - truth.X_WC[:3, 3]) @ truth.X_WC[:3, :3] + rng.normal(0, 1e-3, (8, 3)))
    result = calibrate_eye_to_hand_points(data, X_WH)
    assert not any(r.converged for r in result.single)
    assert all(r.verdict.reason == "too few samples: 8 < 10" for r in result.single)
    assert result.converged, result.verdict
    position, angle = camera_errors(result.X_WC, truth)
    assert position <= 2.5e-3 and angle <= 0.15


def test_a_mispaired_sample_is_flagged_as_an_outlier():
    truth = make_truth(2)
    data, X_WH = make_points(truth, P_HP, 30, noise_m=1e-3, seed=12)
    samples, p_C = data["p1"]
    p_C = p_C.copy()
    p_C[5] += [0.02, 0.0, 0.0]  # 2 cm off: the position of another moment
    data["p1"] = (samples, p_C)
    result = calibrate_eye_to_hand_points(data, X_WH)
    assert result.converged, result.verdict
    assert [o.tolist() for o in result.outliers()] == [[], [int(samples[5])], []]


def _mirrored(truth, data, X_WH):
    return {k: (s, p * [1.0, 1.0, -1.0]) for k, (s, p) in data.items()}, X_WH


def _millimetres(truth, data, X_WH):
    return {k: (s, 1000.0 * p) for k, (s, p) in data.items()}, X_WH


def _hand_in_millimetres(truth, data, X_WH):
    X_WH = X_WH.copy()
    X_WH[:, :3, 3] *= 1000.0
    return data, X_WH


def _resampled(truth, X_WH, rng):
    """Every point measured anew (1 mm noise) at the poses ``X_WH``."""
    data = {}
    for k, p in enumerate(P_HP):
        p_W = np.einsum("nij,j->ni", X_WH[:, :3, :3], p) + X_WH[:, :3, 3]
        data[f"p{k}"] = (np.arange(len(X_WH)), (p_W - truth.X_WC[:3, 3]) @ truth.X_WC[:3, :3]
                         + rng.normal(0.0, 1e-3, (len(X_WH), 3)))  # fmt: skip
    return data


def _translation_only(truth, data, X_WH):
    X_WH = X_WH.copy()
    X_WH[:, :3, :3] = X_WH[0, :3, :3]
    return _resampled(truth, X_WH, np.random.default_rng(1)), X_WH


def _one_axis(truth, data, X_WH):
    X_WH = X_WH.copy()
    X_WH[:, :3, :3] = Rotation.from_euler("z", np.linspace(-2.0, 2.0, len(X_WH))[:, None]).as_matrix()
    return _resampled(truth, X_WH, np.random.default_rng(1)), X_WH


def _another_camera(truth, data, X_WH):
    """Point p1 in another camera's frame (its own fit is fine; it disagrees with the others)."""
    data = dict(data)
    samples, p_C = data["p1"]
    data["p1"] = (samples, p_C @ Rotation.from_euler("z", 3.0, degrees=True).as_matrix().T)
    return data, X_WH


def _loose_point(truth, data, X_WH):
    """Point p1 not fixed on the hand: it wanders 2 cm from sample to sample."""
    data = dict(data)
    samples, p_C = data["p1"]
    data["p1"] = (samples, p_C + np.random.default_rng(0).normal(0.0, 0.02, p_C.shape))
    return data, X_WH


@pytest.mark.parametrize(("make", "reason"), [
    (_mirrored, observability.LEFT_HANDED),
    (_millimetres, observability.POINTS_NOT_IN_METRES),
    (_hand_in_millimetres, observability.HAND_NOT_IN_METRES),
    (_translation_only, observability.NO_ROTATION),
    (_one_axis, observability.ONE_AXIS),
    (_another_camera, observability.FIT_DISAGREES),
    (_loose_point, observability.FIT_DISAGREES),
], ids=["left-handed", "millimetres", "hand in millimetres", "translation only", "one axis", "another camera",
        "loose point"])  # fmt: skip
def test_data_the_verdict_refuses(make, reason):
    truth = make_truth(7)
    data, X_WH = make_points(truth, P_HP, 30, noise_m=1e-3, missing=0.2, seed=21)
    result = calibrate_eye_to_hand_points(*make(truth, data, X_WH))
    assert not result.converged
    assert result.verdict.reason.startswith(reason), result.verdict.reason
    assert "\n" not in result.verdict.reason


def test_a_disagreeing_point_is_named():
    truth = make_truth(7)
    data, X_WH = make_points(truth, P_HP, 30, noise_m=1e-3, seed=21)
    reason = calibrate_eye_to_hand_points(*_loose_point(truth, data, X_WH)).verdict.reason
    assert "point 'p1': residuals" in reason and "is it fixed on the hand" in reason


def test_too_few_poses():
    truth = make_truth(1)
    data, X_WH = make_points(truth, P_HP, 9, noise_m=1e-3, seed=2)
    assert calibrate_eye_to_hand_points(data, X_WH).verdict.reason == "too few samples: 9 < 10"


def test_the_joint_covariance_of_one_point_is_the_single_point_covariance():
    truth = make_truth(4)
    p_C, X_WH = make_samples(truth, 20, noise_m=1e-3, seed=5)
    identifier = EyeToHandIdentifier()
    for c, X in zip(p_C, X_WH, strict=True):
        identifier.add(c, X[:3, :3], X[:3, 3])
    refined = identifier.solve().refined
    single = observability.eye_to_hand_covariance(identifier.core.S, refined.R_WC)
    joint = points.joint_covariance([identifier.core.S], refined.R_WC, refined.p_WC, [refined.p_HP], [2.5])
    np.testing.assert_allclose(joint, single, rtol=1e-6, atol=1e-14)


def test_points_given_the_true_camera_are_the_true_points():
    truth = make_truth(6)
    data, X_WH = make_points(truth, P_HP, 12, seed=3)
    statistics = [identifier.core.S.copy() for identifier in point_identifiers(data, X_WH)]
    found = points.points_given_camera(statistics, truth.X_WC[:3, :3], truth.X_WC[:3, 3])
    np.testing.assert_allclose(found, P_HP, atol=1e-9)
    R, p_WC, P, weights = points.refine_joint_weighted(statistics, truth.X_WC[:3, :3], truth.X_WC[:3, 3])
    np.testing.assert_allclose(P, P_HP, atol=1e-9)
    assert np.abs(p_WC - truth.X_WC[:3, 3]).max() <= 1e-9 and np.allclose(weights, 1.0)  # noise-free: alike


def _three_point_fit(n: int = 60, seed: int = 4):
    truth = make_truth(6)
    p_HP = np.array([[0.05, 0.02, 0.12], [-0.08, 0.04, 0.10], [0.0, -0.09, 0.15]])
    data, X_WH = make_points(truth, p_HP, n, noise_m=1e-3, seed=seed)
    S_list = [identifier.core.S for identifier in point_identifiers(data, X_WH)]
    R, p_WC, P = points.refine_joint(S_list, truth.X_WC[:3, :3], truth.X_WC[:3, 3], p_HP)
    return truth, S_list, R, p_WC, P


def test_fewer_independent_samples_widen_the_joint_covariance_by_the_degrees_of_freedom_ratio():
    """``independent``: point k's statistic weighs ``independent_k / n_k``; with every point at a
    quarter, ``H`` and the residual sum are a quarter each, so the covariance grows by the ratio
    of the degrees of freedom; as many independent samples as samples (or more) change nothing."""
    _, S_list, R, p_WC, P = _three_point_fit()
    n = np.array([S[9, 9] for S in S_list])
    full = points.joint_covariance(S_list, R, p_WC, P)
    for all_of_them in (n, 2 * n):
        same = points.joint_covariance(S_list, R, p_WC, P, independent=all_of_them)
        np.testing.assert_allclose(same, full, rtol=1e-12)
    quarter = points.joint_covariance(S_list, R, p_WC, P, independent=n / 4)
    dof, dof_quarter = 3 * n.sum() - 6 - 9, 3 * n.sum() / 4 - 6 - 9
    np.testing.assert_allclose(quarter, full * dof / dof_quarter, rtol=1e-9)
    assert points.joint_covariance(S_list, R, p_WC, P, independent=[1.0, 1.0, 1.0]) is None  # 9 < 15
    for bad in ([1.0, -1.0, 1.0], [1.0, np.nan, 1.0], [1.0, 1.0]):
        with pytest.raises(IdentificationError, match="independent must be (3 positive numbers|finite)"):
            points.joint_covariance(S_list, R, p_WC, P, independent=bad)


def test_the_position_given_the_rotation_counts_independent_samples_in_its_covariance_only():
    truth, S_list, R, _, _ = _three_point_fit()
    found = points.position_and_points_given_rotation(S_list, truth.X_WC[:3, :3])
    assert np.linalg.norm(found.p_WC - truth.X_WC[:3, 3]) < 3e-3
    n = np.array([S[9, 9] for S in S_list])
    quarter = points.position_and_points_given_rotation(S_list, truth.X_WC[:3, :3], independent=n / 4)
    np.testing.assert_allclose(quarter.p_WC, found.p_WC, rtol=1e-12)  # the fit weighs every sample
    np.testing.assert_allclose(quarter.mean_squared_errors, found.mean_squared_errors, rtol=1e-12)
    dof, dof_quarter = 3 * n.sum() - 3 - 9, 3 * n.sum() / 4 - 3 - 9
    np.testing.assert_allclose(quarter.covariance, found.covariance * dof / dof_quarter, rtol=1e-9)
    with pytest.raises(IdentificationError, match="independent must be 3 positive numbers"):
        points.position_and_points_given_rotation(S_list, truth.X_WC[:3, :3], independent=[0.0, 1.0, 1.0])
