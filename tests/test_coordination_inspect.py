"""make_sustainable_coordination's loops chosen at construction and its inspectable outputs (issue 28,
items 1 and 4): a loop that is off has no systems and no ports; an unconnected input or a wrong
argument is one line naming the port or the argument; every estimate has a validity flag and an
uncertainty; the followed point and the candidates' states are outputs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.geometry import Box
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator
from pydrake.systems.sensors import CameraInfo, ImageDepth32F, ImageRgba8U

from sustain_drake.identification import coordination
from sustain_drake.identification.candidates import Adoption, CandidateBank
from sustain_drake.identification.eye_to_hand import EyeToHandIdentifier
from sustain_drake.loops import HandEyeConfig, KinestheticConfig, Loops, make_sustainable_coordination
from sustain_drake.perception.optical_flow import TrackedFeatures
from sustain_drake.systems.coordination_outputs import (
    CONVERGED,
    EMPTY,
    IDENTIFYING,
    LEADER,
    AdoptedEstimates,
    FollowedPoint,
)

INFO = CameraInfo(160, 120, 1.0)
N = 6
RANGES = [[-1.0, 1.0]] * N
# A value for each input of the diagram.
VALUES = {"color_image": ImageRgba8U(160, 120), "depth_image": ImageDepth32F(160, 120),
          "joint_positions": np.zeros(N), "joint_velocities": np.zeros(N), "X_WH": RigidTransform(),
          "wrench": np.zeros(6), "image_time": [0.0]}  # fmt: skip


def _names(diagram, inputs: bool) -> set[str]:
    count, get = ((diagram.num_input_ports(), diagram.get_input_port) if inputs
                  else (diagram.num_output_ports(), diagram.get_output_port))  # fmt: skip
    return {get(i).get_name() for i in range(count)}


@pytest.mark.parametrize("missing", ["color_image", "depth_image", "joint_positions", "joint_velocities",
                                     "X_WH", "wrench"])  # fmt: skip
def test_an_unconnected_input_names_the_port_and_what_to_connect(missing):
    diagram = make_sustainable_coordination(INFO, N, joint_ranges=RANGES)
    context = diagram.CreateDefaultContext()
    for name in _names(diagram, inputs=True) - {missing, "image_time"}:  # image_time is optional
        diagram.GetInputPort(name).FixValue(context, VALUES[name])
    simulator = Simulator(diagram, context)
    with pytest.raises(RuntimeError) as error:
        simulator.Initialize()
    message = str(error.value)
    assert "\n" not in message
    expected = f"make_sustainable_coordination: input port '{missing}' is not connected; connect"
    assert message.startswith(expected)


def test_all_inputs_connected_initializes():
    diagram = make_sustainable_coordination(INFO, N, joint_ranges=RANGES)
    context = diagram.CreateDefaultContext()
    for name in _names(diagram, inputs=True) - {"image_time"}:
        diagram.GetInputPort(name).FixValue(context, VALUES[name])
    Simulator(diagram, context).AdvanceTo(0.05)


def test_a_loop_that_is_off_has_no_systems_and_no_ports():
    hand_eye_only = make_sustainable_coordination(INFO, N, joint_ranges=RANGES, loops=Loops(payload=False))
    assert _names(hand_eye_only, inputs=True) == {"color_image", "depth_image", "image_time",
                                                  "joint_positions", "X_WH"}  # fmt: skip
    outputs = _names(hand_eye_only, inputs=False)
    assert not any(name.startswith("payload") for name in outputs) and "p_KCm" not in outputs
    assert {"X_WC", "X_WC_valid", "followed_point", "candidate_states", "hand_eye_reset_reason"} <= outputs
    systems = {s.get_name() for s in hand_eye_only.GetSystems()}
    assert "candidate_identifiers" in systems and "payload_identifier" not in systems

    payload_only = make_sustainable_coordination(None, N, loops=Loops(hand_eye=False))
    assert _names(payload_only, inputs=True) == {"joint_velocities", "X_WH", "wrench"}
    outputs = _names(payload_only, inputs=False)
    assert not any(name.startswith("hand_eye") for name in outputs)
    assert not ({"X_WC", "p_HP", "motion_confirm", "followed_point"} & outputs)
    systems = {s.get_name() for s in payload_only.GetSystems()}
    assert "payload_identifier" in systems and "candidate_identifiers" not in systems
    assert "touch_estimator" not in systems

    touch = make_sustainable_coordination(None, N, loops=Loops(hand_eye=False, touch=True),
                                          held_shape=Box(0.04, 0.04, 0.2))  # fmt: skip
    assert {"touch", "p_WP", "f_env_W"} <= _names(touch, inputs=False)


@pytest.mark.parametrize("kwargs, argument", [
    (dict(loops=(True, False)), "loops must be a Loops"),
    (dict(loops=Loops(payload="no")), "loops.payload must be a bool, got 'no'"),
    (dict(loops=Loops(hand_eye=False, payload=False)), "loops has no loop on"),
    (dict(loops=Loops(payload=False, touch=True)), "loops.touch needs loops.payload"),
    (dict(loops=Loops(touch=True)), "loops.touch needs held_shape"),
    (dict(held_shape=Box(0.1, 0.1, 0.1)), "held_shape is an option of the touch loop"),
    (dict(X_KG=RigidTransform()), "X_KG is an option of the touch loop"),
    (dict(loops=Loops(payload=False), kinesthetic=KinestheticConfig()),
     "kinesthetic is an option of the payload"),
    (dict(loops=Loops(hand_eye=False), camera_info=INFO), "camera_info is an option of the hand_eye loop"),
    (dict(loops=Loops(hand_eye=False), camera_info=None, hand_eye=HandEyeConfig()),
     "hand_eye is an option of the hand_eye loop"),
    (dict(loops=Loops(hand_eye=False), camera_info=None, fps=15.0), "fps is an option of the hand_eye loop"),
    (dict(loops=Loops(hand_eye=False), camera_info=None, motion_seed=3), "motion_seed is an option"),
    (dict(hand_eye={"refine_points": True}), "hand_eye must be a HandEyeConfig, got dict"),
    (dict(kinesthetic=HandEyeConfig()), "kinesthetic must be a KinestheticConfig, got HandEyeConfig"),
    (dict(num_joints=0), "num_joints must be a positive integer, got 0"),
    (dict(num_joints=6.0), "num_joints must be a positive integer, got 6.0"),
    (dict(fps=-30.0), "fps must be > 0"),
    (dict(camera_info="160x120"), "camera_info must be a pydrake.systems.sensors.CameraInfo"),
])  # fmt: skip
def test_a_wrong_argument_is_one_line_naming_it(kwargs, argument):
    kwargs = {"camera_info": INFO, "num_joints": N, "joint_ranges": RANGES, **kwargs}
    loops = kwargs.get("loops")
    if isinstance(loops, Loops) and not loops.hand_eye:
        kwargs.pop("joint_ranges")
    camera_info, num_joints = kwargs.pop("camera_info"), kwargs.pop("num_joints")
    with pytest.raises((ValueError, TypeError)) as error:
        make_sustainable_coordination(camera_info, num_joints, **kwargs)
    assert argument in str(error.value) and "\n" not in str(error.value)


# ---- the inspectable outputs, fed at the unit level ------------------------------------------------
X_WC_TRUE = RigidTransform(RollPitchYaw(-1.6, 0.1, 2.5), [1.0, 1.0, 0.6])
P_HP_TRUE = np.array([0.01, -0.02, 0.3])


def _identified(noise: float = 1e-3, samples: int = 300, seed: int = 1):
    """An eye-to-hand identifier fed hand poses turning about every axis and the point seen with
    ``noise`` (m, per axis): its state and its solution."""
    rng = np.random.default_rng(seed)
    identifier = EyeToHandIdentifier()
    R_WC, p_WC = X_WC_TRUE.rotation().matrix(), X_WC_TRUE.translation()
    for _ in range(samples):
        R_WH = RollPitchYaw(rng.uniform(-0.6, 0.6, 3)).ToRotationMatrix().matrix()
        p_WH = np.array([0.5, 0.2, 0.4]) + rng.uniform(-0.2, 0.2, 3)
        p_CP = R_WC.T @ (R_WH @ P_HP_TRUE + p_WH - p_WC) + rng.normal(0.0, noise, 3)
        identifier.add(p_CP, R_WH, p_WH)
    return identifier.state, identifier.solve()


def test_the_adopted_estimates_have_validity_flags_and_uncertainty():
    system = AdoptedEstimates()
    context = system.CreateDefaultContext()
    port = system.GetOutputPort
    for name, value in (("hand_eye_solution", None), ("payload_solution", None), ("hand_eye_mode", [0.0]),
                        ("payload_mode", [0.0]), ("candidates", CandidateBank())):  # fmt: skip
        system.GetInputPort(name).FixValue(context, value)
    # Nothing adopted: every flag 0, the values mean nothing (never NaN), the uncertainty unknown.
    for name in ("X_WC_valid", "p_HP_valid", "payload_valid"):
        assert port(name).Eval(context)[0] == 0.0
    assert port("X_WC").Eval(context).IsExactlyIdentity()
    for name in ("X_WC_sd", "p_HP_sd", "payload_sd"):
        assert np.all(np.isinf(port(name).Eval(context)))

    statistic, solution = _identified()
    assert solution.verdict.converged
    bank = CandidateBank(adoptions=(Adoption(1.0, 7, statistic, 0.0, 0.0, solution.estimate),))
    system.GetInputPort("hand_eye_solution").FixValue(context, solution)
    system.GetInputPort("candidates").FixValue(context, bank)
    system.GetInputPort("hand_eye_mode").FixValue(context, [coordination.OBSERVE])
    assert port("X_WC_valid").Eval(context)[0] == 1.0 and port("p_HP_valid").Eval(context)[0] == 1.0
    X_WC = port("X_WC").Eval(context)
    assert X_WC.IsNearlyEqualTo(RigidTransform(solution.estimate.X_WC), 1e-12)
    sd, p_HP_sd = port("X_WC_sd").Eval(context), port("p_HP_sd").Eval(context)
    assert np.all(np.isfinite(sd)) and np.all(sd > 0) and np.all(p_HP_sd > 0)
    # 1 mm noise on 300 samples: sub-millimetre, sub-milliradian, and the error within 4 sd.
    assert np.all(sd[3:] < 1e-3) and np.all(sd[:3] < 2e-3) and np.all(p_HP_sd < 1e-3)
    error = np.abs(X_WC.translation() - X_WC_TRUE.translation())
    assert np.all(error < 4.0 * sd[3:] + 1e-5), (error, sd[3:])
    assert np.all(np.abs(port("p_HP").Eval(context) - P_HP_TRUE) < 4.0 * p_HP_sd + 1e-5)
    # Identifying again after an observation failure: the camera stays valid, the tool point not.
    system.GetInputPort("hand_eye_mode").FixValue(context, [coordination.IDENTIFY])
    assert port("X_WC_valid").Eval(context)[0] == 1.0 and port("p_HP_valid").Eval(context)[0] == 0.0
    assert np.all(np.isinf(port("p_HP_sd").Eval(context)))


def test_the_followed_point_and_the_candidates_states():
    system = FollowedPoint(max_candidates=3)
    context = system.CreateDefaultContext()
    port = system.GetOutputPort
    statistic, solution = _identified()
    unconverged = _identified(samples=5, seed=2)[1]
    from sustain_drake.identification.candidates import Candidate

    leader = Candidate(12, statistic, solution, 0.0, 1.0)
    other = Candidate(4, statistic, unconverged, 0.5, 1.0)
    features = TrackedFeatures(ids=np.array([3, 12]), p_px=np.array([[10.0, 20.0], [80.5, 60.25]]),
                               p_CP=np.array([[0.0, 0.0, 1.0], [0.1, 0.05, 0.9]]),
                               valid=np.array([True, True]))  # fmt: skip
    x = solution.x
    system.GetInputPort("tracked_features").FixValue(context, features)
    system.GetInputPort("reference_x").FixValue(context, np.zeros(16))
    system.GetInputPort("candidates").FixValue(context, CandidateBank(candidates=(other, leader)))
    # Identifying: no model, nothing followed; the candidates' states, the leader none yet.
    assert port("followed_point_valid").Eval(context)[0] == 0.0
    assert port("followed_point").Eval(context)[0] == -1.0
    states = port("candidate_states").Eval(context).reshape(3, 3)
    assert states[0].tolist() == [4, 5, IDENTIFYING]
    assert states[1].tolist() == [12, solution.num_samples, CONVERGED]
    assert states[2].tolist() == [-1, 0, EMPTY]
    # Observing the leader's feature: its id, pixel, measured point and the adopted p_HP.
    bank = CandidateBank(candidates=(other, leader), leader=12, observed=12)
    system.GetInputPort("candidates").FixValue(context, bank)
    system.GetInputPort("reference_x").FixValue(context, x)
    assert port("followed_point_valid").Eval(context)[0] == 1.0
    point = port("followed_point").Eval(context)
    np.testing.assert_array_equal(point[:6], [12, 80.5, 60.25, 0.1, 0.05, 0.9])
    np.testing.assert_array_equal(point[6:], x[12:15])
    states = port("candidate_states").Eval(context).reshape(3, 3)
    assert states[0].tolist() == [12, solution.num_samples, LEADER]
    # The observed feature lost from the frame (or unmeasured): not valid.
    features.valid[1] = False
    system.GetInputPort("tracked_features").FixValue(context, features)
    assert port("followed_point_valid").Eval(context)[0] == 0.0
    assert not math.isnan(port("followed_point").Eval(context).sum())
