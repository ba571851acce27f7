"""Random disturbances (issue 23, item 6): the section ``random_disturbances`` expands, from its seed,
into the same slips and camera moves every time, within its ranges and limits, spaced within its
interval; bad values are one-line errors; ``diagrams/soak.yaml`` loads and covers its 30 minutes."""

from __future__ import annotations

import dataclasses
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from sustain_drake.experiments import hand_eye_metrics as m
from sustain_drake.experiments.run import simulate_scenario
from sustain_drake.experiments.targets import target_bound
from sustain_drake.provenance import source_commit
from sustain_drake.station import ScenarioError, load_scenario
from sustain_drake.station.random_disturbances import (
    HEAD_MOVE,
    SETTLE,
    SLIP,
    RandomDisturbances,
    draw,
)
from sustain_drake.station.scenario import HeadMove, ToolSlip, Touch, timeline
from sustain_drake.station.scenario_files import load_scenario_string

ROOT = Path(__file__).resolve().parents[1]
SOAK = ROOT / "diagrams" / "soak.yaml"
sys.path.insert(0, str(ROOT / "bench"))
import bench_soak  # noqa: E402

ON = RandomDisturbances(enabled=True, seed=5)
HEAD, TOOL = (0.0, 0.1), (0.0, 0.0)


def test_settle_is_the_detection_and_reconvergence_targets():
    assert SETTLE == (target_bound("hand_eye", "detection_latency_s")
                      + target_bound("hand_eye", "reconvergence_after_detection_s"))


def test_off_draws_nothing():
    assert draw(RandomDisturbances(), 1800.0) == []


def test_the_same_seed_draws_the_same_list_and_another_seed_another():
    assert draw(ON, 7200.0, HEAD, TOOL) == draw(dataclasses.replace(ON), 7200.0, HEAD, TOOL)
    assert draw(ON, 7200.0, HEAD, TOOL) != draw(dataclasses.replace(ON, seed=6), 7200.0, HEAD, TOOL)


@pytest.mark.parametrize("seed", range(20))
def test_times_sizes_and_states_are_within_the_ranges(seed):
    config = dataclasses.replace(ON, seed=seed)
    duration = 3 * 3600.0
    drawn = draw(config, duration, HEAD, TOOL)
    times = np.array([d.time for d in drawn])
    assert times[0] == config.start_time
    gaps = np.diff(times)
    assert np.all(gaps >= config.interval[0] - 1e-9) and np.all(gaps <= config.interval[1] + 1e-9)
    assert times[-1] <= duration - SETTLE < times[-1] + config.interval[1]  # the run is covered
    before = {SLIP: TOOL, HEAD_MOVE: HEAD}
    for d in drawn:
        previous = before[d.kind]
        assert np.allclose(np.subtract(d.state, previous), d.change)
        if d.kind == SLIP:
            assert config.slide[0] <= abs(d.change[0]) <= config.slide[1]
            assert config.pivot[0] <= abs(d.change[1]) <= config.pivot[1]
            assert abs(d.state[0] - TOOL[0]) <= config.slide_limit + 1e-12
            assert abs(d.state[1] - TOOL[1]) <= config.pivot_limit + 1e-12
            assert d.duration == config.slip_duration
        else:
            assert config.turn[0] - 1e-12 <= math.hypot(*d.change) <= config.turn[1] + 1e-12
            assert all(abs(s - c) <= config.turn_limit + 1e-12 for s, c in zip(d.state, HEAD, strict=True))
            assert d.duration == config.turn_duration
        before[d.kind] = d.state
    assert {d.kind for d in drawn} == {SLIP, HEAD_MOVE}


def test_slip_probability_picks_the_kind():
    assert {d.kind for d in draw(dataclasses.replace(ON, slip_probability=1.0), 3600.0)} == {SLIP}
    assert {d.kind for d in draw(dataclasses.replace(ON, slip_probability=0.0), 3600.0)} == {HEAD_MOVE}


def test_the_timeline_holds_the_drawn_and_the_listed_disturbances_in_order():
    s = load_scenario_string("duration: 900\nrandom_disturbances: {enabled: true, seed: 2}\n"
                             "disturbances: [!Touch {time: 500, f_T: [0, 0, 1]}]\n")
    events = timeline(s)
    assert [e.time for e in events] == sorted(e.time for e in events)
    assert sum(isinstance(e, Touch) for e in events) == 1
    drawn = draw(s.random_disturbances, 900.0, (s.head.pan, s.head.tilt), (s.tool.slide, s.tool.pivot))
    moves = [e for e in events if not isinstance(e, Touch)]
    assert [(type(e), e.time) for e in moves] == [
        (HeadMove if d.kind == HEAD_MOVE else ToolSlip, d.time) for d in drawn]


