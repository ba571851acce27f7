"""``make_sustainable_coordination``'s ``camera_info``: a ``CameraInfo`` as it is, a ``CameraConfig``'s
intrinsics, any other type a one-line TypeError naming the argument and the accepted types; the
station's ``camera_info`` takes a scenario camera's intrinsics the same way; and those intrinsics
describe the images Drake's VTK renderer draws (``rendered_intrinsics``)."""

import math

import numpy as np
import pytest
from pydrake.geometry import (
    Box,
    ClippingRange,
    ColorRenderCamera,
    DepthRange,
    DepthRenderCamera,
    MakeRenderEngineVtk,
    RenderCameraCore,
    RenderEngineVtkParams,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.sensors import CameraConfig, CameraInfo, RgbdSensor

from sustain_drake.loops import camera_intrinsics, make_sustainable_coordination
from sustain_drake.loops.coordination import rendered_intrinsics
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
                          focal_y=100 / 2 / math.tan(math.radians(20.0)), center_x=89.5, center_y=49.0)
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


# m: thin enough that the plate's side face, seen beside its edge, spans under 0.01 px.
PLATE_THICKNESS = 1e-5


def _first_covered_pixel(info: CameraInfo, axis: int, edge_px: float) -> int:
    """Renders (Drake's VTK) a plane 1 m ahead of a camera of ``info`` that covers the image from
    where Drake's pinhole model of ``info`` puts ``edge_px`` (u for axis 0, v for axis 1) onwards;
    returns the first covered pixel along the middle row (or column)."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    scene_graph.AddRenderer("vtk", MakeRenderEngineVtk(RenderEngineVtkParams()))
    centre = (info.center_x(), info.center_y())[axis]
    edge = (edge_px - centre) / (info.focal_x(), info.focal_y())[axis]  # m at 1 m depth
    offset = np.zeros(3)
    offset[axis] = edge + 1.0  # the 2 m plate's near side on the edge
    offset[2] = 1.0 + 0.5 * PLATE_THICKNESS  # its front face 1 m ahead
    plate = Box(2.0, 2.0, PLATE_THICKNESS)
    plant.RegisterVisualGeometry(plant.world_body(), RigidTransform(offset), plate, "plate", [1.0] * 4)
    plant.Finalize()
    core = RenderCameraCore("vtk", info, ClippingRange(0.01, 10.0), RigidTransform())
    cameras = ColorRenderCamera(core), DepthRenderCamera(core, DepthRange(0.1, 5.0))
    sensor = builder.AddSystem(RgbdSensor(scene_graph.world_frame_id(), RigidTransform(), *cameras))
    builder.Connect(scene_graph.get_query_output_port(), sensor.query_object_input_port())
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    depth = sensor.depth_image_32F_output_port().Eval(sensor.GetMyContextFromRoot(context)).data[:, :, 0]
    line = depth[info.height() // 2] if axis == 0 else depth[:, info.width() // 2]
    return int(np.flatnonzero(line < 2.0)[0])


@pytest.mark.parametrize("axis", [0, 1])
def test_rendered_intrinsics_put_a_depth_edge_where_the_renderer_draws_it(axis):
    # Edges across the image at nominal u (or v) = k + 0.4 and k + 0.6: the first pixel whose centre
    # lies on the plate under rendered_intrinsics is ceil(edge - 0.5) (k, then k + 1), as drawn;
    # Drake's nominal model would say k + 1 for both.
    info = CameraInfo(640, 480, math.pi / 4)
    rendered = rendered_intrinsics(info)
    centre_shift = (rendered.center_x() - info.center_x(), rendered.center_y() - info.center_y())[axis]
    for k in (20, 300, 460):
        for edge in (k + 0.4, k + 0.6):
            assert _first_covered_pixel(info, axis, edge) == math.ceil(edge + centre_shift)
