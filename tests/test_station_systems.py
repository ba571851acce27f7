"""The station's small systems: the distractor's path, the disturbance timeline and the camera
sampler (frame timing, reproducible depth noise)."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource
from pydrake.systems.sensors import ImageDepth32F, ImageRgba8U

from sustain_drake.systems.camera_sampler import RgbdCameraSampler
from sustain_drake.systems.depth_noise import DepthNoiseModel
from sustain_drake.systems.distractor import DistractorPath
from sustain_drake.systems.disturbances import Step, piecewise_target


def test_distractor_waits_then_walks_the_path_at_its_speed():
    path = DistractorPath([[0, 0], [2, 0], [2, 1]], speed=0.5, start_time=1.0, loop=False)
    np.testing.assert_allclose(path.state_at(0.0), [0, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(path.state_at(3.0), [1.0, 0, 0, 0.5, 0, 0])
    np.testing.assert_allclose(path.state_at(6.0), [2.0, 0.5, np.pi / 2, 0, 0.5, 0], atol=1e-12)
    # Without loop it stops at the last waypoint.
    np.testing.assert_allclose(path.state_at(100.0)[[0, 1, 3, 4]], [2, 1, 0, 0])


def test_distractor_loop_walks_back():
    path = DistractorPath([[0, 0], [1, 0]], speed=1.0, start_time=0.0, loop=True)
    np.testing.assert_allclose(path.state_at(1.5)[:2], [0.5, 0])
    assert path.state_at(1.5)[3] == pytest.approx(-1.0)  # walking back
    np.testing.assert_allclose(path.state_at(2.25)[:2], [0.25, 0])


@pytest.mark.parametrize("args", [
    ([[0, 0]], 1.0), ([[0, 0], [0, 0]], 1.0), ([[0, 0], [1, 0]], 0.0),
    ([[0, 0], [np.nan, 0]], 1.0),
])
def test_distractor_rejects_bad_paths(args):
    with pytest.raises(ValueError):
        DistractorPath(*args)


def test_disturbance_timeline_ramps_to_each_step():
    steps = [Step(1.0, (0.5, 0.0), 0.2), Step(2.0, (0.5, 1.0), 0.5)]
    q, v = piecewise_target([0.0, 0.0], steps, 0.5)
    np.testing.assert_allclose(q, [0, 0])
    np.testing.assert_allclose(v, [0, 0])
    q, v = piecewise_target([0.0, 0.0], steps, 1.1)
    assert 0 < q[0] < 0.5 and v[0] > 0
    q, v = piecewise_target([0.0, 0.0], steps, 1.9)
    np.testing.assert_allclose(q, [0.5, 0.0])
    np.testing.assert_allclose(v, [0, 0], atol=1e-12)
    q, _ = piecewise_target([0.0, 0.0], steps, 3.0)
    np.testing.assert_allclose(q, [0.5, 1.0])


def sampler_run(noise, seed=0, fps=10.0):
    depth = ImageDepth32F(4, 3)
    depth.mutable_data[:] = 2.0
    color = ImageRgba8U(4, 3)
    builder = DiagramBuilder()
    sampler = builder.AddSystem(RgbdCameraSampler(fps, ["color_image", "depth_image"], noise,
                                                  seed))
    for name, image in (("color_image", color), ("depth_image", depth)):
        source = builder.AddSystem(ConstantValueSource(AbstractValue.Make(image)))
        builder.Connect(source.get_output_port(), sampler.GetInputPort(name))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = sampler.GetMyContextFromRoot(simulator.get_context())
    frames = []
    for t in (0.0, 0.05, 0.12, 0.19, 0.21):
        simulator.AdvanceTo(t)
        frames.append((sampler.GetOutputPort("image_time").Eval(context)[0],
                       sampler.GetOutputPort("depth_image").Eval(context).data.copy()))
    return frames


def test_camera_sampler_holds_each_frame_and_stamps_it():
    frames = sampler_run(DepthNoiseModel(), seed=3)
    times = [t for t, _ in frames]
    np.testing.assert_allclose(times, [0.0, 0.0, 0.1, 0.1, 0.2])
    # Within a frame the noisy depth is held; a new frame draws new noise.
    np.testing.assert_array_equal(frames[2][1], frames[3][1])
    assert not np.array_equal(frames[1][1], frames[2][1])
    assert np.all(np.abs(frames[2][1] - 2.0) < 6 * DepthNoiseModel().sigma(2.0))
    assert np.any(frames[2][1] != 2.0)


def test_camera_sampler_noise_is_reproducible_and_optional():
    a = sampler_run(DepthNoiseModel(), seed=3)
    b = sampler_run(DepthNoiseModel(), seed=3)
    c = sampler_run(DepthNoiseModel(), seed=4)
    for (_, x), (_, y) in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a[2][1], c[2][1])
    exact = sampler_run(None)
    assert all(np.all(d == 2.0) for _, d in exact)


def test_depth_noise_into_a_given_array_is_the_same_image():
    z = np.linspace(0.2, 4.0, 12 * 16, dtype=np.float32).reshape(12, 16, 1)
    z[0, :3, 0] = [0.0, np.inf, -1.0]
    noise = DepthNoiseModel()
    out = np.empty_like(z)
    expected = noise.apply(z, np.random.default_rng([5, 7]))
    assert noise.apply(z, np.random.default_rng([5, 7]), out=out) is out
    assert out.tobytes() == expected.tobytes()
    assert out[0, 0, 0] == 0.0 and out[0, 1, 0] == np.inf and out[0, 2, 0] == 0.0


def test_camera_sampler_rejects_bad_arguments():
    with pytest.raises(ValueError):
        RgbdCameraSampler(0.0)
    with pytest.raises(ValueError):
        RgbdCameraSampler(30.0, ["infrared_image"])
