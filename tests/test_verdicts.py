"""Verdicts that degenerate or mis-scaled data cannot fool (issue 25; identification/observability.py).

Property-based (hypothesis) over random sample streams (``verdict_streams``): degenerate streams
never converge, batch or streaming, and say why; millimetres and left-handed frames never give a
camera; converged results lie within the noise's reach of the truth; bad arrays raise only
IdentificationError. ``SUSTAIN_DRAKE_FUZZ=long`` runs 10,000 streams per property (many minutes).
"""

import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy.spatial.transform import Rotation
from verdict_streams import (
    EYE_DEGENERATE,
    EYE_UNITS_AND_FRAMES,
    PAYLOAD_DEGENERATE,
    eye_stream,
    eye_within_noise,
    payload_stream,
    payload_within_noise,
    stream_eye,
    stream_payload,
)

from sustain_drake.identification import (
    EyeToHandIdentifier,
    IdentificationError,
    PayloadIdentifier,
    calibrate_eye_to_hand,
    identify_payload,
    observability,
)
from sustain_drake.recorded_data import write_points_csv, write_poses_csv

LONG = os.environ.get("SUSTAIN_DRAKE_FUZZ", "") == "long"
FUZZ = settings(max_examples=10_000 if LONG else 150, deadline=None, derandomize=not LONG,
                suppress_health_check=[HealthCheck.too_slow])  # fmt: skip
SEEDS = st.integers(0, 2**32 - 1)

# The reason each kind of stream must give.
EYE_REASONS = {
    "pure_translation": observability.NO_ROTATION, "repeated": observability.NO_ROTATION,
    "single_axis": observability.ONE_AXIS, "two_poses": observability.ONE_AXIS,
    "hand_mm": observability.HAND_NOT_IN_METRES, "points_mm": observability.POINTS_NOT_IN_METRES,
    "both_mm": observability.POINTS_NOT_IN_METRES, "left_handed": observability.LEFT_HANDED,
    "negated": observability.LEFT_HANDED,
}  # fmt: skip


@FUZZ
@given(SEEDS, st.sampled_from(EYE_DEGENERATE + EYE_UNITS_AND_FRAMES))
def test_degenerate_and_mis_scaled_eye_to_hand_streams_never_converge(seed, kind):
    stream = eye_stream(seed, kind)
    result = calibrate_eye_to_hand(stream.p_C, stream.X_WH)
    assert not result.converged
    assert result.verdict.reason.startswith(EYE_REASONS[kind]), result.verdict
    solutions = list(stream_eye(stream))
    assert not any(s.verdict.converged for s in solutions)
    assert solutions[-1].verdict.reason == result.verdict.reason  # the same statistic, the same verdict


@FUZZ
@given(SEEDS, st.sampled_from(PAYLOAD_DEGENERATE))
def test_degenerate_payload_streams_never_converge(seed, kind):
    stream = payload_stream(seed, kind)
    result = identify_payload(stream.wrench, stream.R_WK)
    assert not result.converged
    assert result.verdict.reason.startswith(observability.ONE_ORIENTATION), result.verdict
    assert not any(s.verdict.converged for s in stream_payload(stream))


@FUZZ
@given(SEEDS, st.sampled_from(["excited", "weak"]))
def test_a_converged_camera_is_within_the_noise_of_the_truth(seed, kind):
    """Converged (batch or at any streaming checkpoint) means within 6 sd (Gauss-Newton's, from the
    true noise) of the truth; well-excited streams of 50 samples or more always converge."""
    stream = eye_stream(seed, kind)
    result = calibrate_eye_to_hand(stream.p_C, stream.X_WH)
    if kind == "excited" and len(stream.p_C) >= 50:
        assert result.converged, result.verdict
    if result.converged:
        assert eye_within_noise(stream, result.X_WC, result.p_HP)
    for solution in stream_eye(stream, refine=True):
        if solution.verdict.converged:
            est = solution.estimate
            assert eye_within_noise(stream, est.X_WC, est.p_HP, solution.num_samples)


@FUZZ
@given(SEEDS, st.sampled_from(["excited", "weak"]))
def test_a_converged_payload_is_within_the_noise_of_the_truth(seed, kind):
    stream = payload_stream(seed, kind)
    result = identify_payload(stream.wrench, stream.R_WK)
    if kind == "excited" and len(stream.wrench) >= 50:
        assert result.converged, result.verdict
    if result.converged:
        assert payload_within_noise(stream, result.mass, result.p_KCm)
    for solution in stream_payload(stream):
        if solution.verdict.converged:
            assert payload_within_noise(stream, solution.mass, solution.p_KCm, solution.num_samples)


