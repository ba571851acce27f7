"""Real fixed-3-D-camera data (Jin et al., see tests/data/jin_eyetobase_rvc_single/PROVENANCE.md)."""

from pathlib import Path

import numpy as np
import pytest
from eye_to_hand_data import rotation_error_deg

from sustain_drake.identification import calibrate_eye_to_hand
from sustain_drake.recorded_data import read_points_csv, read_poses_csv

DATA = Path(__file__).parent / "data" / "jin_eyetobase_rvc_single"


@pytest.fixture(scope="module")
def poses():
    return read_poses_csv(DATA / "poses.csv")


def points(name):
    return read_points_csv(DATA / f"{name}_points.csv")


def test_fixture_shape(poses):
    assert poses.shape == (50, 4, 4)
    for name in ("corner", "aruco10", "aruco14"):
        assert points(name).shape == (50, 3)


def test_chessboard_corner(poses):
    result = calibrate_eye_to_hand(points("corner"), poses)
    assert result.converged, result.verdict
    assert result.rms <= 0.6e-3
    # The provenance's independent fit: camera at about (-145, -491, 951) mm.
    assert np.abs(result.X_WC[:3, 3] * 1e3 - [-145, -491, 951]).max() < 2.0


@pytest.mark.parametrize("code", ["aruco10", "aruco14"])
def test_each_aruco_code(poses, code):
    result = calibrate_eye_to_hand(points(code), poses)
    assert result.converged, result.verdict
    assert result.rms <= 4.5e-3


def test_the_two_codes_agree(poses):
    a = calibrate_eye_to_hand(points("aruco10"), poses).X_WC
    b = calibrate_eye_to_hand(points("aruco14"), poses).X_WC
    assert np.linalg.norm(a[:3, 3] - b[:3, 3]) <= 3e-3
    assert rotation_error_deg(a[:3, :3], b[:3, :3]) <= 0.2


def test_shuffled_rows_same_answer(poses):
    p = points("corner")
    order = np.random.default_rng(0).permutation(len(p))
    a = calibrate_eye_to_hand(p, poses)
    b = calibrate_eye_to_hand(p[order], poses[order])
    assert np.abs(a.X_WC - b.X_WC).max() < 1e-9
    assert np.abs(a.p_HP - b.p_HP).max() < 1e-9
    assert np.allclose(a.residuals[order], b.residuals, atol=1e-9)


@pytest.mark.parametrize(("i", "j"), [(3, 17), (0, 49), (20, 21)])
def test_swapped_pair_is_singled_out(poses, i, j):
    """Two samples' poses swapped (images and poses mis-paired): their residuals are the largest."""
    p = points("corner")
    swapped = poses.copy()
    swapped[[i, j]] = swapped[[j, i]]
    result = calibrate_eye_to_hand(p, swapped)
    top_two = set(np.argsort(result.residuals)[-2:].tolist())
    assert top_two == {i, j}
    others = np.delete(result.residuals, [i, j])
    assert min(result.residuals[i], result.residuals[j]) > 3 * others.max()
