"""OpticalFlowTracker in small Diagrams: a synthetic moving scene, empty images from a
ConstantValueSource, the optional image_time port, and context cloning."""

import cv2
import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource, TrajectorySource
from pydrake.systems.sensors import CameraInfo, ImageDepth32F, ImageRgba8U
from pydrake.trajectories import PiecewisePolynomial

from sustain_drake.perception.optical_flow import TrackedFeatures
from sustain_drake.systems.optical_flow_tracker import OpticalFlowTracker

W, H = 320, 240
CAMERA = CameraInfo(W, H, np.pi / 3)
GRID_SHAPE = (6, 8)                       # 40 px cells
PX_PER_RAD = 40.0


class MovingScene(LeafSystem):
    """A textured image whose left half (the "arm") shifts by ``PX_PER_RAD * q`` pixels, and a
    patch in the right half (the "distractor") that shifts by itself during ``distractor``
    intervals. Depth is 1 m everywhere except a hole in the top-left corner."""

    def __init__(self, distractor=((0.2, 0.4), (1.2, 1.4))):
        super().__init__()
        rng = np.random.default_rng(0)
        noise = cv2.GaussianBlur(rng.uniform(0, 255, (H, W + 80)).astype(np.float32), (0, 0), 2)
        self._base = ((noise - noise.min()) / np.ptp(noise) * 235 + 10).astype(np.uint8)
        self._distractor = distractor
        self.DeclareVectorInputPort("q", 1)
        self.DeclareAbstractOutputPort("color_image", lambda: AbstractValue.Make(ImageRgba8U()),
                                       self._calc_color)
        self.DeclareAbstractOutputPort("depth_image", lambda: AbstractValue.Make(ImageDepth32F()),
                                       self._calc_depth)

    def gray(self, q, t):
        img = self._base[:, 40:40 + W].copy()
        shift = np.float32([[1, 0, PX_PER_RAD * q], [0, 1, 0]])
        arm = cv2.warpAffine(self._base, shift, (W + 80, H), flags=cv2.INTER_LINEAR)
        img[:, : W // 2] = arm[:, 40:40 + W // 2]
        offset = sum(min(max(t - t0, 0.0), t1 - t0) for t0, t1 in self._distractor) * 30.0
        patch = cv2.warpAffine(self._base, np.float32([[1, 0, offset], [0, 1, 0]]),
                               (W + 80, H), flags=cv2.INTER_LINEAR)
        img[80:160, 200:280] = patch[80:160, 240:320]
        return img

    def _calc_color(self, context, output):
        g = self.gray(float(self.get_input_port(0).Eval(context)[0]), context.get_time())
        image = ImageRgba8U(W, H)
        image.mutable_data[:, :, :3] = g[:, :, None]
        image.mutable_data[:, :, 3] = 255
        output.set_value(image)

    def _calc_depth(self, context, output):
        depth = ImageDepth32F(W, H)
        depth.mutable_data[:] = 1.0
        depth.mutable_data[:40, :40] = np.inf
        output.set_value(depth)


def joint_trajectory():
    """q = 0 until 0.5 s, moves at 0.5 rad/s to 1.0 s, holds, moves again from 1.5 s."""
    return PiecewisePolynomial.FirstOrderHold(
        [0.0, 0.5, 1.0, 1.5, 2.0], np.array([[0.0, 0.0, 0.25, 0.25, 0.5]]))


def build_scene_diagram(with_detector=False):
    builder = DiagramBuilder()
    q = builder.AddNamedSystem("q", TrajectorySource(joint_trajectory()))
    scene = builder.AddNamedSystem("scene", MovingScene())
    tracker = builder.AddNamedSystem("tracker", OpticalFlowTracker(CAMERA, GRID_SHAPE))
    builder.Connect(q.get_output_port(), scene.get_input_port(0))
    builder.Connect(scene.GetOutputPort("color_image"), tracker.GetInputPort("color_image"))
    builder.Connect(scene.GetOutputPort("depth_image"), tracker.GetInputPort("depth_image"))
    detector = None
    if with_detector:
        from sustain_drake.systems.motion_coincidence_detector import MotionCoincidenceDetector
        detector = builder.AddNamedSystem(
            "detector", MotionCoincidenceDetector(1, tracker.grid.num_cells))
        builder.Connect(q.get_output_port(), detector.GetInputPort("actuator_positions"))
        builder.Connect(tracker.GetOutputPort("visual_change"),
                        detector.GetInputPort("visual_change"))
        builder.Connect(tracker.GetOutputPort("tracked_features"),
                        detector.GetInputPort("tracked_features"))
    return builder.Build(), tracker, detector


def test_tracks_the_moving_scene_and_reports_points_and_visual_change():
    diagram, tracker, _ = build_scene_diagram()
    sim = Simulator(diagram)
    sim.AdvanceTo(0.8)
    ctx = tracker.GetMyContextFromRoot(sim.get_context())
    f = tracker.GetOutputPort("tracked_features").Eval(ctx)
    assert isinstance(f, TrackedFeatures) and len(f) > 50
    hole = (f.p_px[:, 0] < 39) & (f.p_px[:, 1] < 39)
    assert not f.valid[hole].any() and f.valid[~hole & (f.p_px[:, 0] > 41)].all()
    assert np.allclose(f.p_CP[f.valid, 2], 1.0)
    # the arm (left half) moves at 0.5 rad/s * 40 px/rad = 20 px/s: ≈ 0.67 px per frame
    left = (f.p_px[:, 0] < W // 2 - 20) & (f.ids < 10_000)
    assert np.median(f.flow_px[left, 0]) == pytest.approx(PX_PER_RAD * 0.5 / 30, abs=0.1)
    sdot = tracker.GetOutputPort("visual_change").Eval(ctx)
    grid = tracker.grid
    assert sdot.shape == (grid.num_cells,)
    cols = np.arange(grid.num_cells) % grid.cols
    assert (sdot[cols < grid.cols // 2 - 1] > 0).mean() > 0.8
    assert np.all(sdot[cols >= grid.cols // 2 + 1] == 0)     # right half still at t = 0.8
    # The frame the tracks were found in, in grey: the scene's image at that frame's time.
    gray = tracker.GetOutputPort("gray_image").Eval(ctx)
    at_frame = diagram.CreateDefaultContext()
    at_frame.SetTime(f.time)
    scene = diagram.GetSubsystemByName("scene")
    color = scene.GetOutputPort("color_image").Eval(scene.GetMyContextFromRoot(at_frame)).data
    assert gray.shape == color.shape[:2] and gray.dtype == np.uint8
    assert np.array_equal(gray, cv2.cvtColor(color, cv2.COLOR_RGBA2GRAY))


def test_empty_images_from_a_constant_source_are_skipped_without_raising():
    builder = DiagramBuilder()
    empty = builder.AddSystem(ConstantValueSource(AbstractValue.Make(ImageRgba8U())))
    tracker = builder.AddSystem(OpticalFlowTracker(CAMERA, GRID_SHAPE))
    builder.Connect(empty.get_output_port(), tracker.GetInputPort("color_image"))
    diagram = builder.Build()
    sim = Simulator(diagram)
    sim.AdvanceTo(0.5)
    ctx = tracker.GetMyContextFromRoot(sim.get_context())
    state = tracker.tracker_state(ctx)
    assert state.frames == 0 and state.skipped >= 15
    assert np.all(tracker.GetOutputPort("visual_change").Eval(ctx) == 0)
    assert len(tracker.GetOutputPort("tracked_features").Eval(ctx)) == 0
    assert tracker.GetOutputPort("gray_image").Eval(ctx).shape == (0, 0)


def test_a_frame_not_newer_than_the_last_is_skipped_when_image_time_is_connected():
    builder = DiagramBuilder()
    scene = builder.AddSystem(MovingScene())
    zero = builder.AddSystem(ConstantVectorSource([0.0]))
    stamp = builder.AddSystem(ConstantVectorSource([0.0]))    # one capture, repeated
    tracker = builder.AddSystem(OpticalFlowTracker(CAMERA, GRID_SHAPE))
    builder.Connect(zero.get_output_port(), scene.get_input_port(0))
    builder.Connect(scene.GetOutputPort("color_image"), tracker.GetInputPort("color_image"))
    builder.Connect(stamp.get_output_port(), tracker.GetInputPort("image_time"))
    sim = Simulator(builder.Build())
    sim.AdvanceTo(0.3)
    state = tracker.tracker_state(tracker.GetMyContextFromRoot(sim.get_context()))
    assert state.frames == 1 and state.skipped >= 8 and len(state.features) > 50


def test_cloned_contexts_evolve_independently_and_identically():
    diagram, tracker, _ = build_scene_diagram()
    sim = Simulator(diagram)
    sim.AdvanceTo(0.7)
    clone = sim.get_context().Clone()
    sim.AdvanceTo(1.0)
    sim2 = Simulator(diagram, clone)
    before = tracker.tracker_state(tracker.GetMyContextFromRoot(clone))
    assert before.frames < tracker.tracker_state(
        tracker.GetMyContextFromRoot(sim.get_context())).frames
    sim2.AdvanceTo(1.0)
    a = tracker.tracker_state(tracker.GetMyContextFromRoot(sim.get_context()))
    b = tracker.tracker_state(tracker.GetMyContextFromRoot(sim2.get_context()))
    assert a is not b and a.frames == b.frames
    assert np.array_equal(a.ids, b.ids) and np.array_equal(a.sdot, b.sdot)
    assert not np.shares_memory(a.prev_gray, b.prev_gray)
