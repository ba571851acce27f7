"""Calibration export: the camera pose as a Drake CameraConfig and the payload as a spatial
inertia, written and loaded back."""

import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.sensors import CameraConfig
from scipy.spatial.transform import Rotation

from sustain_drake.calibration_export import (
    CalibrationExportError,
    camera_config_yaml,
    load_camera_config,
    load_payload,
    payload_yaml,
)
from sustain_drake.identification import payload_dynamic as pd


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


def test_payload_round_trip_with_the_identified_inertia():
    """A dynamic identification's payload keeps its rotational inertia through the YAML, and Drake
    reads the same spatial inertia back."""
    rng = np.random.default_rng(0)
    R = Rotation.from_euler("xyz", [0.3, -0.2, 0.9]).as_matrix()
    I_cm = R @ np.diag([0.0019, 0.0027, 0.0031]) @ R.T
    phi, bias = pd.inertial_parameters(0.6, [0.01, -0.02, 0.07], I_cm), rng.normal(0.0, 0.3, 6)
    identifier = pd.DynamicPayloadIdentifier()
    for R_WK in Rotation.random(60, random_state=rng).as_matrix():
        w, alpha, a = rng.normal(0, 1, 3), rng.normal(0, 4, 3), rng.normal(0, 2, 3)
        k = pd.sensor_kinematics(R_WK, w, alpha, a, [0, 0, -9.81])
        identifier.add(pd.predicted_wrench(phi, bias, k), k)
    solution = identifier.solve()
    assert solution.verdict.converged, solution.verdict
    config = load_payload(payload_yaml(solution.mass, solution.p_KCm, I_BBcm=solution.I_BBcm))
    M = config.spatial_inertia()
    assert M.get_mass() == pytest.approx(0.6) and np.allclose(M.get_com(), [0.01, -0.02, 0.07], atol=1e-12)
    I_Bo = M.CalcRotationalInertia().CopyToFullMatrix3()  # about K's origin
    assert np.allclose(I_Bo, pd.inertia_matrix(phi[4:]), atol=1e-12)


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


# --- Reliability (issue #23): everything written or loaded is checked, one-line errors -------------


def one_line(error: pytest.ExceptionInfo) -> str:
    message = str(error.value)
    assert isinstance(error.value, ValueError) and "\n" not in message and message
    return message


def _reflection():
    return np.diag([1.0, 1.0, -1.0, 1.0])


def _scaled():
    return np.diag([2.0, 2.0, 2.0, 1.0])


def _wrong_last_row():
    X = np.eye(4)
    X[3, 0] = 1.0
    return X


def _nan_translation():
    X = np.eye(4)
    X[0, 3] = np.nan
    return X


def _inf_rotation():
    X = np.eye(4)
    X[1, 1] = np.inf
    return X


def _off_by_more_than_a_micro():
    X = RigidTransform(RollPitchYaw(0.1, 0.2, 0.3), [1, 2, 3]).GetAsMatrix4()
    X[0, 0] += 1e-5
    return X


BAD_POSES = {
    "a reflection": (_reflection, "reflection"),
    "a scaled matrix": (_scaled, "not orthonormal"),
    "a wrong last row": (_wrong_last_row, "last row"),
    "a NaN translation": (_nan_translation, "NaN or inf"),
    "an inf in the rotation": (_inf_rotation, "NaN or inf"),
    "a NaN RigidTransform": (lambda: RigidTransform([np.nan, 0.0, 0.0]), "NaN or inf"),
    "a rotation off by 1e-5": (_off_by_more_than_a_micro, "not orthonormal"),
    "a 3 x 3 matrix": (lambda: np.eye(3), "4 x 4"),
    "not numbers": (lambda: [["a"] * 4] * 4, "4 x 4 matrix of numbers"),
}


@pytest.mark.parametrize("case", BAD_POSES, ids=list(BAD_POSES))
def test_camera_config_yaml_refuses_what_is_not_a_rigid_transform(case):
    make, expected = BAD_POSES[case]
    with pytest.raises(CalibrationExportError) as error:
        camera_config_yaml(make())
    assert expected in one_line(error)


