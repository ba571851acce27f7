"""Eye-to-hand formulation (§3.4) with the §3.2 projection, conditioning and refinement."""

import math
from dataclasses import replace

import numpy as np
import pytest
from eye_to_hand_data import make_samples, make_truth, rotation_error_deg
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from sustain_drake.identification import (
    EyeToHandIdentifier,
    IdentificationError,
    calibrate_eye_to_hand,
)
from sustain_drake.identification.candidates import best_p_HP_given_camera
from sustain_drake.identification.eye_to_hand import build_A, conditioning_transform, pack_x
from sustain_drake.identification.eye_to_hand_points import camera_given_points, refine_joint, rotation_levers
from sustain_drake.identification.rotation import project_to_rotation


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_noise_free_is_exact(seed):
    truth = make_truth(seed)
    p_C, X_WH = make_samples(truth, 20, seed=seed + 10)
    result = calibrate_eye_to_hand(p_C, X_WH)
    assert result.converged, result.verdict
    for est in (result.projected, result.refined):
        assert np.abs(est.X_WC - truth.X_WC).max() < 1e-9
        assert np.abs(est.p_HP - truth.p_HP).max() < 1e-9
    assert result.rms < 1e-9


def test_one_mm_noise_300_samples():
    truth = make_truth(5)
    p_C, X_WH = make_samples(truth, 300, noise_m=1e-3, seed=6)
    result = calibrate_eye_to_hand(p_C, X_WH)
    assert result.converged, result.verdict
    assert rotation_error_deg(result.X_WC[:3, :3], truth.X_WC[:3, :3]) <= 0.1
    assert np.linalg.norm(result.X_WC[:3, 3] - truth.X_WC[:3, 3]) <= 1e-3
    assert np.linalg.norm(result.p_HP - truth.p_HP) <= 1e-3
    # 1 mm per axis: the 3-D residual RMS is about sqrt(3) mm.
    assert result.rms == pytest.approx(math.sqrt(3) * 1e-3, rel=0.15)


@pytest.mark.parametrize("noise", [0.0, 1e-3])
def test_pure_translation_never_converges(noise):
    truth = make_truth(7)
    p_C, X_WH = make_samples(truth, 500, noise_m=noise, rotate=False, seed=8)
    ident = EyeToHandIdentifier()
    for i, (c, X) in enumerate(zip(p_C, X_WH, strict=True)):
        ident.add(c, X[:3, :3], X[:3, 3])
        if i % 50 == 49:
            solution = ident.solve()
            assert not solution.verdict.converged
            assert "motion not rich enough" in solution.verdict.reason
            assert solution.eigen.num_null >= 2


def test_too_few_samples_is_not_converged():
    truth = make_truth(9)
    p_C, X_WH = make_samples(truth, 6, seed=10)
    result = calibrate_eye_to_hand(p_C, X_WH)
    assert not result.converged
    assert result.verdict.reason.startswith("too few samples")


def test_sign_of_v_N_does_not_matter():
    truth = make_truth(11)
    p_C, X_WH = make_samples(truth, 50, noise_m=5e-4, seed=12)
    ident = EyeToHandIdentifier()
    for c, X in zip(p_C, X_WH, strict=True):
        ident.add(c, X[:3, :3], X[:3, 3])
    direction = ident.core.eigen(conditioning_transform(ident.core.S)).direction
    plus, minus = project_to_rotation(direction[:9]), project_to_rotation(-direction[:9])
    assert np.allclose(plus.R, minus.R, atol=1e-14)
    assert np.linalg.det(plus.R) == pytest.approx(1.0)
    assert plus.ssd == pytest.approx(minus.ssd)
    assert np.allclose(plus.scale * direction, minus.scale * -direction, atol=1e-14)
    assert plus.sign == -minus.sign


