"""make_sustainable_coordination on our simulated station, from rendered images: the diagram's
hand-eye path (the pose input X_WH, the motion requests) converges to the true camera."""

import math
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from sustain_drake.identification import coordination
from sustain_drake.identification.rotation import rotation_angle
from sustain_drake.loops.coordination import make_sustainable_coordination
from sustain_drake.station import build_station, camera_info, load_scenario
from sustain_drake.station.scenario import ARM_JOINTS
from sustain_drake.systems.coordination_outputs import LEADER

ROOT = Path(__file__).resolve().parents[1]


def test_rendered_images_to_an_adopted_camera_through_the_diagram():
    scenario = load_scenario(ROOT / "diagrams" / "hand_eye.yaml")
    scenario.distractor.enabled = False
    scenario.disturbances = []
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(scenario))
    sc = builder.AddSystem(make_sustainable_coordination(
        camera_info(scenario), len(ARM_JOINTS), fps=scenario.camera.fps, hand_eye=scenario.hand_eye,
        body_detection=scenario.body_detection, kinesthetic=scenario.kinesthetic,
        joint_ranges=scenario.motion.joint_ranges, motion_seed=scenario.motion.seed))  # fmt: skip
    for name in ("color_image", "depth_image", "image_time", "joint_positions", "joint_velocities", "X_WH",
                 "wrench"):  # fmt: skip
        builder.Connect(station.GetOutputPort(name), sc.GetInputPort(name))
    builder.Connect(sc.GetOutputPort("motion_confirm"), station.GetInputPort("motion_confirm"))
    builder.Connect(sc.GetOutputPort("hand_eye_pause"), station.GetInputPort("motion_pause"))
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(16.0)

    context = sc.GetMyContextFromRoot(simulator.get_context())
    events = sc.GetOutputPort("hand_eye_events").Eval(context)
    assert coordination.CONVERGED in [e.kind for e in events]
    assert sc.GetOutputPort("hand_eye_mode").Eval(context)[0] == coordination.OBSERVE
    X_WC = sc.GetOutputPort("X_WC").Eval(context)
    true_X_WC = station.GetOutputPort("true_X_WC").Eval(station.GetMyContextFromRoot(simulator.get_context()))
    # Millimetres from the truth (a wrong candidate is metres off), as in tests/test_hand_eye.py.
    assert np.linalg.norm(X_WC.translation() - true_X_WC.translation()) < 0.01
    R = X_WC.rotation().matrix().T @ true_X_WC.rotation().matrix()
    assert math.degrees(rotation_angle(R)) < 0.5
    # The inspectable outputs (issue 28, item 4): the camera and tool point valid, their 1 sd
    # millimetres, the leader among the candidates, and the followed point where the true camera
    # sees it (when it is in this frame).
    for name in ("X_WC_valid", "p_HP_valid"):
        assert sc.GetOutputPort(name).Eval(context)[0] == 1.0, name
    sd = sc.GetOutputPort("X_WC_sd").Eval(context)
    assert np.all(np.isfinite(sd)) and np.all(sd[3:] < 0.01), sd
    assert np.all(sc.GetOutputPort("p_HP_sd").Eval(context) < 0.01)
    states = sc.GetOutputPort("candidate_states").Eval(context).reshape(-1, 3)
    assert states[0, 2] == LEADER
    point = sc.GetOutputPort("followed_point").Eval(context)
    if sc.GetOutputPort("followed_point_valid").Eval(context)[0]:
        u, v = point[1:3]
        info = camera_info(scenario)
        assert 0 <= u < info.width() and 0 <= v < info.height()
        X_WH = sc.GetOutputPort("X_WH_used").Eval(context)
        assert np.linalg.norm(true_X_WC @ point[3:6] - X_WH @ point[6:9]) < 0.01
