"""The lazy solve of the formulations' identifiers (issue #24): a solution is computed once per
change of the statistic, and it is the same, to the last bit, as solving after every sample."""

import numpy as np
import pytest
from scipy.linalg import lapack
from scipy.spatial.transform import Rotation

from sustain_drake.identification import EyeToHandIdentifier, PayloadIdentifier, SustainableIdentifier
from sustain_drake.identification.eye_to_hand import build_A, conditioning_transform, default_criteria
from sustain_drake.identification.rotation import project_to_rotation


def eye_samples(n, seed=0, noise=1e-3):
    rng = np.random.default_rng(seed)
    R = Rotation.random(n, random_state=rng).as_matrix()
    p = rng.uniform(-0.3, 0.3, (n, 3)) + [0.4, 0.0, 0.3]
    R_WC = Rotation.random(random_state=rng).as_matrix()
    p_WC, p_HP = np.array([0.5, -0.4, 1.0]), np.array([0.0, 0.02, 0.2])
    c = (np.einsum("nij,j->ni", R, p_HP) + p - p_WC) @ R_WC + rng.normal(0, noise, (n, 3))
    return c, R, p


def payload_samples(n, seed=0):
    rng = np.random.default_rng(seed)
    R = Rotation.random(n, random_state=rng).as_matrix()
    mass, p_KCm = 0.6, np.array([0.01, -0.02, 0.08])
    f = np.einsum("nji,j->ni", R, [0.0, 0.0, mass * 9.81])
    tau = np.cross(p_KCm, f) + rng.normal(0, 5e-4, (n, 3))
    return np.hstack([tau, f + rng.normal(0, 0.02, (n, 3))]), R


def assert_same_solution(a, b):
    """Every number of two solutions is bit for bit the same."""
    assert a.num_samples == b.num_samples and a.verdict == b.verdict
    assert np.array_equal(a.eigenvalues, b.eigenvalues)
    assert np.array_equal(a.eigen.v_N, b.eigen.v_N) and np.array_equal(a.eigen.direction, b.eigen.direction)
    assert a.eigen.num_null == b.eigen.num_null
    assert np.array_equal(a.x, b.x) and a.expected_mse == b.expected_mse and a.ssd == b.ssd


def count_eigen_calls(identifier, monkeypatch):
    calls = []
    core = identifier.core
    original = core.eigen
    monkeypatch.setattr(core, "eigen", lambda *args: calls.append(1) or original(*args))
    return calls


def test_eye_to_hand_lazy_equals_eager_bit_for_bit():
    c, R, p = eye_samples(60)
    eager, lazy = EyeToHandIdentifier(), EyeToHandIdentifier()
    for i in range(60):
        eager.add(c[i], R[i], p[i])
        last = eager.solve(refine_estimate=False)
        lazy.add(c[i], R[i], p[i])
    assert np.array_equal(eager.state, lazy.state)
    once = lazy.solve(refine_estimate=False)
    assert_same_solution(last, once)
    assert np.array_equal(last.projected.R_WC, once.projected.R_WC)
    assert once.verdict.converged
    refined_eager, refined_lazy = eager.solve(), lazy.solve()
    assert np.array_equal(refined_eager.refined.x, refined_lazy.refined.x)
    assert refined_eager.refined.mean_squared_error == refined_lazy.refined.mean_squared_error


def test_eye_to_hand_solve_is_the_reference_computation_bit_for_bit():
    """The solve's fewer calls keep the arithmetic of the plain formulas: S = sum A^T A,
    C' = T^T S T / n, dsyev, T v_N, and the SVD projection of §3.2."""
    c, R, p = eye_samples(40, seed=1)
    ident = EyeToHandIdentifier()
    S = np.zeros((16, 16))
    for i in range(40):
        ident.add(c[i], R[i], p[i])
        A = build_A(c[i], R[i], p[i])
        S += A.T @ A
    assert np.array_equal(ident.core.S, S)
    T = conditioning_transform(S)
    w, V, info = lapack.dsyev((T.T @ S @ T).T)
    assert info == 0
    direction = T @ V[:, 0]
    proj = project_to_rotation(direction[:9])
    solution = ident.solve(refine_estimate=False)
    assert np.array_equal(solution.eigenvalues, w[::-1] * (1.0 / 40))
    assert np.array_equal(solution.eigen.direction, direction)
    assert np.array_equal(solution.projected.R_WC, proj.R)
    assert solution.scale == proj.scale and solution.ssd == proj.ssd
    assert np.array_equal(solution.x, proj.scale * direction)


