"""The hand-eye section holds a few user settings (``HandEyeConfig``); every other threshold is a
constant of ``hand_eye_parts``, the measured configuration."""

import dataclasses

import pytest
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.sensors import CameraInfo

from sustain_drake.loops.body_detection import BodyDetectionConfig
from sustain_drake.loops.hand_eye import (
    HandEyeConfig,
    HandEyeParts,
    add_hand_eye_loop,
    hand_eye_parts,
    noise_floor,
)
from sustain_drake.systems.depth_noise import DepthNoiseModel


def test_at_most_twenty_user_settings():
    assert len(dataclasses.fields(HandEyeConfig)) <= 20


def test_the_noise_floor_is_the_sensors_sigma_rounded_up():
    # sigma(0.6 m) = 1.2 mm + 1.9 mm/m^2 * 0.04 m^2 = 1.276 mm -> 1.3 mm: the measured value, exactly
    assert noise_floor(DepthNoiseModel()) == 0.0013
    assert noise_floor(DepthNoiseModel(a=0.002, b=0.0, z0=0.4)) == 0.002  # on a step: not raised
    assert noise_floor(DepthNoiseModel(a=0.00201, b=0.0, z0=0.4)) == pytest.approx(0.0021)
    noisier = hand_eye_parts(HandEyeConfig(depth_noise=DepthNoiseModel(a=0.003)))
    assert noisier.coordination.noise_rms == pytest.approx(0.0031)


def test_the_user_settings_reach_their_parts():
    config = HandEyeConfig(max_hand_radius=0.9, tool_radius=0.05, min_samples=120, max_expected_rms=0.004,
                           allowable_error_factor=50.0, max_consecutive_violations=7,
                           pause_after_convergence=2.0, max_candidates=5, camera_motion=False)
    parts = hand_eye_parts(config)
    c, k, r = parts.coordination, parts.candidates, parts.refinement
    assert (c.min_samples, c.max_expected_rms, c.allowable_error_factor) == (120, 0.004, 50.0)
    assert (c.max_consecutive_violations, c.pause_after_convergence) == (7, 2.0)
    assert (k.max_hand_radius, k.observe_radius, k.max_candidates) == (0.9, 0.05, 5)
    assert not parts.camera_motion.enabled and r.anchor_window_px == 8 and r.symmetry_window_px == 3
    default = hand_eye_parts(HandEyeConfig())
    assert default.camera_motion.enabled
    assert default.candidates.observe_radius == 0.1 and default.coordination.min_samples == 250


def test_a_study_passes_parts_with_a_constant_changed():
    """``add_hand_eye_loop`` takes ``HandEyeParts`` as well as a ``HandEyeConfig``: the candidates'
    system then runs with the changed constant."""
    parts = hand_eye_parts(HandEyeConfig(identifying_motion_interval=0.0))
    candidates = dataclasses.replace(parts.candidates, joint_consistency=3.0)
    study = dataclasses.replace(parts, candidates=candidates)
    assert isinstance(study, HandEyeParts)
    loop = add_hand_eye_loop(DiagramBuilder(), CameraInfo(160, 120, 1.0), 6, 30.0, study,
                             BodyDetectionConfig(confirm=False))
    assert loop.candidates.params.joint_consistency == 3.0
    loop = add_hand_eye_loop(DiagramBuilder(), CameraInfo(160, 120, 1.0), 6, 30.0, parts.config,
                             BodyDetectionConfig(confirm=False))
    assert loop.candidates.params.joint_consistency == 2.0
