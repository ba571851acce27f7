"""Body detection end to end (issue 4): ``sustain-drake simulate`` on a short, smaller version of
``body_detection.yaml`` marks arm cells and no distractor cell, and ``finish`` writes the metrics
and the pictures; the scenario section, the labels, the evaluation system and ``--seed``."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from sustain_drake.experiments import body_detection
from sustain_drake.experiments.run import simulate_file
from sustain_drake.loops.body_detection import BodyDetectionConfig
from sustain_drake.station import ScenarioError, build_station, load_scenario
from sustain_drake.station.scenario_files import with_seed

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "diagrams" / "body_detection.yaml"


def small_scenario(tmp_path: Path, extra: str = "") -> Path:
    """body_detection.yaml at 320 x 240 (a quarter of the rendering and tracking cost)."""
    text = SCENARIO.read_text().replace("width: 640", "width: 320").replace(
        "height: 480", "height: 240")
    assert "width: 320" in text and "height: 240" in text
    path = tmp_path / "small_body_detection.yaml"
    path.write_text(text + extra)
    return path


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("body_detection")
    out = tmp / "out"
    result = simulate_file(small_scenario(tmp), seed=3, out=out, duration=6.0, replay=False)
    return out, json.loads(result.metrics.read_text())


def test_a_short_run_marks_arm_cells_and_no_distractor_cell(short_run):
    _, metrics = short_run
    m = metrics["body_detection"]
    assert m["evaluated"] and m["frames"] == pytest.approx(6.0 * 30, abs=2)
    assert m["distractor_cells"] >= 5            # the person did walk through the view
    assert m["distractor_cells_marked"] == 0
    assert m["true_positive"] >= 5               # arm/tool cells found within 6 s
    assert m["precision"] >= 0.9
    assert m["detector"]["confirm_trials"] >= 2  # found through confirming motions
    assert m["latency_cells"] == m["true_positive"] and m["latency_median_s"] >= 0


def test_finish_writes_the_metrics_and_the_pictures(short_run):
    out, metrics = short_run
    m = metrics["body_detection"]
    for key in ("precision", "recall", "iou", "distractor_cells_marked", "latency_median_s",
                "body_cells_true", "body_cells_marked", "parts", "detector"):
        assert key in m
    assert set(m["parts"]) == {"cells", "features"}
    assert m["body_cells_marked"] >= max(p["body_cells_marked"] for p in m["parts"].values())
    expected = {"likelihood_006.0s.png", "body_vs_truth.png"} | {
        f"likelihood_joint{i}.png" for i in range(1, 6)}
    assert expected <= set(m["pictures"])
    for name in m["pictures"]:
        image = cv2.imread(str(out / name))
        assert image is not None and image.shape == (240, 320, 3), name


def test_labels_are_the_moving_robot_bodies_and_the_person():
    scenario = load_scenario(SCENARIO)
    station = build_station(scenario)
    robot, person = body_detection.body_labels(station, scenario)
    plant = station.GetSubsystemByName("plant")
    names = {plant.get_body(BodyIndex(b)).name() for b in robot}
    assert "arm_base" not in names                      # welded to the world: never moves
    assert {"arm_link1", "arm_link5", "gripper", "tool"} <= names
    assert {plant.get_body(BodyIndex(b)).name() for b in person} >= {"person_body"}
    assert not set(robot) & set(person)


def test_the_scenario_section_builds_the_rule_and_rejects_bad_values():
    config = BodyDetectionConfig(tau_a=0.25, response_window=0.1, alpha=1e-4, feature_hits=3)
    params = config.coincidence_params()
    assert (params.tau_a, params.trial_window, params.alpha) == (0.25, 0.1, 1e-4)
    assert config.feature_params().hits == 3
    scenario = load_scenario(SCENARIO)
    assert scenario.body_detection.enabled and scenario.duration == 60.0
    rule = scenario.body_detection.coincidence_params()
    assert rule.trial_window == 0.2 and rule.stop_requests and rule.max_sequence_trials == 6
    assert rule.skip_busy_cells
    assert scenario.body_detection.feature_params().flow_threshold_px == 0.5
    assert (scenario.motion.confirm_step, scenario.motion.confirm_near) == (0.1, 0.2)
    scenario.body_detection.alpha = 2.0  # refused before any world is built
    with pytest.raises(ScenarioError, match="body_detection.alpha"):
        build_station(scenario)


def test_seed_overrides_motion_noise_and_distractor_start():
    a, b = load_scenario(SCENARIO), load_scenario(SCENARIO)
    start = a.distractor.start_time
    a, b = with_seed(a, 11), with_seed(b, 12)
    assert a.motion.seed == 11 and b.motion.seed == 12
    assert len({a.motion.seed, a.depth_noise.seed, a.wrench_sensor.seed}) == 3
    assert a.depth_noise.seed != b.depth_noise.seed
    assert start <= a.distractor.start_time <= start + 3.0
    assert a.distractor.start_time != b.distractor.start_time
    c = load_scenario(SCENARIO)
    c = with_seed(c, 11)
    assert c.distractor.start_time == a.distractor.start_time   # reproducible
    with pytest.raises(ScenarioError, match="seed must be an integer >= 0"):
        with_seed(c, -1)


def test_evaluation_state_clones_with_the_context():
    scenario = load_scenario(SCENARIO)
    scenario.camera.width, scenario.camera.height = 160, 120
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(scenario))
    handle = body_detection.add_to_diagram(builder, station, scenario)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(0.5)
    context = simulator.get_context()
    clone = context.Clone()
    evaluation = handle.evaluation
    frames = evaluation.evaluator(evaluation.GetMyContextFromRoot(context)).frames
    assert frames == pytest.approx(15, abs=1)
    simulator.AdvanceTo(0.7)
    assert evaluation.evaluator(evaluation.GetMyContextFromRoot(clone)).frames == frames
    assert evaluation.evaluator(evaluation.GetMyContextFromRoot(context)).frames > frames
    assert np.all(np.isfinite(evaluation.evaluator(
        evaluation.GetMyContextFromRoot(context)).to_vector()))