def test_eye_to_hand_reads_without_a_new_sample_do_not_recompute(monkeypatch):
    c, R, p = eye_samples(30, seed=2)
    ident = EyeToHandIdentifier()
    calls = count_eigen_calls(ident, monkeypatch)
    for i in range(20):
        ident.add(c[i], R[i], p[i])
    assert calls == []  # adding never solves
    first = ident.solve(refine_estimate=False)
    assert ident.solve(refine_estimate=False) is first
    assert len(calls) == 1
    # The refinement is run once, on the cached solution, and not run again.
    refined = ident.solve()
    assert refined.refined is not None and refined.projected is first.projected
    assert ident.solve() is refined and ident.solve(refine_estimate=False) is first
    assert len(calls) == 1
    # Every change of the statistic or of the criteria makes the cache stale.
    ident.add(c[20], R[20], p[20])
    second = ident.solve(refine_estimate=False)
    assert second is not first and second.num_samples == 21 and len(calls) == 2
    ident.set_state(ident.state)
    assert ident.solve(refine_estimate=False) is not second and len(calls) == 3
    ident.criteria = default_criteria()
    assert len(calls) == 3
    ident.solve(refine_estimate=False)
    assert len(calls) == 4
    ident.reset()
    empty = ident.solve()
    assert empty.num_samples == 0 and empty.verdict.reason == "no samples"


def test_eye_to_hand_refined_first_then_unrefined_matches_a_fresh_solve():
    c, R, p = eye_samples(30, seed=3)
    a, b = EyeToHandIdentifier(), EyeToHandIdentifier()
    for i in range(30):
        a.add(c[i], R[i], p[i])
        b.add(c[i], R[i], p[i])
    refined = a.solve()
    unrefined = a.solve(refine_estimate=False)
    assert unrefined.refined is None and unrefined.estimate is unrefined.projected
    assert_same_solution(unrefined, b.solve(refine_estimate=False))
    assert np.array_equal(refined.x, b.solve().x)


def test_payload_lazy_equals_eager_and_caches(monkeypatch):
    wrench, R = payload_samples(50)
    eager, lazy = PayloadIdentifier(), PayloadIdentifier()
    for i in range(50):
        eager.add(wrench[i], R[i])
        last = eager.solve()
        lazy.add(wrench[i], R[i])
    calls = count_eigen_calls(lazy, monkeypatch)
    once = lazy.solve()
    assert_same_solution(last, once)
    assert once.mass == last.mass and np.array_equal(once.p_KCm, last.p_KCm)
    assert once.mass == pytest.approx(0.6, rel=0.02)
    assert lazy.solve() is once and len(calls) == 1
    lazy.add(wrench[0], R[0])
    assert lazy.solve() is not once and len(calls) == 2


def test_eye_to_hand_add_writes_build_A():
    c, R, p = eye_samples(5, seed=4)
    ident, core = EyeToHandIdentifier(), SustainableIdentifier(16)
    for i in range(5):
        ident.add(list(c[i]), R[i].tolist(), p[i])
        core.add(build_A(c[i], R[i], p[i]))
    assert np.array_equal(ident.state, core.state)
    with pytest.raises(ValueError):
        ident.add(c[0].reshape(3, 1), R[0], p[0])  # a column would broadcast wrongly: refused
    assert np.array_equal(ident.state, core.state)


@pytest.mark.parametrize("dtype", [np.float32, np.int64])
def test_core_add_other_dtypes_and_large_entries_take_the_checked_path(dtype):
    """Samples the fast path does not take (another dtype, entries large enough that A^T A could
    overflow) give the same statistic as the plain ``S += A.T @ A``."""
    rng = np.random.default_rng(5)
    ident, S = SustainableIdentifier(4), np.zeros((4, 4))
    for A in ((rng.normal(size=(3, 4)) * 100).astype(dtype), rng.normal(size=(3, 4)) * 1e151):
        ident.add(A)
        S += A.T @ A
    assert np.all(np.isfinite(S)) and np.abs(S).max() > 1e300
    assert np.array_equal(ident.S, S) and ident.num_samples == 2 and ident.weight == 2.0