BAD = [
    ("random_disturbances: {seed: -1}\n", "random_disturbances.seed"),
    ("random_disturbances: {start_time: .nan}\n", "random_disturbances.start_time"),
    ("random_disturbances: {interval: [10, 300]}\n", "random_disturbances.interval[0]"),
    ("random_disturbances: {interval: [300, 120]}\n", "random_disturbances.interval"),
    ("random_disturbances: {interval: [120]}\n", "random_disturbances.interval"),
    ("random_disturbances: {interval: [120, .inf]}\n", "random_disturbances.interval[1]"),
    ("random_disturbances: {slip_probability: 1.5}\n", "random_disturbances.slip_probability"),
    ("random_disturbances: {slide: [0.04, 0.01]}\n", "random_disturbances.slide"),
    ("random_disturbances: {slide: [0.01, 1.0]}\n", "random_disturbances.slide[1]"),
    ("random_disturbances: {pivot: [-0.1, 0.3]}\n", "random_disturbances.pivot[0]"),
    ("random_disturbances: {slide_limit: 0.02}\n", "random_disturbances.slide_limit"),
    ("random_disturbances: {pivot_limit: 0.2}\n", "random_disturbances.pivot_limit"),
    ("random_disturbances: {turn: [0.03, 2.0]}\n", "random_disturbances.turn[1]"),
    ("random_disturbances: {turn_limit: 0.1}\n", "random_disturbances.turn_limit"),
    ("random_disturbances: {slip_duration: 0}\n", "random_disturbances.slip_duration"),
    ("random_disturbances: {turn_duration: .inf}\n", "random_disturbances.turn_duration"),
    ("random_disturbances: {enabled: maybe}\n", "random_disturbances.enabled"),
    ("random_disturbances: {seeds: 3}\n", "random_disturbances.seeds"),
    ("random_disturbances: {enabled: true}\ndisturbances: [!ToolSlip {time: 1}]\n", "random_disturbances"),
    ("random_disturbances: {enabled: true}\ntool: {model: none}\n", "random_disturbances"),
    # a drawn slip beyond what ToolSlip accepts (the configured grasp near its own limit)
    ("duration: 600\ntool: {slide: 0.14}\nrandom_disturbances: {enabled: true, slip_probability: 1}\n",
     "random_disturbances (drawn 0, !ToolSlip"),
]


@pytest.mark.parametrize(("text", "key"), BAD)
def test_a_bad_value_is_one_line_naming_the_key(text, key):
    with pytest.raises(ScenarioError) as error:
        load_scenario_string(text)
    message = str(error.value)
    assert "\n" not in message and key in message, message


def test_the_soak_covers_30_minutes_with_a_disturbance_every_2_to_5_minutes():
    s = load_scenario(SOAK)
    assert s.duration == 1800.0 and s.hand_eye.enabled and s.distractor.enabled and s.distractor.loop
    events = timeline(s)
    times = np.array([e.time for e in events])
    assert all(isinstance(e, ToolSlip | HeadMove) for e in events)
    assert times[0] == 120.0 and times[-1] <= 1800.0 - SETTLE
    assert np.all((np.diff(times) >= 120.0) & (np.diff(times) <= 300.0))
    assert times[-1] + 300.0 > 1800.0 - SETTLE  # no room left for another
    assert {type(e) for e in events} == {ToolSlip, HeadMove}
    assert load_scenario(SOAK).random_disturbances == s.random_disturbances  # the same draw each load
    assert timeline(load_scenario(SOAK)) == events


def test_the_adopted_camera_after_each_reconvergence():
    adopted = [{"time_s": 10.0, "camera_position_error_mm": 0.5, "camera_rotation_error_deg": 0.02,
                "tool_point_error_mm": 0.7, "kind": "identified"},
               {"time_s": 130.0, "camera_position_error_mm": 3.0, "camera_rotation_error_deg": 0.3,
                "tool_point_error_mm": 1.0, "kind": "identified"}]
    disturbances = [{"time_s": 120.0, "reconverged_s": 130.0}, {"time_s": 300.0, "reconverged_s": None}]
    after = m.adopted_after(disturbances, adopted)
    assert after[0] == {"time_s": 130.0, "camera_position_error_mm": 3.0, "camera_rotation_error_deg": 0.3,
                        "tool_point_error_mm": 1.0}
    assert after[1] is None


def test_the_soak_builds_and_lists_its_drawn_disturbances(tmp_path):
    """A 0.2 s run of the soak's whole diagram, with the soak bench's memory monitor sampling it
    every 0.1 s: the station plays the drawn timeline, the metrics list each of its disturbances (none
    happened yet), and the monitor reads the resident memory and the logs' samples."""
    s = load_scenario(SOAK)
    monitor = bench_soak.MemoryMonitor(0.1, tmp_path / "memory.json")
    simulate_scenario(s, tmp_path, duration=0.2, log_rate=10.0, replay=False, on_step=monitor)
    assert len(monitor.samples) == 2 and all(m["rss_mb"] > 0 and m["logs_mb"] > 0 for m in monitor.samples)
    written = json.loads((tmp_path / "memory.json").read_text())
    assert written["samples"] == monitor.samples and written["commit"] == source_commit()
    listed = json.loads((tmp_path / "metrics.json").read_text())["hand_eye"]["disturbances"]
    assert [(d["kind"], d["time_s"]) for d in listed] == [
        ("head_move" if isinstance(e, HeadMove) else "tool_slip", e.time) for e in timeline(s)]
    assert all(d["detected_s"] is None and d["adopted_after"] is None for d in listed)