def test_projection_of_a_reflection_is_a_proper_rotation():
    R = Rotation.random(random_state=3).as_matrix()
    reflection = R @ np.diag([1.0, 1.0, -1.0])  # det -1
    p = project_to_rotation(reflection.ravel(order="F"))
    assert np.linalg.det(p.R) == pytest.approx(1.0)
    assert np.allclose(p.R.T @ p.R, np.eye(3), atol=1e-12)
    # A scaled rotation projects to itself with the inverse scale and SSD 0.
    q = project_to_rotation((-2.5 * R).ravel(order="F"))
    assert np.allclose(q.R, R, atol=1e-12) and q.scale == pytest.approx(-0.4) and q.ssd < 1e-12


def test_refinement_from_the_statistic_equals_least_squares_on_the_samples():
    """The Gauss-Newton refinement runs from C alone; it must reach the same optimum as a
    least-squares solver that keeps every sample."""
    truth = make_truth(13)
    p_C, X_WH = make_samples(truth, 80, noise_m=2e-3, seed=14)
    result = calibrate_eye_to_hand(p_C, X_WH)

    def residuals(theta):
        R = Rotation.from_rotvec(theta[:3]).as_matrix()
        r = p_C @ R.T + theta[3:6] - np.einsum("nij,j->ni", X_WH[:, :3, :3], theta[6:9]) - X_WH[:, :3, 3]
        return r.ravel()

    start = np.concatenate([Rotation.from_matrix(truth.X_WC[:3, :3]).as_rotvec(), truth.X_WC[:3, 3],
                            truth.p_HP])  # fmt: skip
    ls = least_squares(residuals, start, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    R_ls = Rotation.from_rotvec(ls.x[:3]).as_matrix()
    assert rotation_error_deg(result.X_WC[:3, :3], R_ls) < 1e-6
    assert np.abs(result.X_WC[:3, 3] - ls.x[3:6]).max() < 1e-8
    assert np.abs(result.p_HP - ls.x[6:9]).max() < 1e-8


def test_conditioning_transform_maps_the_normalised_problem():
    """A_t x = s A'_t x' with x = T x' (T includes 1/s): T^T C T is the statistic of A'_t / ... ."""
    truth = make_truth(15)
    p_C, X_WH = make_samples(truth, 40, noise_m=1e-3, seed=16)
    ident = EyeToHandIdentifier()
    for c, X in zip(p_C, X_WH, strict=True):
        ident.add(c, X[:3, :3], X[:3, 3])
    T = conditioning_transform(ident.core.S)
    c_mean = p_C.mean(axis=0)
    s = math.sqrt(np.mean(np.sum((p_C - c_mean) ** 2, axis=1)))
    p_mean = X_WH[:, :3, 3].mean(axis=0)
    for c, X in zip(p_C[:5], X_WH[:5], strict=True):
        A_norm = build_A((c - c_mean) / s, X[:3, :3], (X[:3, 3] - p_mean) / s)
        assert np.allclose(build_A(c, X[:3, :3], X[:3, 3]) @ T, A_norm, atol=1e-12)


def test_sample_error_and_state_clone():
    truth = make_truth(17)
    p_C, X_WH = make_samples(truth, 30, noise_m=1e-3, seed=18)
    ident = EyeToHandIdentifier()
    for c, X in zip(p_C, X_WH, strict=True):
        ident.add_pose(c, X)
    clone = EyeToHandIdentifier()
    clone.set_state(ident.state)
    a, b = ident.solve(), clone.solve()
    assert np.array_equal(a.estimate.X_WC, b.estimate.X_WC)
    est = a.estimate
    s = ident.sample_error(p_C[0], X_WH[0, :3, :3], X_WH[0, :3, 3], est)
    A = build_A(p_C[0], X_WH[0, :3, :3], X_WH[0, :3, 3])
    assert s == pytest.approx(np.sum((A @ pack_x(est.R_WC, est.p_WC, est.p_HP)) ** 2))
    # A sample 5 cm off is flagged by its error.
    assert ident.sample_error(p_C[0] + [0.05, 0, 0], X_WH[0, :3, :3], X_WH[0, :3, 3], est) > 1e-3


finite = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False, allow_infinity=False)
anything = st.floats(allow_nan=True, allow_infinity=True)


