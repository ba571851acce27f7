"""The station's ports plug into the perception systems: tracker and coincidence detector run
on the simulated camera and encoders, and the detector's confirm request drives the motion
generator (the paper's closed loop of §3.3)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from sustain_drake.station import build_station, camera_info, load_scenario
from sustain_drake.station.scenario import ARM_JOINTS
from sustain_drake.systems.motion_coincidence_detector import MotionCoincidenceDetector
from sustain_drake.systems.optical_flow_tracker import OpticalFlowTracker

ROOT = Path(__file__).resolve().parents[1]


def test_station_drives_the_tracker_and_detector():
    scenario = load_scenario(ROOT / "diagrams" / "hand_eye.yaml")
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(scenario))
    period = 1.0 / scenario.camera.fps
    grid = (6, 8)
    tracker = builder.AddSystem(OpticalFlowTracker(camera_info(scenario), grid, period=period))
    detector = builder.AddSystem(MotionCoincidenceDetector(
        len(ARM_JOINTS), grid[0] * grid[1], period=period))
    for name in ("color_image", "depth_image", "image_time"):
        builder.Connect(station.GetOutputPort(name), tracker.GetInputPort(name))
    builder.Connect(station.GetOutputPort("joint_positions"),
                    detector.GetInputPort("actuator_positions"))
    builder.Connect(tracker.GetOutputPort("visual_change"), detector.GetInputPort("visual_change"))
    builder.Connect(tracker.GetOutputPort("tracked_features"),
                    detector.GetInputPort("tracked_features"))
    builder.Connect(detector.GetOutputPort("confirm"), station.GetInputPort("motion_confirm"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(2.0)
    context = simulator.get_context()
    change = tracker.GetOutputPort("visual_change").Eval(
        tracker.GetMyContextFromRoot(context))
    assert change.shape == (grid[0] * grid[1],)
    assert np.all(np.isfinite(change)) and change.sum() > 0  # the babbling arm is seen moving
    q = station.GetOutputPort("joint_positions").Eval(station.GetMyContextFromRoot(context))
    assert np.all(np.isfinite(q))
