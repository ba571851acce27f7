"""Pixel settings scale with the camera's focal length (loops.pixel_scale): identical at the measured
camera, the same angles at any other."""

import math

from pydrake.systems.sensors import CameraInfo

from sustain_drake.loops.body_detection import BodyDetectionConfig
from sustain_drake.loops.pixel_scale import pixel_scale, scaled
from sustain_drake.perception.point_refinement import RefinementParams


def _camera(width: int, height: int, fov_y_deg: float = 45.0) -> CameraInfo:
    return CameraInfo(width, height, math.radians(fov_y_deg))


def test_the_measured_camera_keeps_every_setting():
    assert pixel_scale(_camera(640, 480)) == 1.0
    config = BodyDetectionConfig()
    assert config.tracker_params(1.0) == config.tracker_params()
    params = RefinementParams(corner_window_px=4)
    assert scaled(params, 1.0, lengths=("max_shift_px",), windows=("corner_window_px",)) is params


def test_another_camera_sees_the_same_angles():
    scale = pixel_scale(_camera(1280, 720))
    assert math.isclose(scale, 1.5)
    tracker = BodyDetectionConfig().tracker_params(scale)
    base = BodyDetectionConfig().tracker_params()
    assert math.isclose(tracker.min_distance_px, 1.5 * base.min_distance_px)
    assert math.isclose(tracker.min_flow_px / scale, base.min_flow_px)
    assert tracker.lk_window_px == round(1.5 * base.lk_window_px)
    assert tracker.ncc_patch_px % 2 == 1 and abs(tracker.ncc_patch_px - 1.5 * base.ncc_patch_px) <= 1
    config = BodyDetectionConfig()
    assert math.isclose(config.coincidence_params(scale).sdot_threshold, 1.5 * config.sdot_threshold)
    refinement = scaled(RefinementParams(corner_window_px=4, blob_window_px=0), 0.5,
                        windows=("corner_window_px", "blob_window_px"))
    # a window shrinks to 3 px at least, and 0 (off) stays off
    assert refinement.corner_window_px == 3 and refinement.blob_window_px == 0