@settings(max_examples=60, deadline=None)
@example(samples=[([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], [133705730176444.0, 0.0, 0.0]),
                  ([0.0, 0.0, 3.382577463982276e-140], [0.0, 0.0, 0.0, 0.0], [133705730176444.0, 0.0, 0.0])],
         forgetting=0.9)  # a * a overflowed to a NaN expected error
@given(
    samples=st.lists(
        st.tuples(
            st.lists(st.one_of(finite, anything), min_size=3, max_size=3),
            st.lists(finite, min_size=4, max_size=4),
            st.lists(st.one_of(finite, anything), min_size=3, max_size=3),
        ),
        max_size=25,
    ),
    forgetting=st.sampled_from([1.0, 0.9, 0.5]),
)
def test_random_streams_never_give_nan_or_undocumented_errors(samples, forgetting):
    ident = EyeToHandIdentifier(forgetting_factor=forgetting)
    for c, q, p in samples:
        q = np.array(q)
        R = Rotation.from_quat(q).as_matrix() if np.linalg.norm(q) > 1e-6 else np.eye(3)
        try:
            ident.add(np.array(c), R, np.array(p))
        except IdentificationError:
            assert not (np.all(np.isfinite(c)) and np.all(np.isfinite(p)) and max(map(abs, c + p)) < 1e100)
        solution = ident.solve()
        assert isinstance(solution.verdict.converged, bool) and solution.verdict.reason
        assert np.all(np.isfinite(solution.eigenvalues))
        if solution.estimate is not None:
            assert np.all(np.isfinite(solution.estimate.X_WC))
            assert np.all(np.isfinite(solution.estimate.p_HP))
            assert math.isfinite(solution.estimate.mean_squared_error)
            assert np.linalg.det(solution.estimate.R_WC) == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize(
    ("p_C", "X_WH", "message"),
    [
        (np.zeros((5, 2)), np.tile(np.eye(4), (5, 1, 1)), r"p_C must have shape \(n, 3\)"),
        (np.zeros((5, 3)), np.tile(np.eye(4), (4, 1, 1)), "must pair one to one"),
        (np.full((5, 3), np.nan), np.tile(np.eye(4), (5, 1, 1)), "not finite"),
        (np.zeros((5, 3)), np.tile(np.diag([1.0, 1.0, 2.0, 1.0]), (5, 1, 1)), r"X_WH\[0\] is not a rotation"),
        (np.zeros((5, 3)), np.tile(np.diag([1.0, 1.0, -1.0, 1.0]), (5, 1, 1)), "not a rotation"),
        (np.zeros((5, 3)), np.tile(np.eye(4) + np.eye(4, k=-3), (5, 1, 1)), "last row"),
        ([["a", "b", "c"]], np.tile(np.eye(4), (1, 1, 1)), "not a numeric array"),
    ],
)
def test_batch_input_errors(p_C, X_WH, message):
    with pytest.raises(IdentificationError, match=message):
        calibrate_eye_to_hand(p_C, X_WH)


