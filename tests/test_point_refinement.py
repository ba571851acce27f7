"""Drift-free points of tracked features (perception.point_refinement) on synthetic images."""

import cv2
import numpy as np
import pytest

from sustain_drake.perception.optical_flow import PinholeIntrinsics
from sustain_drake.perception.point_refinement import RefinementParams, local_depth, refine_points

K = PinholeIntrinsics(width=160, height=120, fx=145.0, fy=145.0, cx=79.5, cy=59.5)
SADDLE = (70.3, 50.6)  # px, a checker saddle at a sub-pixel position


def checker_image(saddle=SADDLE, cell=9.0, scale=8):
    """A yellow/black checker whose corners include ``saddle``, drawn 8x larger and shrunk with
    area averaging (sub-pixel edges, as a renderer gives)."""
    h, w = K.height * scale, K.width * scale
    v, u = np.mgrid[0:h, 0:w]
    uu = ((u + 0.5) / scale - 0.5 - saddle[0]) / cell
    vv = ((v + 0.5) / scale - 0.5 - saddle[1]) / cell
    light = (np.floor(uu) + np.floor(vv)) % 2 == 0
    big = np.where(light[..., None], np.array([250, 210, 20, 255]), np.array([20, 20, 20, 255]))
    return cv2.resize(big.astype(np.uint8), (K.width, K.height), interpolation=cv2.INTER_AREA)


def test_a_drifted_track_is_moved_back_to_the_saddle_and_back_projected():
    rng = np.random.default_rng(0)
    depth = np.full((K.height, K.width, 1), 0.8, np.float32) + rng.normal(0, 1.5e-3, (K.height, K.width, 1))
    tracked = np.array([[SADDLE[0] + 1.2, SADDLE[1] - 0.9]])  # 1.5 px of drift
    p_CP, valid, p_px = refine_points(checker_image(), depth.astype(np.float32), tracked, K,
                                      RefinementParams(), return_pixels=True)
    assert valid[0]
    assert np.linalg.norm(p_px[0] - SADDLE) < 0.15
    # Depth: the median of 5 x 5 noisy pixels, much nearer 0.8 m than one pixel's 1.5 mm noise.
    assert p_CP[0, 2] == pytest.approx(0.8, abs=0.8e-3)
    assert p_CP[0, 0] == pytest.approx((SADDLE[0] - K.cx) * 0.8 / K.fx, abs=1e-3)
    assert p_CP[0, 1] == pytest.approx((SADDLE[1] - K.cy) * 0.8 / K.fy, abs=1e-3)


def test_a_window_across_a_silhouette_gives_no_point():
    flat = np.full((K.height, K.width, 4), 128, np.uint8)
    depth = np.full((K.height, K.width), 0.8, np.float32)
    # A flat patch has no gradient to move the pixel: the tracked pixel is kept.
    _, valid, p_px = refine_points(flat, depth, np.array([[70.2, 50.1]]), K, return_pixels=True)
    assert valid[0] and np.allclose(p_px[0], [70.2, 50.1], atol=1e-3)
    # Half the depth window on the tool (0.8 m), half on the background (2.5 m): no clean depth.
    depth[:, 71:] = 2.5
    assert np.isnan(local_depth(depth, np.array([[70.6, 50.0]]), RefinementParams()))[0]
    assert local_depth(depth, np.array([[60.0, 50.0]]), RefinementParams())[0] == pytest.approx(0.8)
    # Outside the image, and an empty list.
    outside_or_across = np.array([[1.0, 1.0], [200.0, 50.0], [70.6, 50.0]])
    p_CP, valid = refine_points(checker_image(), depth, outside_or_across, K)
    assert not valid.any() and not np.any(p_CP)  # zero rows, never NaN
    assert refine_points(checker_image(), depth, np.zeros((0, 2)), K)[0].shape == (0, 3)


def test_params_validation():
    with pytest.raises(ValueError, match="window"):
        RefinementParams(corner_window_px=-1)
    with pytest.raises(ValueError, match="min_fraction"):
        RefinementParams(min_fraction=0.0)


def test_feature_refiner_system_refines_only_features_of_the_shown_frame():
    from pydrake.systems.sensors import CameraInfo, ImageDepth32F, ImageRgba8U

    from sustain_drake.perception.optical_flow import TrackedFeatures
    from sustain_drake.systems.candidate_identifiers import FeatureRefiner

    info = CameraInfo(K.width, K.height, K.fx, K.fy, K.cx, K.cy)
    refiner = FeatureRefiner(info)
    context = refiner.CreateDefaultContext()
    color, depth = ImageRgba8U(K.width, K.height), ImageDepth32F(K.width, K.height)
    color.mutable_data[:] = checker_image()
    depth.mutable_data[:] = 0.8
    features = TrackedFeatures(ids=np.array([5]), p_px=np.array([[SADDLE[0] + 1.0, SADDLE[1] + 0.8]]),
                               flow_px=np.zeros((1, 2)), p_CP=np.zeros((1, 3)), valid=np.array([False]),
                               cell=np.zeros(1, np.int64), time=2.0)  # fmt: skip
    refiner.GetInputPort("tracked_features").FixValue(context, features)
    refiner.GetInputPort("color_image").FixValue(context, color)
    refiner.GetInputPort("depth_image").FixValue(context, depth)
    refiner.GetInputPort("image_time").FixValue(context, [2.0])
    out = refiner.GetOutputPort("tracked_features").Eval(context)
    assert out.ids.tolist() == [5] and out.valid[0] and out.time == 2.0
    assert np.linalg.norm(out.p_px[0] - SADDLE) < 0.15 and out.p_CP[0, 2] == pytest.approx(0.8)
    refiner.GetInputPort("image_time").FixValue(context, [2.0 + 1 / 30])  # the next frame's image
    out = refiner.GetOutputPort("tracked_features").Eval(context)
    assert not out.valid.any() and not np.any(out.p_CP)
