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


def test_the_three_points_jointly(poses):
    """The corner and the two codes at once (``all_points.csv``): converged; the camera is the
    corner's within 0.5 mm and 0.05 deg (it weighs about 64 times a code: 0.5 mm against 4 mm of
    noise), each code's own camera is within 2 of its own 1 sd of the joint one (measured 5.8 and
    7.3 mm for 5.5 mm), and every point fits the joint camera within 5 % of its own RMS."""
    from sustain_drake.identification import calibrate_eye_to_hand_points
    from sustain_drake.recorded_data import read_point_tracks_csv

    tracks = read_point_tracks_csv(DATA / "all_points.csv", num_samples=len(poses))
    result = calibrate_eye_to_hand_points(tracks.points, poses)
    assert result.converged, result.verdict
    assert result.labels == ("corner", "aruco10", "aruco14") and result.labels[result.seed] == "corner"
    corner = calibrate_eye_to_hand(points("corner"), poses)
    assert np.linalg.norm(result.X_WC[:3, 3] - corner.X_WC[:3, 3]) <= 0.5e-3
    assert rotation_error_deg(result.X_WC[:3, :3], corner.X_WC[:3, :3]) <= 0.05
    for k, name in enumerate(result.labels):
        alone = result.single[k]
        assert alone.converged and alone.rms <= result.rms[k] <= 1.05 * alone.rms
        rotation, position, _ = alone.standard_errors
        offset = result.single_offsets()[k]
        assert offset[0] <= 2.0 * position and offset[1] <= 2.0 * rotation, name
    assert 40.0 <= result.weights[0] / result.weights[1:].max() <= 100.0
    rotation, position, point_errors = result.standard_errors
    assert position <= corner.standard_errors[1] and point_errors.max() <= 1e-3
