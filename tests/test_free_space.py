"""Free space along a ray: the depth behind a point, on a hand-made depth image, and the
candidate identifiers' depth inputs."""

import math

import numpy as np
import pytest
from pydrake.systems.sensors import CameraInfo, ImageDepth32F

from sustain_drake.identification.candidates import CandidateParams
from sustain_drake.perception.free_space import depth_gap
from sustain_drake.perception.optical_flow import PinholeIntrinsics
from sustain_drake.systems.candidate_identifiers import CandidateIdentifiers

K = PinholeIntrinsics(width=640, height=480, fx=580.0, fy=580.0, cx=320.0, cy=240.0)


def scene():
    """A wall 2 m away; a 50 mm bar 0.6 m away over columns 300-347 (50 mm at 0.6 m is 48 px)."""
    depth = np.full((480, 640), 2.0, np.float32)
    depth[:, 300:348] = 0.6
    return depth


def at_pixel(u, v, z):
    return np.array([(u - K.cx) * z / K.fx, (v - K.cy) * z / K.fy, z])


def test_a_point_on_a_surface_or_hidden_is_not_seen_through_and_free_space_is():
    depth = scene()
    assert depth_gap(depth, K, at_pixel(320, 240, 0.6), 0.005) == pytest.approx(0.0, abs=1e-6)
    assert depth_gap(depth, K, at_pixel(320, 240, 0.62), 0.005) == pytest.approx(-0.02, abs=1e-6)  # hidden
    assert depth_gap(depth, K, at_pixel(320, 240, 0.55), 0.005) == pytest.approx(0.05, abs=1e-6)  # in front
    assert depth_gap(depth, K, at_pixel(400, 240, 0.6), 0.005) == pytest.approx(1.4, abs=1e-6)  # free
    # 3 px (3 mm) off the bar's edge: the 5 mm window still finds the bar; 8 px off, it does not.
    assert depth_gap(depth, K, at_pixel(350, 240, 0.6), 0.005) == pytest.approx(0.0, abs=1e-6)
    assert depth_gap(depth, K, at_pixel(356, 240, 0.6), 0.005) == pytest.approx(1.4, abs=1e-6)


def test_drake_depth_codes_and_unjudgeable_points():
    depth = scene()
    depth[100:110, 500:510] = 0.0  # too close: something in front
    assert depth_gap(depth, K, at_pixel(505, 105, 0.6), 0.005) == pytest.approx(-0.6)
    depth[200:230, 500:530] = np.inf  # too far: behind
    assert depth_gap(depth, K, at_pixel(515, 215, 0.6), 0.005) == math.inf
    depth[300:330, 500:530] = np.nan  # unknown
    assert math.isnan(depth_gap(depth, K, at_pixel(515, 315, 0.6), 0.005))
    depth[300:330, 515] = 1.0  # one known column in the window is enough
    assert depth_gap(depth, K, at_pixel(515, 315, 0.6), 0.005) == pytest.approx(0.4)
    assert math.isnan(depth_gap(depth, K, at_pixel(2, 240, 0.6), 0.005))  # window leaves the image
    assert math.isnan(depth_gap(depth, K, np.array([0.0, 0.0, -0.5]), 0.005))  # behind the camera
    assert math.isnan(depth_gap(depth, K, np.array([np.nan, 0.0, 0.5]), 0.005))
    with pytest.raises(ValueError, match="depth image is"):
        depth_gap(depth[:, :320], K, at_pixel(100, 100, 0.6), 0.005)
    with pytest.raises(ValueError, match="radius"):
        depth_gap(depth, K, at_pixel(100, 100, 0.6), 0.0)


def test_candidate_identifiers_take_the_features_frames_depth_only_with_the_check_on():
    """``CandidateIdentifiers(camera_info=...)``: the depth inputs exist only with the check on; the
    depth image is used only when ``image_time`` says it is the features' frame."""
    info = CameraInfo(640, 480, 580.0, 580.0, 319.5, 239.5)
    on = CandidateParams(free_space_radius=0.005)
    assert not CandidateIdentifiers(params=on).HasInputPort("depth_image")
    with pytest.raises(ValueError, match="free_space_radius"):
        CandidateIdentifiers(camera_info=info)
    system = CandidateIdentifiers(params=on, camera_info=info)
    context = system.CreateDefaultContext()
    image = ImageDepth32F(640, 480)
    image.mutable_data[:] = scene()[:, :, None]
    system.GetInputPort("depth_image").FixValue(context, image)
    system.GetInputPort("image_time").FixValue(context, [2.0])
    assert system._depth_gap(context, 1.9) is None  # another frame's image
    gap = system._depth_gap(context, 2.0)
    assert gap(at_pixel(400, 240, 0.6)) == pytest.approx(1.4, abs=1e-6)  # free space behind the point