def test_the_issue_examples():
    """Issue 25's reproductions: a SCARA-like single axis (300 samples, +-1.5 rad about world z,
    +-8 cm, 0.5 mm and 10 um noise) and one payload orientation without noise."""
    rng = np.random.default_rng(25)
    stream = eye_stream(1, "excited", n=300)
    R = Rotation.from_rotvec(np.outer(rng.uniform(-1.5, 1.5, 300), [0, 0, 1])).as_matrix()
    X = np.tile(np.eye(4), (300, 1, 1))
    X[:, :3, :3], X[:, :3, 3] = R, rng.uniform(-0.08, 0.08, (300, 3)) + [0.4, 0.0, 0.3]
    p_W = np.einsum("nij,j->ni", R, stream.p_HP) + X[:, :3, 3]
    for noise in (5e-4, 1e-5):
        p_C = (p_W - stream.X_WC[:3, 3]) @ stream.X_WC[:3, :3] + rng.normal(0, noise, (300, 3))
        verdict = calibrate_eye_to_hand(p_C, X).verdict
        assert str(verdict) == ("not converged: motion not rich enough: the hand rotated about one axis only "
                                "(world z): rotate about another axis")
    payload = payload_stream(3, "one_orientation", n=100)
    tau_f = payload.wrench.copy()
    f = tau_f[:, 3:] = np.einsum("nji,j->ni", payload.R_WK, [0.0, 0.0, payload.mass * 9.81])
    tau_f[:, :3] = np.cross(payload.p_KCm, f)
    verdict = identify_payload(tau_f, payload.R_WK).verdict
    assert verdict.reason.startswith(observability.ONE_ORIENTATION) and verdict.reason.endswith("tilt it")


def test_weakly_determined_is_not_converged_and_names_the_figures():
    """Turns of +-1 deg about every axis, 12 samples, 1 mm noise: the camera would be centimetres off."""
    stream = eye_stream(7, "excited", n=12, noise=1e-3)
    R0 = stream.X_WH[0, :3, :3]
    rng = np.random.default_rng(8)
    stream.X_WH[:, :3, :3] = Rotation.from_rotvec(rng.normal(size=(12, 3)) * 0.02).as_matrix() @ R0
    p_W = np.einsum("nij,j->ni", stream.X_WH[:, :3, :3], stream.p_HP) + stream.X_WH[:, :3, 3]
    p_C = (p_W - stream.X_WC[:3, 3]) @ stream.X_WC[:3, :3] + rng.normal(0, 1e-3, (12, 3))
    verdict = calibrate_eye_to_hand(p_C, stream.X_WH).verdict
    assert verdict.reason.startswith(observability.WEAKLY_DETERMINED), verdict
    assert "camera position" in verdict.reason


def test_every_reason_is_a_distinct_constant():
    assert len(set(observability.REASONS)) == len(observability.REASONS)
    for a in observability.REASONS:
        assert not any(b != a and b.startswith(a) for b in observability.REASONS)


@pytest.mark.parametrize(("kind", "reason"), [("hand_mm", observability.HAND_NOT_IN_METRES),
                                              ("left_handed", observability.LEFT_HANDED)])
def test_the_calibrate_command_exits_3_with_the_reason_on_one_line(tmp_path, kind, reason):
    stream = eye_stream(11, kind, n=60, noise=5e-4)
    (tmp_path / "p.csv").write_text(write_points_csv(stream.p_C))
    (tmp_path / "q.csv").write_text(write_poses_csv(stream.X_WH))
    out = tmp_path / "result.yaml"
    command = ["calibrate", "eye-to-hand", "--points", tmp_path / "p.csv", "--poses", tmp_path / "q.csv",
               "--out", out]  # fmt: skip
    r = subprocess.run([sys.executable, "-m", "sustain_drake.cli.main", *map(str, command)],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert r.returncode == 3, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"sustain-drake: not converged: {reason}")
    assert not out.exists()
    assert "X_WC" not in r.stdout  # never a camera from such data


