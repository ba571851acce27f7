"""Static payload formulation (§4.4): mass and centre of mass from quasi-static wrenches."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from sustain_drake.identification import (
    IdentificationError,
    PayloadIdentifier,
    identify_payload,
    observability,
)
from sustain_drake.identification.payload import STANDARD_GRAVITY_W, build_A


def make_wrenches(mass, p_KCm, n, seed=0, force_noise=0.0, torque_noise=0.0, orientations=None):
    """Wrenches [tau; f] applied by the sensor on the payload, at rest, in K (see payload.py)."""
    rng = np.random.default_rng(seed)
    R_WK = Rotation.random(n, random_state=rng).as_matrix() if orientations is None else orientations
    f_K = np.einsum("nji,j->ni", R_WK, -mass * STANDARD_GRAVITY_W)  # R_KW (-m g_W)
    tau_K = np.cross(p_KCm, f_K)
    f_K = f_K + rng.normal(0.0, force_noise, f_K.shape)
    tau_K = tau_K + rng.normal(0.0, torque_noise, tau_K.shape)
    return np.hstack([tau_K, f_K]), R_WK


def test_sign_convention_at_rest():
    """At rest the sensor holds the payload up: R_WK f_K = -m g_W, and A_t x = 0 exactly."""
    wrench, R = make_wrenches(0.6, np.array([0.01, -0.02, 0.08]), 1)
    assert (R[0] @ wrench[0, 3:])[2] == pytest.approx(0.6 * 9.81)
    x = np.array([1 / 0.6, 0.01, -0.02, 0.08, 1.0])
    assert np.abs(build_A(wrench[0], R[0], STANDARD_GRAVITY_W) @ x).max() < 1e-12


def test_noise_free_is_exact():
    p = np.array([0.02, -0.01, 0.12])
    wrench, R = make_wrenches(0.594, p, 30)
    result = identify_payload(wrench, R)
    assert result.converged, result.verdict
    assert result.mass == pytest.approx(0.594, rel=1e-9)
    assert np.abs(result.p_KCm - p).max() < 1e-9
    assert result.force_residuals.max() < 1e-9 and result.torque_residuals.max() < 1e-9


def test_mini40_noise():
    p = np.array([0.02, -0.01, 0.12])
    wrench, R = make_wrenches(0.6, p, 200, seed=1, force_noise=0.02, torque_noise=5e-4)
    result = identify_payload(wrench, R)
    assert result.converged, result.verdict
    assert abs(result.mass - 0.6) / 0.6 < 0.01
    assert np.linalg.norm(result.p_KCm - p) < 2e-3


def test_one_orientation_is_not_converged():
    """With gravity fixed in K, the centre of mass along it is unobservable."""
    R = np.tile(Rotation.from_euler("xyz", [0.3, -0.2, 1.0]).as_matrix(), (50, 1, 1))
    wrench, R = make_wrenches(0.6, np.array([0.0, 0.0, 0.1]), 50, force_noise=0.02, torque_noise=5e-4,
                              orientations=R)  # fmt: skip
    result = identify_payload(wrench, R)
    assert not result.converged
    assert result.verdict.reason.startswith(observability.ONE_ORIENTATION), result.verdict.reason


def test_wrong_wrench_sign_is_not_converged():
    wrench, R = make_wrenches(0.6, np.array([0.0, 0.01, 0.1]), 40)
    result = identify_payload(-wrench, R)
    assert not result.converged
    assert "not positive" in result.verdict.reason


def test_streaming_identifier_and_clone():
    wrench, R = make_wrenches(1.2, np.array([0.0, 0.05, 0.02]), 40, seed=3)
    ident = PayloadIdentifier()
    for w, r in zip(wrench, R, strict=True):
        ident.add(w, r)
    clone = PayloadIdentifier()
    clone.set_state(ident.state)
    a = ident.solve()
    assert a.mass == pytest.approx(1.2, rel=1e-9)
    assert clone.solve().mass == a.mass
    assert ident.sample_error(wrench[0], R[0], a.x) < 1e-20
    ident.reset()
    assert not ident.solve().verdict and ident.solve().verdict.reason == "no samples"


def test_input_errors():
    wrench, R = make_wrenches(0.6, np.zeros(3), 5)
    with pytest.raises(IdentificationError, match=r"wrench_K must have shape \(n, 6\)"):
        identify_payload(wrench[:, :5], R)
    with pytest.raises(IdentificationError, match="pair one to one"):
        identify_payload(wrench, R[:4])
    R_bad = R.copy()
    R_bad[2] *= 2.0
    with pytest.raises(IdentificationError, match=r"R_WK\[2\] is not a rotation"):
        identify_payload(wrench, R_bad)
    with pytest.raises(ValueError, match="gravity_W"):
        PayloadIdentifier(gravity_W=[0.0, 0.0, 0.0])


finite = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None)
@given(
    samples=st.lists(
        st.tuples(
            st.lists(st.one_of(finite, st.floats()), min_size=6, max_size=6),
            st.lists(finite, min_size=4, max_size=4),
        ),
        max_size=20,
    )
)
def test_random_streams_never_give_nan(samples):
    ident = PayloadIdentifier()
    for w, q in samples:
        q = np.array(q)
        R = Rotation.from_quat(q).as_matrix() if np.linalg.norm(q) > 1e-6 else np.eye(3)
        try:
            ident.add(np.array(w), R)
        except IdentificationError:
            assert not np.all(np.isfinite(w)) or max(map(abs, w)) >= 1e100
        solution = ident.solve()
        assert np.all(np.isfinite(solution.eigenvalues))
        assert np.isfinite(solution.mass) and np.all(np.isfinite(solution.p_KCm))
        assert not np.isnan(solution.expected_mse)
        assert isinstance(solution.verdict.converged, bool)
