"""The §3.1 core: constant memory, the eigen-solution, forgetting, reset and state round trips."""

import tracemalloc

import numpy as np
import pytest

from sustain_drake.identification import IdentificationError, SustainableIdentifier
from sustain_drake.identification.sustainable_identifier import ConvergenceCriteria, judge


def random_A(rng, x_true, noise=0.0):
    """A 3 x N sample with A x_true = 0 (+ noise): rows projected off x_true."""
    A = rng.normal(size=(3, len(x_true)))
    A -= np.outer(A @ x_true, x_true) / (x_true @ x_true)
    return A + noise * rng.normal(size=A.shape)


def test_null_vector_and_mean_squared_error():
    rng = np.random.default_rng(0)
    x_true = rng.normal(size=6)
    ident = SustainableIdentifier(6)
    samples = [random_A(rng, x_true, noise=1e-3) for _ in range(200)]
    for A in samples:
        ident.add(A)
    eig = ident.eigen()
    v = eig.v_N
    cos = abs(v @ x_true) / np.linalg.norm(x_true)
    assert cos > 1 - 1e-5
    # Eq. (3)/(13): lambda_N is the mean squared error of the unit minimiser.
    direct = np.mean([np.sum((A @ v) ** 2) for A in samples])
    assert eig.lambda_N == pytest.approx(direct, rel=1e-9)
    assert ident.mean_squared_error(v) == pytest.approx(direct, rel=1e-9)
    assert np.all(np.diff(eig.eigenvalues) <= 0)  # descending
    # Same as a batch eigen-decomposition of the stacked samples' normal matrix.
    C = sum(A.T @ A for A in samples) / len(samples)
    assert np.allclose(eig.eigenvalues, np.linalg.eigvalsh(C)[::-1], rtol=1e-9, atol=1e-15)


def test_sample_error_is_eq2():
    A = np.arange(12.0).reshape(3, 4)
    x = np.array([1.0, -1.0, 0.5, 2.0])
    assert SustainableIdentifier.sample_error(A, x) == pytest.approx(np.sum((A @ x) ** 2))


def test_memory_does_not_grow_with_samples():
    rng = np.random.default_rng(1)
    ident = SustainableIdentifier(16)
    A = rng.normal(size=(3, 16))
    size = ident.state_size
    for _ in range(100):
        ident.add(A)
    tracemalloc.start()
    before, _ = tracemalloc.get_traced_memory()
    for _ in range(20000):
        ident.add(A)
    after, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert ident.state_size == size == 16 * 16 + 2
    assert after - before < 4096  # bytes: no per-sample growth (20000 samples would be MBs)
    assert ident.num_samples == 20100


def test_forgetting_factor_weights_recent_samples():
    rng = np.random.default_rng(2)
    x_old, x_new = rng.normal(size=5), rng.normal(size=5)
    ident = SustainableIdentifier(5, forgetting_factor=0.9)
    for _ in range(300):
        ident.add(random_A(rng, x_old))
    for _ in range(300):
        ident.add(random_A(rng, x_new))
    v = ident.eigen().v_N
    assert abs(v @ x_new) / np.linalg.norm(x_new) > 1 - 1e-6
    assert ident.weight == pytest.approx(1 / (1 - 0.9), rel=1e-6)  # saturates at 1/(1-f)
    assert ident.num_samples == 600
    plain = SustainableIdentifier(5)
    for _ in range(3):
        plain.add(random_A(rng, x_old))
    assert plain.weight == 3.0


def test_reset_and_state_round_trip():
    rng = np.random.default_rng(3)
    ident = SustainableIdentifier(4)
    for _ in range(10):
        ident.add(rng.normal(size=(2, 4)))
    clone = SustainableIdentifier(4)
    clone.set_state(ident.state)
    assert np.array_equal(clone.eigen().eigenvalues, ident.eigen().eigenvalues)
    ident.reset()
    assert ident.num_samples == 0 and ident.eigen() is None
    with pytest.raises(ValueError, match="state must have shape"):
        clone.set_state(np.zeros(3))


def test_non_finite_sample_is_rejected_and_state_unchanged():
    ident = SustainableIdentifier(3)
    ident.add(np.eye(3)[:2])
    state = ident.state
    for bad in (np.nan, np.inf, 1e200):
        A = np.ones((2, 3))
        A[0, 1] = bad
        with pytest.raises(IdentificationError, match="not finite"):
            ident.add(A)
        assert np.array_equal(ident.state, state)
    with pytest.raises(IdentificationError, match="columns"):
        ident.add(np.ones((2, 4)))


def test_invalid_construction():
    with pytest.raises(ValueError, match="forgetting_factor"):
        SustainableIdentifier(4, forgetting_factor=0.0)
    with pytest.raises(ValueError, match="num_unknowns"):
        SustainableIdentifier(1)
    with pytest.raises(ValueError, match="max_expected_rms"):
        ConvergenceCriteria(max_expected_rms=float("nan"))


def test_verdict_never_from_lambda_N_alone():
    """Too few / too similar samples: lambda_N is 0 because the null space is many-dimensional."""
    ident = SustainableIdentifier(6)
    A = np.random.default_rng(4).normal(size=(3, 6))
    for _ in range(50):
        ident.add(A)  # the same sample over and over: rank 3, null space 3-dimensional
    eig = ident.eigen()
    assert eig.lambda_N == pytest.approx(0.0, abs=1e-12)
    assert eig.num_null == 3
    criteria = ConvergenceCriteria(max_expected_rms=1.0, max_ssd=None)
    verdict = judge(criteria, 50, eig, expected_rms=0.0, constraint_problem=None)
    assert not verdict
    assert "null space is 3-dimensional" in verdict.reason