def test_the_covariances_are_calibrated():
    """Over 200 random well-excited streams the squared Mahalanobis error under the batch results'
    covariance averages its degrees of freedom (9: camera turn, camera, p_HP; 4: mass, p_KCm);
    bench/bench_verdicts.py counts the 95 % regions' coverage over 1,000."""
    eye, payload = [], []
    for seed in range(200):
        s = eye_stream(seed, "excited", n=100, noise=1e-3)
        r = calibrate_eye_to_hand(s.p_C, s.X_WH)
        turn = Rotation.from_matrix(r.X_WC[:3, :3].T @ s.X_WC[:3, :3]).as_rotvec()
        d = np.concatenate([turn, s.X_WC[:3, 3] - r.X_WC[:3, 3], s.p_HP - r.p_HP])
        eye.append(d @ np.linalg.solve(r.covariance, d))
        q = payload_stream(seed, "excited", n=100, noise=(0.02, 5e-4))
        r = identify_payload(q.wrench, q.R_WK)
        d = np.concatenate([[r.mass - q.mass], r.p_KCm - q.p_KCm])
        payload.append(d @ np.linalg.solve(r.covariance, d))
    assert 9.0 - 1.2 <= np.mean(eye) <= 9.0 + 1.2  # +-4 standard errors of the mean of chi2(9)
    assert 4.0 - 0.8 <= np.mean(payload) <= 4.0 + 0.8


def test_the_calibrate_command_prints_the_standard_errors(tmp_path):
    import io
    from pathlib import Path

    from sustain_drake.cli.calibrate import run_eye_to_hand
    from sustain_drake.identification.eye_to_hand import default_criteria

    data = Path(__file__).parent / "data" / "jin_eyetobase_rvc_single"
    out = io.StringIO()
    assert run_eye_to_hand(data / "corner_points.csv", data / "poses.csv", None, default_criteria(), out) == 0
    line = next(t for t in out.getvalue().splitlines() if t.startswith("1 sd"))
    assert "camera position 0.689 mm" in line and "p_HP 0.296 mm" in line


# ---- bad arrays: IdentificationError only ------------------------------------------------------
BAD = st.one_of(
    st.none(), st.text(max_size=5), st.floats(allow_nan=True), st.integers(),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=8),
    st.lists(st.lists(st.floats(-1e3, 1e3), max_size=5), max_size=5),
    hnp.arrays(np.float64, hnp.array_shapes(min_dims=0, max_dims=4, max_side=5),
               elements=st.floats(allow_nan=True, allow_infinity=True)),
)  # fmt: skip


def _only_identification_errors(call):
    try:
        call()
    except IdentificationError as e:
        assert "\n" not in str(e)


@settings(max_examples=10_000 if LONG else 150, deadline=None, derandomize=not LONG,
          suppress_health_check=[HealthCheck.too_slow])  # fmt: skip
@given(BAD, st.integers(0, 5))
def test_bad_arrays_raise_only_identification_errors(bad, where):
    stream = eye_stream(3, "excited", n=20)
    payload = payload_stream(3, "excited", n=20)
    calls = [
        lambda: calibrate_eye_to_hand(bad, stream.X_WH), lambda: calibrate_eye_to_hand(stream.p_C, bad),
        lambda: identify_payload(bad, payload.R_WK), lambda: identify_payload(payload.wrench, bad),
        lambda: EyeToHandIdentifier().add(stream.p_C[0], bad, stream.X_WH[0, :3, 3]),
        lambda: PayloadIdentifier().add(payload.wrench[0], bad),
    ]  # fmt: skip
    _only_identification_errors(calls[where])


@FUZZ
@given(SEEDS)
def test_streaming_add_refuses_a_matrix_that_is_not_a_rotation(seed):
    rng = np.random.default_rng(seed)
    stream = eye_stream(seed, "excited", n=12)
    identifier = EyeToHandIdentifier()
    for c, X in zip(stream.p_C, stream.X_WH, strict=True):
        identifier.add(c, X[:3, :3], X[:3, 3])
    state = identifier.state
    M = stream.X_WH[0, :3, :3] @ np.diag(rng.choice([-1.0, 1.0], 3))
    bad = [M if np.linalg.det(M) < 0 else -M, 1.01 * M, M + rng.normal(0, 1e-3, (3, 3)), np.zeros((3, 3))]
    for R in bad:
        with pytest.raises(IdentificationError, match="R_WH"):
            identifier.add(stream.p_C[0], R, stream.X_WH[0, :3, 3])
    assert np.array_equal(identifier.state, state)
