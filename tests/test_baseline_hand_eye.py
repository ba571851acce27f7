"""The marker-based baseline (issue 26, item 1): the held ChArUco board, its detection in the
station's images, and OpenCV's hand-eye solvers fed the way a fixed camera needs."""

import re
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlant
from scipy.spatial.transform import Rotation

from sustain_drake.identification.opencv_hand_eye import (
    HAND_EYE_METHODS,
    ROBOT_WORLD_METHODS,
    eye_to_hand,
    invert,
    pose_error,
    robot_world_eye_to_hand,
)
from sustain_drake.perception.charuco import (
    BoardView,
    CharucoFinder,
    camera_matrix,
    corner_points,
    measure_board,
    pnp_pose,
    rigid_fit,
)
from sustain_drake.perception.optical_flow import PinholeIntrinsics
from sustain_drake.recorded_data import read_poses_csv
from sustain_drake.station import load_scenario
from sustain_drake.station.models import make_parser, model_file, models_dir

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT / "models"))
import baseline_scene  # noqa: E402
import bench_baseline_hand_eye  # noqa: E402
import generate_charuco_board  # noqa: E402

INTRINSICS = PinholeIntrinsics(640, 480, 579.41, 579.41, 319.5, 239.5)


def pose(rotvec, p) -> np.ndarray:
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = Rotation.from_rotvec(rotvec).as_matrix(), p
    return X


def test_the_committed_board_files_are_the_generators():
    """Texture, plate and SDF are what models/generate_charuco_board.py writes (re-made by it)."""
    png = cv2.cvtColor(cv2.imread(str(models_dir() / "meshes" / "charuco_board.png")), cv2.COLOR_BGR2RGB)
    np.testing.assert_array_equal(png, generate_charuco_board.texture())
    assert (models_dir() / "meshes" / "charuco_board.obj").read_text() == generate_charuco_board.plate_obj()
    assert (models_dir() / "charuco_board_tool.sdf").read_text() == generate_charuco_board.tool_sdf()


def test_the_texture_holds_the_board_where_the_board_frame_says():
    """Every corner of the printed texture is found at its board point (margin + p_B / texel, the
    pixel centres at integers), so the plate's texture mapping puts corner i at p_BQ[i]."""
    ids, px = CharucoFinder().detect(generate_charuco_board.texture())
    assert list(ids) == list(range(24))
    expected = (generate_charuco_board.MARGIN + corner_points()[:, :2]) / generate_charuco_board.TEXEL - 0.5
    np.testing.assert_allclose(px, expected, atol=0.05)


def test_the_board_model_loads_in_a_plant():
    plant = MultibodyPlant(0.0)
    make_parser(plant).AddModels(model_file("charuco_board_tool.sdf"))
    plant.Finalize()
    context = plant.CreateDefaultContext()
    tool = plant.GetBodyByName("tool")
    assert 0.2 < tool.default_mass() < 0.3
    assert tool.default_rotational_inertia().CouldBePhysicallyValid()
    X_TB = plant.GetFrameByName("charuco").CalcPose(context, tool.body_frame())
    # The printed face's outward normal (-z of B) is 45 degrees from T's z towards -x.
    np.testing.assert_allclose(-X_TB.rotation().matrix()[:, 2], [-np.sqrt(0.5), 0.0, np.sqrt(0.5)],
                               atol=1e-9)
    X_BQ = X_TB.inverse() @ plant.GetFrameByName("tracked_point").CalcPose(context, tool.body_frame())
    np.testing.assert_allclose(X_BQ.translation(), corner_points()[generate_charuco_board.TRACKED_CORNER],
                               atol=1e-8)


@pytest.fixture(scope="module")
def scene():
    return baseline_scene.BoardScene(load_scenario(ROOT / "diagrams" / "hand_eye.yaml"))


def test_the_station_renders_the_held_board_and_it_is_measured(scene):
    """At the initial posture the board faces the head camera: at least 20 of its 24 corners are
    found, both board poses are within 2 mm / 0.3 deg of the truth and the corners' depth points
    within a few depth-noise sigmas of the true corners."""
    q0 = scene.joint_ranges()[2]
    shot = scene.shot(q0, 0.0)
    view = measure_board(scene.finder, shot.color, shot.depth, scene.intrinsics)
    assert len(view.ids) >= 20
    X_CB = np.linalg.inv(scene.X_WC) @ shot.X_WB
    for X in (view.X_CB_pnp, view.X_CB_depth):
        position, rotation = pose_error(X, X_CB)
        assert position < 0.002 and np.degrees(rotation) < 0.3
    p_true = corner_points()[view.ids] @ X_CB[:3, :3].T + X_CB[:3, 3]
    errors = np.linalg.norm(view.p_CQ - p_true, axis=1)
    assert np.median(errors) < 0.0025 and errors.max() < 0.005
    assert scene.tracked_corner() == generate_charuco_board.TRACKED_CORNER


def test_the_stops_are_the_babblings_moves_at_its_pace(scene):
    """Each stop ends a move of max(min_duration, 15/8 max|dq| / max_speed) and a SETTLE s rest,
    within the generator's update period: the collect time's model."""
    lower, upper, q0 = scene.joint_ranges()
    stops = baseline_scene.babbling_stops(scene.scenario, lower, upper, q0, 6)
    motion, previous, t = scene.scenario.motion, q0, 0.0
    for stop in stops:
        assert np.all(stop.q >= lower) and np.all(stop.q <= upper)
        move = max(motion.min_duration, 15 / 8 * np.max(np.abs(stop.q - previous)) / motion.max_speed)
        assert stop.time - t == pytest.approx(move + baseline_scene.SETTLE, abs=2.5 * motion.period)
        previous, t = stop.q, stop.time