def test_camera_config_yaml_accepts_a_rotation_within_the_tolerance_and_orthonormalizes_it():
    X = RigidTransform(RollPitchYaw(0.1, 0.2, 0.3), [1, 2, 3]).GetAsMatrix4()
    noisy = X.copy()
    noisy[:3, :3] += 1e-8 * np.random.default_rng(0).standard_normal((3, 3))
    loaded = load_camera_config(camera_config_yaml(noisy)).X_PB.GetDeterministicValue().GetAsMatrix4()
    assert np.abs(loaded - X).max() < 1e-7
    R = loaded[:3, :3]
    assert np.abs(R.T @ R - np.eye(3)).max() < 1e-12


def test_camera_config_yaml_checks_the_base_config():
    base = CameraConfig()
    base.width = 0
    with pytest.raises(CalibrationExportError) as error:
        camera_config_yaml(np.eye(4), base=base)
    assert "image size must be positive" in one_line(error)
    with pytest.raises(CalibrationExportError):
        camera_config_yaml(np.eye(4), name="")


BAD_CAMERA_CONFIGS = {
    "width 0": ("width: 0\n", "image size must be positive"),
    "width -5": ("width: -5\n", "image size must be positive"),
    "height 0": ("height: 0\n", "image size must be positive"),
    "fps -1": ("fps: -1\n", "fps must be a finite positive number"),
    "fps NaN": ("fps: .nan\n", "fps must be a finite positive number"),
    "fps inf": ("fps: .inf\n", "fps must be a finite positive number"),
    "a NaN pose": ("X_PB:\n  translation: [.nan, 0, 0]\n", "X_PB has NaN or inf"),
    "a NaN rpy": ("X_PB:\n  rotation: !Rpy {deg: [.nan, 0, 0]}\n", "X_PB is not a finite pose"),
    "a zero-axis AngleAxis": ("X_PB: {rotation: !AngleAxis {angle_deg: 10, axis: [0, 0, 0]}}", "orthonormal"),
    "a random pose": ("X_PB: {translation: !UniformVector {min: [0, 0, 0], max: [1, 1, 1]}}", "fixed pose"),
    "z_near > z_far": ("z_near: 5\nz_far: 1\n", "0 < z_near < z_far"),
    "z_near 0": ("z_near: 0\n", "0 < z_near < z_far"),
    "clipping_near > clipping_far": ("clipping_near: 10\nclipping_far: 1\n", "0 < clipping_near"),
    "a negative focal length": ("focal: !FocalLength {x: -5}\n", "focal length"),
    "a field of view of 180 deg": ("focal: !FovDegrees {y: 180}\n", "field of view"),
    "a principal point outside": ("center_x: 1000\n", "center_x must be inside the image"),
    "output_delay >= 1/fps": ("fps: 10\noutput_delay: 0.1\n", "output_delay"),
    "a negative capture_offset": ("capture_offset: -1\n", "capture_offset"),
    "an empty name": ("name: ''\n", "name must not be empty"),
    "a duplicate key": ("width: 640\nwidth: 320\n", "line 2: duplicate key 'width'"),
    "an unknown key": ("widht: 640\n", "unknown"),
    "a wrong type": ("width: 1.5\n", "width"),
    "a syntax error": ("width: [640\n", "not valid YAML"),
    "an empty text": ("", "expected a YAML mapping"),
    "a list": ("- 1\n", "expected a YAML mapping"),
}


@pytest.mark.parametrize("case", BAD_CAMERA_CONFIGS, ids=list(BAD_CAMERA_CONFIGS))
def test_load_camera_config_refuses_what_drake_would_not_take(case):
    text, expected = BAD_CAMERA_CONFIGS[case]
    with pytest.raises(CalibrationExportError) as error:
        load_camera_config(text)
    assert expected in one_line(error)


BAD_PAYLOADS = {
    "mass NaN": ((np.nan, [0, 0, 0]), {}, "mass must be a finite number"),
    "mass 0": ((0.0, [0, 0, 0]), {}, "positive"),
    "mass -1": ((-1.0, [0, 0, 0]), {}, "positive"),
    "a NaN centre of mass": ((1.0, [np.nan, 0, 0]), {}, "p_KCm has NaN or inf"),
    "an inf centre of mass": ((1.0, [0, np.inf, 0]), {}, "p_KCm has NaN or inf"),
    "two coordinates": ((1.0, [0, 0]), {}, "p_KCm must be 3 numbers"),
    "a NaN inertia": ((1.0, [0, 0, 0]), {"I_BBcm": [np.nan, 1, 1, 0, 0, 0]}, "NaN or inf"),
    "a negative moment": ((1.0, [0, 0, 0]), {"I_BBcm": [-1, 1, 1, 0, 0, 0]}, "physically valid"),
    "no triangle inequality": ((1.0, [0, 0, 0]), {"I_BBcm": [1, 1, 5, 0, 0, 0]}, "triangle inequality"),
    "a semidefinite inertia": ((1.0, [0, 0, 0]), {"I_BBcm": [1, 1, 0, 0, 0, 0]}, "not positive definite"),
    "products too large": ((1.0, [0, 0, 0]), {"I_BBcm": [1, 1, 1, 2, 0, 0]}, "physically valid"),
}


