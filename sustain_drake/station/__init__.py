"""Scenario files -> Diagrams: the simulated world of the paper's experiments.

``load_scenario(path, name)`` reads a scenario YAML file (``diagrams/*.yaml``) into a ``Scenario``;
``build_station(scenario)`` returns the Diagram with the exported ports listed in docs/simulation.md.
"""

from sustain_drake.station.build import (
    EXPORTED_OUTPUTS,
    babbling_joints,
    babbling_ranges,
    build_station,
    camera_info,
    hand_frame,
    held_shape,
    sensor_frame,
    sensor_pose_in_hand,
)
from sustain_drake.station.models import models_dir
from sustain_drake.station.scenario import Scenario, ScenarioError
from sustain_drake.station.scenario_files import load_scenario

__all__ = ["EXPORTED_OUTPUTS", "Scenario", "ScenarioError", "babbling_joints", "babbling_ranges",
           "build_station", "camera_info", "hand_frame", "held_shape", "load_scenario", "models_dir",
           "sensor_frame", "sensor_pose_in_hand"]
