"""The coordination on a robot that speaks Drake's LCM messages (real hardware)."""

from __future__ import annotations

from drake import lcmt_force_torque, lcmt_iiwa_status, lcmt_image_array
from pydrake.manipulation import IiwaStatusReceiver
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.lcm import LcmInterfaceSystem, LcmScopeSystem, LcmSubscriberSystem
from pydrake.systems.sensors import LcmImageArrayToImages

from sustain_drake.loops.coordination import make_sustainable_coordination
from sustain_drake.systems.ground_truth import PoseToVector
from sustain_drake.systems.lcm_converters import ForceTorqueToWrench, ImageArrayTime

# Default LCM channels of the bridge: the sensors it reads, the estimates it publishes (lcmt_scope).
LCM_INPUT_CHANNELS = {"status": "SUSTAIN_ARM_STATUS", "force_torque": "SUSTAIN_FORCE_TORQUE",
                      "images": "SUSTAIN_RGBD"}  # fmt: skip
LCM_OUTPUT_CHANNELS = {
    "X_WC": "SUSTAIN_X_WC", "p_HP": "SUSTAIN_P_HP", "hand_eye_mode": "SUSTAIN_HAND_EYE_MODE",
    "hand_eye_pause": "SUSTAIN_HAND_EYE_PAUSE", "motion_confirm": "SUSTAIN_MOTION_CONFIRM",
    "payload_mass": "SUSTAIN_PAYLOAD_MASS", "p_KCm": "SUSTAIN_P_KCM", "payload_mode": "SUSTAIN_PAYLOAD_MODE",
    "payload_pause": "SUSTAIN_PAYLOAD_PAUSE", "touch": "SUSTAIN_TOUCH", "p_WP": "SUSTAIN_P_WP",
    "f_env_W": "SUSTAIN_F_ENV_W", "X_WC_valid": "SUSTAIN_X_WC_VALID", "p_HP_valid": "SUSTAIN_P_HP_VALID",
    "payload_valid": "SUSTAIN_PAYLOAD_VALID", "X_WC_sd": "SUSTAIN_X_WC_SD", "p_HP_sd": "SUSTAIN_P_HP_SD",
    "payload_sd": "SUSTAIN_PAYLOAD_SD", "followed_point": "SUSTAIN_FOLLOWED_POINT",
    "followed_point_valid": "SUSTAIN_FOLLOWED_POINT_VALID",
}  # fmt: skip


def make_lcm_bridge(lcm, camera_info, num_joints: int, *, plant, hand_frame, publish_period: float = 0.1,
                    wrench_sign: float = 1.0, input_channels: dict | None = None,
                    output_channels: dict | None = None, **coordination_kwargs) -> Diagram:  # fmt: skip
    """The coordination on a robot that speaks Drake's LCM messages: a Diagram (no ports) that
    subscribes, runs ``make_sustainable_coordination`` and publishes the estimates. Simulate it
    (e.g. ``Simulator`` with ``set_target_realtime_rate(1)``) to run it against hardware.

    Reads (on ``lcm``, a ``DrakeLcmInterface``; channels ``LCM_INPUT_CHANNELS`` updated by
    ``input_channels``): ``status`` ``lcmt_iiwa_status`` (Drake's joint status for any
    ``num_joints``: ``joint_position_measured``, ``joint_velocity_estimated``; read by
    ``IiwaStatusReceiver``), ``force_torque`` ``lcmt_force_torque`` (``wrench_sign``: see
    ``ForceTorqueToWrench``), ``images`` ``lcmt_image_array`` (a color and a depth image, as
    ``ImageToLcmImageArrayT`` writes them; decoded by ``LcmImageArrayToImages``; ``header.utime``
    is the capture time). The hand and sensor poses come from ``plant`` and ``hand_frame``
    (``sensor_frame``, ``loops`` etc. go to ``make_sustainable_coordination`` in
    ``coordination_kwargs``); the channels of a loop that is off are neither read nor published.

    Publishes every ``publish_period`` s, as ``lcmt_scope`` (Drake's vector message; channels
    ``LCM_OUTPUT_CHANNELS`` updated by ``output_channels``) the vector outputs of the
    coordination and ``X_WC`` as its 4x4 matrix, row-major (16 values).
    """
    inputs = {**LCM_INPUT_CHANNELS, **(input_channels or {})}
    outputs = {**LCM_OUTPUT_CHANNELS, **(output_channels or {})}
    if set(inputs) != set(LCM_INPUT_CHANNELS) or set(outputs) != set(LCM_OUTPUT_CHANNELS):
        raise ValueError(f"make_lcm_bridge: unknown channel keys; inputs {sorted(LCM_INPUT_CHANNELS)}, "
                         f"outputs {sorted(LCM_OUTPUT_CHANNELS)}")  # fmt: skip
    builder = DiagramBuilder()
    bus = builder.AddSystem(LcmInterfaceSystem(lcm))
    coordination = builder.AddSystem(make_sustainable_coordination(
        camera_info, num_joints, plant=plant, hand_frame=hand_frame, **coordination_kwargs))  # fmt: skip

    def subscribe(key, lcm_type, cpp, suffix=""):
        sub = builder.AddSystem(LcmSubscriberSystem.Make(inputs[key], lcm_type, bus, use_cpp_serializer=cpp))
        sub.set_name(f"lcm_subscriber_{key}{suffix}")
        return sub.get_output_port()

    def connect(port, name):  # a loop that is off has no such input: its sensor is not read
        if coordination.HasInputPort(name):
            builder.Connect(port, coordination.GetInputPort(name))

    status = builder.AddSystem(IiwaStatusReceiver(num_joints))
    builder.Connect(subscribe("status", lcmt_iiwa_status, True), status.get_input_port())
    connect(status.GetOutputPort("position_measured"), "joint_positions")
    connect(status.GetOutputPort("velocity_estimated"), "joint_velocities")
    if coordination.HasInputPort("wrench"):
        wrench = builder.AddSystem(ForceTorqueToWrench(wrench_sign))
        builder.Connect(subscribe("force_torque", lcmt_force_torque, False), wrench.get_input_port())
        connect(wrench.get_output_port(), "wrench")
    if coordination.HasInputPort("color_image"):
        images = builder.AddSystem(LcmImageArrayToImages())
        images.set_name("lcm_image_array_to_images")
        builder.Connect(subscribe("images", lcmt_image_array, True), images.get_input_port())
        for name in ("color_image", "depth_image"):
            connect(images.GetOutputPort(name), name)
        # The C++ message is opaque to Python: a second (Python) subscription reads the capture time.
        image_time = builder.AddSystem(ImageArrayTime())
        builder.Connect(subscribe("images", lcmt_image_array, False, "_time"), image_time.get_input_port())
        connect(image_time.get_output_port(), "image_time")

    for key, channel in outputs.items():
        if not coordination.HasOutputPort(key):
            continue  # the outputs of a loop that is off
        port = coordination.GetOutputPort(key)
        if key == "X_WC":
            matrix = builder.AddSystem(PoseToVector())
            builder.Connect(port, matrix.get_input_port())
            port = matrix.get_output_port()
        LcmScopeSystem.AddToBuilder(builder, lcm, port, channel, publish_period)
    diagram = builder.Build()
    diagram.set_name("sustainable_coordination_lcm_bridge")
    return diagram