@pytest.mark.parametrize("case", BAD_PAYLOADS, ids=list(BAD_PAYLOADS))
def test_payload_yaml_refuses_a_non_physical_payload(case):
    args, kwargs, expected = BAD_PAYLOADS[case]
    with pytest.raises(CalibrationExportError) as error:
        payload_yaml(*args, **kwargs)
    assert expected in one_line(error)


BAD_PAYLOAD_TEXTS = {
    "mass -1": ("mass: -1\n", "positive"),
    "mass 0": ("mass: 0\n", "positive"),
    "mass NaN": ("mass: .nan\n", "finite"),
    "no mass": ("frame: sensor\n", "positive"),
    "one coordinate": ("mass: 1\np_BoBcm: [1]\n", "p_BoBcm must be 3 numbers"),
    "a NaN centre of mass": ("mass: 1\np_BoBcm: [.nan, 0, 0]\n", "NaN or inf"),
    "an invalid inertia": ("mass: 1\nI_BBcm: [1, 1, 5, 0, 0, 0]\n", "physically valid"),
    "five inertia values": ("mass: 1\nI_BBcm: [1, 1, 1, 0, 0]\n", "6 numbers"),
    "an empty frame": ("mass: 1\nframe: ''\n", "frame"),
    "a duplicate key": ("mass: 1\nmass: 2\n", "duplicate key 'mass'"),
}


@pytest.mark.parametrize("case", BAD_PAYLOAD_TEXTS, ids=list(BAD_PAYLOAD_TEXTS))
def test_load_payload_refuses_a_non_physical_payload(case):
    text, expected = BAD_PAYLOAD_TEXTS[case]
    with pytest.raises(CalibrationExportError) as error:
        load_payload(text)
    assert expected in one_line(error)


def test_a_non_physical_payload_raises_instead_of_ending_the_interpreter():
    # Drake's own check ends the process, so this runs in a child that must survive every case.
    code = (
        "from sustain_drake.calibration_export import CalibrationExportError, SpatialInertiaConfig\n"
        "for mass in (-1.0, 0.0, float('nan')):\n"
        "    try:\n"
        "        SpatialInertiaConfig(mass=mass).spatial_inertia()\n"
        "    except CalibrationExportError as e:\n"
        "        print('raised:', e)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.count("raised: the payload mass must be") == 3, r.stdout


@settings(max_examples=500 if os.environ.get("SUSTAIN_DRAKE_FUZZ") == "long" else 60, deadline=None,
          database=None)  # fmt: skip
@given(
    text=st.one_of(
        st.text(max_size=200),
        st.lists(
            st.tuples(
                st.sampled_from(["width", "height", "fps", "z_near", "z_far", "mass", "p_BoBcm", "I_BBcm",
                                 "name", "frame", "X_PB", "focal", "center_x"]),
                st.sampled_from(["0", "-5", ".nan", ".inf", "1e308", "[1, 2, 3]", "[.nan, 0, 0, 0, 0, 0]",
                                 "''", "!FocalLength {x: 0}", "{translation: [0, 0, .nan]}", "abc", "{}",
                                 "1"]),
            ),
            max_size=6,
        ).map(lambda pairs: "".join(f"{k}: {v}\n" for k, v in pairs)),
    )
)
def test_fuzz_loaders_raise_only_the_documented_error(text):
    for load in (load_camera_config, load_payload):
        try:
            loaded = load(text)
        except CalibrationExportError as e:
            assert "\n" not in str(e)
            continue
        if load is load_payload:
            assert loaded.spatial_inertia().IsPhysicallyValid()
        else:
            assert np.isfinite(loaded.X_PB.GetDeterministicValue().GetAsMatrix4()).all()