def test_joint_refinement_equals_least_squares_over_every_points_samples():
    """Three points fixed on the hand, each seen over its own narrow range of hand rotations (a
    mark on one face of a tool): ``refine_joint`` from the three statistics reaches the optimum of
    a least-squares solver that keeps every sample of every point, and its camera is better than
    any single point's."""
    truth = make_truth(21)
    rng = np.random.default_rng(22)
    points = [truth.p_HP, truth.p_HP + [0.05, -0.03, 0.1], truth.p_HP + [-0.04, 0.06, -0.08]]
    axes = np.eye(3)
    data, S_list, singles = [], [], []
    for k, p_HP in enumerate(points):
        X_WH = np.tile(np.eye(4), (150, 1, 1))
        # Rotations within 0.15 rad about a base orientation that differs per point.
        base = Rotation.from_rotvec(0.8 * axes[k])
        X_WH[:, :3, :3] = (base * Rotation.from_rotvec(rng.normal(0, 0.15, (150, 3)))).as_matrix()
        X_WH[:, :3, 3] = rng.uniform(-0.2, 0.2, (150, 3)) + [0.4, 0.0, 0.3]
        p_W = np.einsum("nij,j->ni", X_WH[:, :3, :3], p_HP) + X_WH[:, :3, 3]
        p_C = (p_W - truth.X_WC[:3, 3]) @ truth.X_WC[:3, :3] + rng.normal(0, 1.5e-3, (150, 3))
        identifier = EyeToHandIdentifier()
        for c, X in zip(p_C, X_WH, strict=True):
            identifier.add_pose(c, X)
        S_list.append(identifier.core.S)
        singles.append(identifier.solve().estimate)
        data.append((p_C, X_WH))
    first = singles[0]
    R, p_WC, P = refine_joint(S_list, first.R_WC, first.p_WC,
                              np.array([best_p_HP_given_camera(np.r_[S.ravel(), 0, 0], first.R_WC, first.p_WC)
                                        for S in S_list]))  # fmt: skip

    def residuals(theta):
        R_ = Rotation.from_rotvec(theta[:3]).as_matrix()
        out = []
        for k, (p_C, X_WH) in enumerate(data):
            p_HP = theta[6 + 3 * k: 9 + 3 * k]
            p_W = np.einsum("nij,j->ni", X_WH[:, :3, :3], p_HP) + X_WH[:, :3, 3]
            out.append(p_C @ R_.T + theta[3:6] - p_W)
        return np.concatenate(out).ravel()

    start = np.concatenate([Rotation.from_matrix(truth.X_WC[:3, :3]).as_rotvec(), truth.X_WC[:3, 3], *points])
    ls = least_squares(residuals, start, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert rotation_error_deg(R, Rotation.from_rotvec(ls.x[:3]).as_matrix()) < 1e-6
    assert np.abs(p_WC - ls.x[3:6]).max() < 1e-7 and np.abs(P.ravel() - ls.x[6:]).max() < 1e-7
    joint_error = rotation_error_deg(R, truth.X_WC[:3, :3])
    assert joint_error < min(rotation_error_deg(e.R_WC, truth.X_WC[:3, :3]) for e in singles)
    assert refine_joint([np.zeros((16, 16))] * 2, first.R_WC, first.p_WC, np.zeros((2, 3))) is None


def test_rotation_levers_are_what_a_turned_camera_costs_once_the_rest_is_refitted():
    """``rotation_levers``: a camera turned by ``delta`` about an axis ``a`` fits the samples, with
    its position and every point's ``p_HP`` refitted (linear least squares), to an RMS of
    ``delta`` times the lever along ``a``: the smallest lever is the least RMS over every axis,
    the largest the most. Two points over narrow hand rotations (0.05 rad: small levers) and over
    wide ones (0.5 rad)."""
    truth = make_truth(31)
    R_WC, p_WC = truth.X_WC[:3, :3], truth.X_WC[:3, 3]
    points = [truth.p_HP, truth.p_HP + [0.03, 0.1, -0.05]]
    rng = np.random.default_rng(32)
    levers = {}
    for wobble in (0.05, 0.5):
        data, S_list = [], []
        for p_HP in points:
            X_WH = np.tile(np.eye(4), (100, 1, 1))
            X_WH[:, :3, :3] = Rotation.from_rotvec(rng.normal(0, wobble, (100, 3))).as_matrix()
            X_WH[:, :3, 3] = rng.uniform(-0.05, 0.05, (100, 3)) + [0.4, 0.0, 0.3]
            p_C = (np.einsum("nij,j->ni", X_WH[:, :3, :3], p_HP) + X_WH[:, :3, 3] - p_WC) @ R_WC
            S_list.append(sum(build_A(c, X[:3, :3], X[:3, 3]).T @ build_A(c, X[:3, :3], X[:3, 3])
                              for c, X in zip(p_C, X_WH, strict=True)))
            data.append((p_C, X_WH))
        L = rotation_levers(S_list, R_WC, p_WC, np.array(points))
        assert np.all(np.diff(L) >= 0) and L[0] > 0

        def rms_turned(axis, data=data, delta=1e-4):
            R = R_WC @ Rotation.from_rotvec(delta * axis).as_matrix()
            rows, rhs = [], []  # R p_C + p_WC - R_WH p_HP_k = p_WH, unknowns (p_WC, p_HP_1, p_HP_2)
            for k, (p_C, X_WH) in enumerate(data):
                for c, X in zip(p_C, X_WH, strict=True):
                    row = np.zeros((3, 9))
                    row[:, 0:3], row[:, 3 + 3 * k: 6 + 3 * k] = np.eye(3), -X[:3, :3]
                    rows.append(row)
                    rhs.append(X[:3, 3] - R @ c)
            A, b = np.vstack(rows), np.concatenate(rhs)
            r = A @ np.linalg.lstsq(A, b, rcond=None)[0] - b
            return math.sqrt(r @ r / (len(b) / 3)) / delta

        axes = Rotation.random(300, random_state=33).as_rotvec()
        measured = [rms_turned(a / np.linalg.norm(a)) for a in axes]
        assert L[0] * 0.999 <= min(measured) <= L[0] * 1.05 and L[2] * 0.95 <= max(measured) <= L[2] * 1.001
        levers[wobble] = L
    assert levers[0.5][0] > 2 * levers[0.05][0]  # wide hand rotations pin the camera's rotation better
    assert np.all(rotation_levers([np.zeros((16, 16))], R_WC, p_WC, points[:1]) == 0)  # no samples


def test_camera_given_points_equals_least_squares_with_the_points_fixed():
    """``camera_given_points``: with ``p_HP`` known, the camera from the statistics alone (closed
    form) is the optimum of a least-squares solver over the samples with only the camera free;
    pure translation of the hand is no obstacle (unlike the 16-unknown problem), a single point
    suffices, and points on a line have no spread."""
    truth = make_truth(31)
    points = [truth.p_HP, truth.p_HP + [0.05, -0.03, 0.1]]
    data, S_list = [], []
    for k, p_HP in enumerate(points):
        p_C, X_WH = make_samples(replace(truth, p_HP=p_HP), 120, noise_m=1e-3, seed=32 + k, rotate=False)
        identifier = EyeToHandIdentifier()
        for c, X in zip(p_C, X_WH, strict=True):
            identifier.add_pose(c, X)
        S_list.append(identifier.core.S)
        data.append((p_C, X_WH, p_HP))

    def residuals(theta):
        R = Rotation.from_rotvec(theta[:3]).as_matrix()
        return np.concatenate([(p_C @ R.T + theta[3:6] - np.einsum("nij,j->ni", X_WH[:, :3, :3], p_HP)
                                - X_WH[:, :3, 3]).ravel() for p_C, X_WH, p_HP in data])

    start = np.concatenate([Rotation.from_matrix(truth.X_WC[:3, :3]).as_rotvec(), truth.X_WC[:3, 3]])
    ls = least_squares(residuals, start, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    R, p_WC, spread = camera_given_points(S_list, np.array(points))
    assert rotation_error_deg(R, Rotation.from_rotvec(ls.x[:3]).as_matrix()) < 1e-6
    assert np.abs(p_WC - ls.x[3:6]).max() < 1e-8
    assert rotation_error_deg(R, truth.X_WC[:3, :3]) < 0.05
    assert np.linalg.norm(p_WC - truth.X_WC[:3, 3]) < 1e-3
    assert 0.1 < spread < 0.4  # the 0.6 m cube's points, off any line
    R1, _, _ = camera_given_points(S_list[:1], np.array(points[:1]))  # one point is enough
    assert rotation_error_deg(R1, truth.X_WC[:3, :3]) < 0.1
    # The hand moving along a line: a turn about it is free, and the spread says so.
    X_line = np.tile(np.eye(4), (50, 1, 1))
    X_line[:, :3, 3] = np.linspace(0.0, 0.3, 50)[:, None] * [1.0, 0.5, 0.2] + [0.4, 0.0, 0.3]
    identifier = EyeToHandIdentifier()
    for X in X_line:
        identifier.add_pose((X[:3, 3] + truth.p_HP - truth.X_WC[:3, 3]) @ truth.X_WC[:3, :3], X)
    assert camera_given_points([identifier.core.S], truth.p_HP[None])[2] < 1e-6
    assert camera_given_points([np.zeros((16, 16))], truth.p_HP[None]) is None
