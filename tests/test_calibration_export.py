"""Calibration export: the camera pose as a Drake CameraConfig and the payload as a spatial
inertia, written and loaded back."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.sensors import CameraConfig

from sustain_drake.calibration_export import (
    camera_config_yaml,
    load_camera_config,
    load_payload,
    payload_yaml,
)


def test_camera_config_round_trip_keeps_the_pose_and_the_base_settings():
    X_WC = RigidTransform(RollPitchYaw(2.9, -0.1, 0.4), [-0.14, -0.49, 0.95]).GetAsMatrix4()
    base = CameraConfig()
    base.width, base.height, base.fps = 320, 240, 15.0
    text = camera_config_yaml(X_WC, name="head_camera", base=base)
    assert "X_PB:" in text and "base_frame: world" in text and "!Rpy" in text
    config = load_camera_config(text)
    assert config.name == "head_camera"
    assert (config.width, config.height, config.fps) == (320, 240, 15.0)
    X = config.X_PB.GetDeterministicValue().GetAsMatrix4()
    assert np.abs(X - X_WC).max() < 1e-12
    assert base.name != "head_camera"  # the caller's config is not modified


def test_payload_round_trip():
    text = payload_yaml(0.594, [0.01, -0.02, 0.15])
    config = load_payload(text)
    assert config.mass == 0.594 and config.p_BoBcm == [0.01, -0.02, 0.15]
    M = config.spatial_inertia()
    assert M.get_mass() == pytest.approx(0.594)
    assert np.allclose(M.get_com(), [0.01, -0.02, 0.15])
    with pytest.raises(ValueError, match="positive"):
        payload_yaml(-1.0, [0, 0, 0])


def test_the_calibrate_command_writes_a_camera_config(tmp_path):
    from pathlib import Path

    from sustain_drake.cli.main import main

    data = Path(__file__).parent / "data" / "jin_eyetobase_rvc_single"
    out = tmp_path / "camera.yaml"
    code = main(["calibrate", "eye-to-hand", "--points", str(data / "corner_points.csv"),
                 "--poses", str(data / "poses.csv"), "--camera-config", str(out)])  # fmt: skip
    assert code == 0
    X = load_camera_config(out.read_text()).X_PB.GetDeterministicValue().translation()
    assert np.abs(X * 1e3 - [-144.26, -491.22, 951.02]).max() < 0.05
