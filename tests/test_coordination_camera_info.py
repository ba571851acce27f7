"""``make_sustainable_coordination``'s ``camera_info``: a ``CameraInfo`` as it is, a ``CameraConfig``'s
intrinsics, any other type a one-line TypeError naming the argument and the accepted types; the
station's ``camera_info`` takes a scenario camera's intrinsics the same way."""

import math

import pytest
from pydrake.systems.sensors import CameraConfig, CameraInfo

from sustain_drake.loops import camera_intrinsics, make_sustainable_coordination
from sustain_drake.station import Scenario, camera_info

# The identifying motion's ranges: the diagram needs them without a plant.
RANGES = [[-0.5, 0.5]] * 2


def intrinsics(info: CameraInfo) -> tuple:
    return (info.width(), info.height(), info.focal_x(), info.focal_y(), info.center_x(), info.center_y())


def tracker_intrinsics(diagram) -> tuple:
    """The intrinsics the diagram's optical-flow tracker was built with."""
    tracker = diagram.GetSubsystemByName("optical_flow_tracker")
    i = tracker.intrinsics
    return (i.width, i.height, i.fx, i.fy, i.cx, i.cy)


def test_a_camera_info_is_taken_as_it_is():
    info = CameraInfo(width=160, height=120, fov_y=1.0)
    assert camera_intrinsics(info) is info
    diagram = make_sustainable_coordination(info, 2, joint_ranges=RANGES)
    assert tracker_intrinsics(diagram) == pytest.approx(intrinsics(info))


def test_a_camera_config_gives_its_intrinsics():
    config = CameraConfig(width=200, height=100, focal=CameraConfig.FovDegrees(y=40.0), center_x=90.0)
    expected = CameraInfo(width=200, height=100, focal_x=100 / 2 / math.tan(math.radians(20.0)),
                          focal_y=100 / 2 / math.tan(math.radians(20.0)), center_x=90.0, center_y=49.5)
    assert intrinsics(camera_intrinsics(config)) == pytest.approx(intrinsics(expected))
    diagram = make_sustainable_coordination(config, 2, joint_ranges=RANGES)
    assert tracker_intrinsics(diagram) == pytest.approx(intrinsics(expected))


def test_the_station_takes_its_cameras_intrinsics_the_same_way():
    scenario = Scenario()
    assert intrinsics(camera_info(scenario)) == intrinsics(camera_intrinsics(scenario.camera))
    assert camera_info(scenario).focal_y() == pytest.approx(240.0 / math.tan(math.radians(22.5)))


@pytest.mark.parametrize("wrong", [640, None, (640, 480), {"width": 640}], ids=repr)
def test_any_other_type_is_a_one_line_type_error(wrong):
    with pytest.raises(TypeError) as error:
        make_sustainable_coordination(wrong, 2, joint_ranges=RANGES)
    message = str(error.value)
    assert "\n" not in message
    assert message.startswith("camera_info must be a pydrake.systems.sensors.CameraInfo or CameraConfig")
    assert type(wrong).__name__ in message