def synthetic_views(count: int, seed: int = 0):
    """A camera ``X_WC``, a board in the hand ``X_HB`` and ``count`` hand poses with the board in
    front of the camera, 0.6-1.0 m away, turned by up to 40 degrees."""
    rng = np.random.default_rng(seed)
    X_WC = pose([1.2, -1.1, 1.3], [1.37, 0.02, 0.57])
    X_HB = pose([2.2, 0.3, -0.4], [-0.07, -0.08, 0.2])
    X_CB = [pose(rng.uniform(-0.4, 0.4, 3), [*rng.uniform(-0.15, 0.15, 2), rng.uniform(0.6, 1.0)])
            @ pose([0, 0, 0], [-0.075, -0.105, 0.0]) for _ in range(count)]
    X_WH = np.array([X_WC @ X @ invert(X_HB) for X in X_CB])
    return X_WC, X_HB, X_WH, np.array(X_CB)


def test_the_opencv_pipeline_recovers_a_known_camera():
    """Noise-free: corners projected with the intrinsics, board poses by solvePnP, the camera by
    every solver to < 1 mm and 0.01 deg (and the board in the hand by the robot-world ones)."""
    X_WC, X_HB, X_WH, X_CB = synthetic_views(12)
    p_BQ, K = corner_points(), camera_matrix(INTRINSICS)
    measured = []
    for X in X_CB:
        p_C = p_BQ @ X[:3, :3].T + X[:3, 3]
        px = (p_C @ K.T)[:, :2] / p_C[:, 2:]
        measured.append(pnp_pose(p_BQ, px, INTRINSICS))
    measured = np.array(measured)
    for method in HAND_EYE_METHODS:
        position, rotation = pose_error(eye_to_hand(X_WH, measured, method), X_WC)
        assert position < 0.001 and np.degrees(rotation) < 0.01, method
    for method in ROBOT_WORLD_METHODS:
        X_WC_est, X_HB_est = robot_world_eye_to_hand(X_WH, measured, method)
        for estimate, truth in ((X_WC_est, X_WC), (X_HB_est, X_HB)):
            position, rotation = pose_error(estimate, truth)
            assert position < 0.001 and np.degrees(rotation) < 0.01, method


def test_the_hand_poses_must_be_inverted_for_a_fixed_camera():
    """The check above can fail: the hand poses passed the other way round (gripper-to-base, as
    for a camera on the hand) give no camera near the truth."""
    X_WC, _, X_WH, X_CB = synthetic_views(12)
    for method in HAND_EYE_METHODS:
        position, _ = pose_error(eye_to_hand(invert(X_WH), X_CB, method), X_WC)
        assert position > 0.1, method


def test_a_rigid_fit_recovers_a_transform_and_refuses_a_line():
    X = pose([0.3, -0.2, 0.5], [0.1, -0.2, 0.8])
    p_B = corner_points()
    np.testing.assert_allclose(rigid_fit(p_B, p_B @ X[:3, :3].T + X[:3, 3]), X, atol=1e-12)
    line = np.outer(np.arange(5.0), [0.03, 0.0, 0.0])
    assert rigid_fit(line, line) is None
    assert rigid_fit(p_B[:2], p_B[:2]) is None


def test_the_csv_files_pair_points_with_poses(tmp_path):
    """points.csv rows name the pose row they belong to; an image without a depth point adds no
    pose; poses.csv reads back as the hand poses (the offline calibration's reader)."""
    _, _, X_WH, _ = synthetic_views(3)
    p = np.array([[0.1, 0.2, 0.9], [np.nan] * 3])
    views = [view_of([3, 7], p), view_of([1], np.full((1, 3), np.nan)), view_of([7, 9], p[::-1])]
    images = bench_baseline_hand_eye.CellImages("scenario", [], views, X_WH, np.eye(4), 10, [])
    bench_baseline_hand_eye.write_csvs(images, 3, tmp_path)
    assert (tmp_path / "points.csv").read_text().splitlines() == [
        "sample,point,x,y,z", "0,3,0.1,0.2,0.9", "1,9,0.1,0.2,0.9"]
    np.testing.assert_allclose(read_poses_csv(tmp_path / "poses.csv"), X_WH[[0, 2]], atol=1e-12)


def view_of(ids, p_CQ) -> BoardView:
    """A view with corners ``ids`` at depth points ``p_CQ`` (NaN rows: no depth) and no pose."""
    return BoardView(np.array(ids), np.zeros((len(ids), 2)), np.asarray(p_CQ, float), None, None)


def test_the_loop_row_is_read_from_the_results_page():
    """The marker-free loop's sixteen runs and the commit they were measured at."""
    runs, commits = bench_baseline_hand_eye.loop_results()
    assert len(runs) == 16 and {"scenario", "seed 1", "seed 16"} <= set(runs)
    for first, adopted, mm, deg in runs.values():
        assert 0 < first < adopted and 0 < mm < 10 and 0 < deg < 1
    assert re.fullmatch(r"[0-9a-f]{7,40}( / [0-9a-f]{7,40})*", commits)
