"""The LCM bridge in-process over memq://: Drake's joint status, force/torque and image-array
messages in, the estimates out as lcmt_scope, on a 3-joint arm that is not ours."""

import numpy as np
import pytest
from drake import lcmt_force_torque, lcmt_iiwa_status, lcmt_image_array, lcmt_scope
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.lcm import LcmPublisherSystem
from pydrake.systems.sensors import CameraInfo, ImageDepth32F, ImageRgba8U, ImageToLcmImageArrayT, PixelType
from test_sustainable_coordination import MASS, P_KCM, payload_wrench, sensor_noise, three_joint_arm

from sustain_drake.identification import coordination
from sustain_drake.loops import Loops
from sustain_drake.loops.lcm_bridge import (
    LCM_INPUT_CHANNELS,
    LCM_OUTPUT_CHANNELS,
    make_lcm_bridge,
)


def publish_images(lcm, color_image, depth_image, utime: int, compress: bool = True) -> None:
    """Publishes a color and a depth image encoded by Drake's own ImageToLcmImageArrayT and
    LcmPublisherSystem (as a camera driver built with Drake would)."""
    builder = DiagramBuilder()
    encoder = builder.AddSystem(ImageToLcmImageArrayT(compress))
    color = encoder.DeclareImageInputPort[PixelType.kRgba8U]("color")
    depth = encoder.DeclareImageInputPort[PixelType.kDepth32F]("depth")
    publisher = builder.AddSystem(LcmPublisherSystem.Make(
        LCM_INPUT_CHANNELS["images"], lcmt_image_array, lcm, publish_period=0.0, use_cpp_serializer=True))
    builder.Connect(encoder.get_output_port(), publisher.get_input_port())
    builder.ExportInput(color, "color")
    builder.ExportInput(depth, "depth")
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    diagram.GetInputPort("color").FixValue(context, color_image)
    diagram.GetInputPort("depth").FixValue(context, depth_image)
    context.SetTime(utime * 1e-6)
    diagram.ForcedPublish(context)


def test_bridge_identifies_the_payload_from_lcm_messages():
    lcm = DrakeLcm("memq://")
    plant = three_joint_arm()
    info = CameraInfo(160, 120, 1.0)
    bridge = make_lcm_bridge(lcm, info, 3, plant=plant, hand_frame=plant.GetBodyByName("link3").body_frame(),
                             publish_period=0.05)  # fmt: skip
    assert bridge.num_input_ports() == 0
    received = {}
    for key, channel in LCM_OUTPUT_CHANNELS.items():
        lcm.Subscribe(channel, lambda data, key=key: received.__setitem__(key, lcmt_scope.decode(data)))
    color, depth = ImageRgba8U(info.width(), info.height()), ImageDepth32F(info.width(), info.height())
    color.mutable_data[:, :, :3] = 90  # a uniform grey: no corners to track
    color.mutable_data[:, :, 3] = 255
    depth.mutable_data[:] = np.linspace(0.8, 1.2, info.width())[None, :, None]
    publish_images(lcm, color, depth, 0)
    simulator = Simulator(bridge)
    postures = np.random.default_rng(3).uniform(-1.2, 1.2, size=(12, 3))
    t, dt = 0.0, 0.01
    while t < 3.0 - 1e-9:
        q = postures[min(int(t / 0.25), len(postures) - 1)]
        status = lcmt_iiwa_status()
        status.utime, status.num_joints = int(t * 1e6), 3
        status.joint_position_measured, status.joint_velocity_estimated = list(q), [0.0] * 3
        for name in ("joint_position_commanded", "joint_position_ipo", "joint_torque_measured",
                     "joint_torque_commanded", "joint_torque_external"):  # fmt: skip
            setattr(status, name, [0.0] * 3)
        lcm.Publish(LCM_INPUT_CHANNELS["status"], status.encode())
        ft = lcmt_force_torque()
        ft.timestamp = int(t * 1e6)
        ft.tx, ft.ty, ft.tz, ft.fx, ft.fy, ft.fz = payload_wrench(plant, q) + sensor_noise(t)
        lcm.Publish(LCM_INPUT_CHANNELS["force_torque"], ft.encode())
        t += dt
        simulator.AdvanceTo(t)
    lcm.HandleSubscriptions(0)
    # The images came through LCM: decoded at the camera's size, the depth as sent.
    images = bridge.GetSubsystemByName("lcm_image_array_to_images")
    images_context = images.GetMyContextFromRoot(simulator.get_context())
    np.testing.assert_array_equal(images.GetOutputPort("color_image").Eval(images_context).data, color.data)
    np.testing.assert_array_equal(images.GetOutputPort("depth_image").Eval(images_context).data, depth.data)

    assert set(received) == set(LCM_OUTPUT_CHANNELS) - {"touch", "p_WP", "f_env_W"}  # no held shape
    assert list(received["payload_mode"].value) == [coordination.OBSERVE]
    assert received["payload_mass"].value[0] == pytest.approx(MASS, rel=0.01)
    np.testing.assert_allclose(received["p_KCm"].value, P_KCM, atol=3e-3)
    assert list(received["hand_eye_mode"].value) == [coordination.IDENTIFY]  # textureless images
    np.testing.assert_array_equal(received["X_WC"].value, np.eye(4).ravel())  # nothing adopted
    assert received["payload_pause"].value[0] == 1  # one pause request, after the convergence


def test_bridge_refuses_uncompressed_depth():
    lcm = DrakeLcm("memq://")
    plant = three_joint_arm()
    info = CameraInfo(160, 120, 1.0)
    bridge = make_lcm_bridge(lcm, info, 3, plant=plant, hand_frame=plant.GetBodyByName("link3").body_frame())
    publish_images(lcm, ImageRgba8U(160, 120), ImageDepth32F(160, 120), 0, compress=False)
    simulator = Simulator(bridge)
    with pytest.raises(ValueError, match="uncompressed depth image"):
        simulator.AdvanceTo(0.1)


def test_bridge_rejects_unknown_channel_keys():
    plant = three_joint_arm()
    with pytest.raises(ValueError, match="unknown channel keys"):
        make_lcm_bridge(DrakeLcm("memq://"), CameraInfo(160, 120, 1.0), 3, plant=plant,
                        hand_frame=plant.GetBodyByName("link3").body_frame(),
                        output_channels={"mass": "M"})  # fmt: skip


def test_a_loop_that_is_off_is_neither_read_nor_published():
    """Hand-eye only: no force/torque subscription, no payload channels; payload only: no images."""
    plant = three_joint_arm()
    hand = plant.GetBodyByName("link3").body_frame()
    vision = make_lcm_bridge(DrakeLcm("memq://"), CameraInfo(160, 120, 1.0), 3, plant=plant, hand_frame=hand,
                             loops=Loops(payload=False))  # fmt: skip
    names = {s.get_name() for s in vision.GetSystems()}
    assert "lcm_subscriber_images" in names and "lcm_subscriber_force_torque" not in names
    payload = make_lcm_bridge(DrakeLcm("memq://"), None, 3, plant=plant, hand_frame=hand,
                              loops=Loops(hand_eye=False))  # fmt: skip
    names = {s.get_name() for s in payload.GetSystems()}
    assert "lcm_subscriber_force_torque" in names and "lcm_subscriber_images" not in names
    Simulator(payload).AdvanceTo(0.05)  # every input the payload loop needs is connected
