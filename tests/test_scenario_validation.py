"""Scenario validation (issue #23): every bad value of a scenario file is a one-line ``ScenarioError``
naming the key, raised before anything is built; a fuzz of the hand-eye scenario's values finds no
other exception. ``SUSTAIN_DRAKE_FUZZ=long`` runs the fuzz with many more examples."""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydrake.common.schema import Transform

from sustain_drake.station import ScenarioError, build_station, load_scenario
from sustain_drake.station.scenario import Scenario, scenario_text
from sustain_drake.station.scenario_files import (
    _top_level_keys,
    load_scenario_string,
    validate_scenario,
    with_seed,
)
from sustain_drake.station.validation import RANGES, range_of

ROOT = Path(__file__).resolve().parents[1]
HAND_EYE = ROOT / "diagrams" / "hand_eye.yaml"
FUZZ_LONG = os.environ.get("SUSTAIN_DRAKE_FUZZ") == "long"

# (scenario text, the key the one-line message must name): the issue's examples and their kin.
BAD = [
    # seeds: any integer >= 0
    ("motion: {seed: -1}\n", "motion.seed"),
    ("wrench_sensor: {seed: -1}\n", "wrench_sensor.seed"),
    ("depth_noise: {seed: -3}\n", "depth_noise.seed"),
    ("motion: {seed: 1.5}\n", "motion.seed"),
    ("motion: {seed: abc}\n", "motion.seed"),
    # fixed poses: finite, not random, a real rotation, within reach
    ("head: {X_WP: {translation: [.nan, 0, 0]}}\n", "head.X_WP"),
    ("head: {X_WP: {translation: [.inf, 0, 0]}}\n", "head.X_WP"),
    ("tool: {X_GT: {translation: [0, .nan, 0]}}\n", "tool.X_GT"),
    ("tool: {X_GT: {translation: [0, 0, .inf]}}\n", "tool.X_GT"),
    ("camera: {X_PB: {base_frame: 'head::camera_mount', translation: [.nan, 0, 0]}}\n", "camera.X_PB"),
    ("head: {X_WP: {translation: !UniformVector {min: [0, 0, 0], max: [1, 1, 1]}}}\n", "head.X_WP"),
    ("head: {X_WP: {rotation: !Uniform {}}}\n", "head.X_WP"),
    ("tool: {X_GT: {rotation: !Rpy {deg: !UniformVector {min: [0, 0, 0], max: [1, 1, 1]}}}}\n", "tool.X_GT"),
    ("camera: {X_PB: {base_frame: 'head::camera_mount', translation: !GaussianVector "
     "{mean: [0, 0, 0], stddev: [1, 1, 1]}}}\n", "camera.X_PB"),
    ("camera: {X_BC: {translation: !UniformVector {min: [0, 0, 0], max: [1, 1, 1]}}}\n", "camera.X_BC"),
    ("head: {X_WP: {rotation: !AngleAxis {angle_deg: 30, axis: [0, 0, 0]}}}\n", "head.X_WP.rotation"),
    ("head: {X_WP: {rotation: !Rpy {deg: [.nan, 0, 0]}}}\n", "head.X_WP"),
    ("head: {X_WP: {translation: [1, 2]}}\n", "head.X_WP.translation"),
    ("head: {X_WP: {translation: 3}}\n", "head.X_WP.translation"),
    ("tool: {X_GT: {rotation: !Rpy {deg: 5}}}\n", "tool.X_GT.rotation"),
    ("head: {X_WP: {translation: [100, 0, 0]}}\n", "head.X_WP.translation"),
    ("tool: {X_GT: {base_frame: grasp}}\n", "tool.X_GT.base_frame"),
    # speeds, rates and sizes: finite, positive, feasible
    ("distractor: {speed: .inf}\n", "distractor.speed"),
    ("distractor: {speed: 0}\n", "distractor.speed"),
    ("motion: {max_speed: .inf}\n", "motion.max_speed"),
    ("motion: {min_duration: .inf}\n", "motion.min_duration"),
    ("motion: {period: 0}\n", "motion.period"),
    ("camera: {fps: .inf}\n", "camera.fps"),
    ("camera: {fps: 10000}\n", "camera.fps"),
    ("camera: {width: 100000}\n", "camera.width"),
    ("camera: {height: 0}\n", "camera.height"),
    ("camera: {capture_offset: 0.5}\n", "camera.capture_offset"),
    ("wrench_sensor: {rate: .inf}\n", "wrench_sensor.rate"),
    ("wrench_sensor: {rate: 1e9}\n", "wrench_sensor.rate"),
    ("wrench_sensor: {force_noise: .inf}\n", "wrench_sensor.force_noise"),
    ("wrench_sensor: {torque_noise: -1}\n", "wrench_sensor.torque_noise"),
    ("wrench_sensor: {bias: [0, 0, 0, 0, 0, .nan]}\n", "wrench_sensor.bias[5]"),
    ("depth_noise: {z0: .nan}\n", "depth_noise.z0"),
    ("depth_noise: {a: .inf}\n", "depth_noise.a"),
    ("depth_noise: {b: -0.1}\n", "depth_noise.b"),
    ("distractor: {start_time: .nan}\n", "distractor.start_time"),
    ("distractor: {waypoints: [[0, 0], [0, 0]]}\n", "distractor.waypoints"),
    ("distractor: {waypoints: [[0, .nan], [1, 0]]}\n", "distractor.waypoints[0][1]"),
    ("duration: .inf\n", "duration"),
    # the plant: Drake's strings, a discrete step
    ("plant_config: {discrete_contact_approximation: foo}\n", "plant_config.discrete_contact_approximation"),
    ("plant_config: {contact_model: bar}\n", "plant_config.contact_model"),
    ("plant_config: {contact_surface_representation: quad}\n", "plant_config.contact_surface_representation"),
    ("plant_config: {time_step: 0.5}\n", "plant_config.time_step"),
    ("plant_config: {time_step: 0}\n", "plant_config.time_step"),
    ("plant_config: {time_step: 1e-9}\n", "plant_config.time_step"),  # a run that never ends
    ("plant_config: {time_step: .nan}\n", "plant_config.time_step"),
    ("plant_config: {penetration_allowance: -1}\n", "plant_config.penetration_allowance"),
    # angles, slips and the timeline
    ("motion: {initial_posture: [100, 0, 0, 0, 0]}\n", "motion.initial_posture[0]"),
    ("motion: {joint_ranges: [[-1, 1], [0, 1], [0, 1], [0, 1], [0, .inf]]}\n", "motion.joint_ranges[4][1]"),
    ("motion: {joint_ranges: [1, 2, 3, 4, 5]}\n", "motion.joint_ranges[0]"),
    ("disturbances: [!HeadMove {time: 1, pan: 1e6}]\n", "disturbances[0].pan"),
    ("disturbances: [!ToolSlip {time: 1, slide: 5}]\n", "disturbances[0].slide"),
    ("disturbances: [!ToolSlip {time: .nan}]\n", "disturbances[0].time"),
    ("disturbances: [!Touch {time: 1, f_T: [0, 0, .inf]}]\n", "disturbances[0].f_T[2]"),
    ("disturbances: {}\n", "disturbances"),
    ("head: {pan: 7}\n", "head.pan"),
    ("head: {tilt: .nan}\n", "head.tilt"),
    ("tool: {slide: 100}\n", "tool.slide"),
    ("tool: {pivot: -4}\n", "tool.pivot"),
    ("tool: {gripper_position: 1}\n", "tool.gripper_position"),
    # the experiments' settings
    ("hand_eye: {log_rate: 0}\n", "hand_eye.log_rate"),
    ("hand_eye: {log_rate: .inf}\n", "hand_eye.log_rate"),
    ("hand_eye: {max_candidates: 1000000000}\n", "hand_eye.max_candidates"),
    ("hand_eye: {min_samples: 0}\n", "hand_eye.min_samples"),
    ("hand_eye: {depth_noise: {a: .nan}}\n", "hand_eye.depth_noise.a"),
    ("hand_eye: {identifying_motion_interval: 2.0, identifying_motion_max_hold: 1.0}\n",
     "hand_eye.identifying_motion_max_hold"),
    ("kinesthetic: {quasi_static: {window: .nan}}\n", "kinesthetic.quasi_static.window"),
    ("body_detection: {snapshot_times: [10, .inf]}\n", "body_detection.snapshot_times[1]"),
    ("body_detection: {grid_rows: 1000}\n", "body_detection.grid_rows"),
    ("body_detection: {tau_a: 0.1, response_window: 0.2}\n", "body_detection.response_window"),
    # what the experiments need of the world
    ("body_detection: {enabled: true}\ncamera: {label: false}\n", "camera.label"),
    ("body_detection: {enabled: true}\ncamera: {rgb: false}\n", "camera.rgb"),
    ("hand_eye: {enabled: true}\ncamera: {depth: false}\n", "camera.depth"),
    ("hand_eye: {enabled: true}\nbody_detection: {enabled: true}\ncamera: {label: true}\n",
     "body_detection.confirm"),
    ("kinesthetic: {enabled: true}\n", "tool.model"),
    ("hand_eye: {enabled: true}\nwrench_sensor: {compensate_gripper: true}\n", "hand_eye.slip_from_wrench"),
    ("tool: {model: none}\ndisturbances: [!ToolSlip {time: 1}]\n", "disturbances[0]"),
    # the file itself: duplicate and unknown keys, types, tags
    ("duration: 1\nduration: 2\n", "duration"),
    ("motion:\n  seed: 1\n  seed: 2\n", "motion.seed"),
    ("motion: {max_sped: 1}\n", "motion.max_sped"),
    ("motion: 3\n", "motion"),
    ("motion:\n", "motion"),
    ("motion: {initial_posture: 3}\n", "motion.initial_posture"),
    ("camera: {width: 640.5}\n", "camera.width"),
    ("backdrop: {enabled: maybe}\n", "backdrop.enabled"),
    ("disturbances: [!Slip {time: 3}]\n", "!Slip"),
    ("disturbances: [!ToolSlip {time: 1, slide: abc}]\n", "disturbances[0].slide"),
]


def assert_one_line(error: ScenarioError, key: str) -> None:
    message = str(error)
    assert key in message, message
    assert "\n" not in message and "Traceback" not in message and "Failure at" not in message


@pytest.mark.parametrize("text, key", BAD, ids=[f"{i:02d}-{key}" for i, (_, key) in enumerate(BAD)])
def test_a_bad_value_is_a_one_line_error_naming_its_key(text, key):
    with pytest.raises(ScenarioError) as error:
        load_scenario_string(text)
    assert_one_line(error.value, key)


def test_the_table_holds_the_issues_examples():
    assert len(BAD) >= 40


def test_a_file_names_the_scenario_and_the_line_of_a_duplicate_key(tmp_path):
    path = tmp_path / "two.yaml"
    text = "a: &a\n  duration: 4.0\nb:\n  <<: *a\n  duration: 5.0\n"
    path.write_text(text)
    assert load_scenario(path, "b").duration == 5.0  # a merged key may be overridden
    path.write_text(text + "  motion:\n    seed: 1\n    seed: 2\n")
    for name in ("a", "b"):  # the file is refused, whichever scenario is asked for
        with pytest.raises(ScenarioError) as error:
            load_scenario(path, name)
        assert_one_line(error.value, "duplicate key 'b.motion.seed' on line 8 (first on line 7)")
        assert str(path) in str(error.value)


@pytest.mark.parametrize("seed", [-1, 1.5, True, "3"])
def test_with_seed_refuses_a_seed_that_is_no_integer_ge_0(seed):
    with pytest.raises(ScenarioError, match="seed"):
        with_seed(Scenario(), seed)


def test_huge_seeds_are_fine():
    assert load_scenario_string(f"motion: {{seed: {2**70}}}\n").motion.seed == 2**70
    assert with_seed(Scenario(), 2**40).motion.seed == 2**40


def test_a_scenario_set_in_python_is_checked_before_it_is_built():
    scenario = Scenario()
    scenario.wrench_sensor.rate = 1e9
    with pytest.raises(ScenarioError, match="wrench_sensor.rate"):
        build_station(scenario)
    scenario = Scenario()
    scenario.head.X_WP = Transform()
    scenario.head.X_WP.translation = [math.nan, 0.0, 0.0]
    with pytest.raises(ScenarioError, match="head.X_WP"):
        validate_scenario(scenario)


def test_the_world_alone_builds_without_an_experiments_images():
    """An experiment's needs are checked by the loaders (and when the experiment is added), not by
    ``build_station``: a test or a user may wire their own sources to the station."""
    scenario = Scenario()
    scenario.hand_eye.enabled = True
    scenario.camera.rgb = scenario.camera.depth = False
    validate_scenario(scenario)
    with pytest.raises(ScenarioError, match="camera.depth"):
        validate_scenario(scenario, experiments=True)
    with pytest.raises(ScenarioError, match="camera.depth"):
        with_seed(scenario, 1)


def named_scenarios():
    for path in sorted((ROOT / "diagrams").glob("*.yaml")):
        names = _top_level_keys(path)
        if set(names) <= {f.name for f in dataclasses.fields(Scenario)}:
            yield path, None
        else:
            yield from ((path, name) for name in names)


@pytest.mark.parametrize("path, name", list(named_scenarios()), ids=lambda v: getattr(v, "stem", v))
def test_every_shipped_scenario_loads_and_takes_a_seed(path, name):
    scenario = load_scenario(path, name)
    with_seed(scenario, 12345)


def numeric_keys(section, path=""):
    """The numeric keys of our own sections (not Drake's): (class, key, path, numbers)."""
    for f in dataclasses.fields(section):
        value = getattr(section, f.name)
        where = f"{path}.{f.name}" if path else f.name
        if dataclasses.is_dataclass(value):
            yield from numeric_keys(value, where)
        elif isinstance(value, list) and value and dataclasses.is_dataclass(value[0]):
            for i, item in enumerate(value):
                yield from numeric_keys(item, f"{where}[{i}]")
        else:
            flat = np.asarray(value, dtype=object).ravel() if isinstance(value, list) else [value]
            numbers = [v for v in flat if isinstance(v, int | float) and not isinstance(v, bool)]
            if numbers or f.name == "response_window":  # None by default: a number when set
                yield type(section), f.name, where, numbers


def test_every_numeric_key_has_a_stated_range():
    scenario = load_scenario_string("disturbances: [!ToolSlip {}, !HeadMove {}, !Touch {}]\n"
                                    "touch_motion: {targets: [{}]}\n")
    missing = [where for cls, key, where, _ in numeric_keys(scenario) if range_of(cls, key) is None]
    assert missing == []
    assert all(range_of(cls, key) is not None for cls in RANGES for key in RANGES[cls])


def test_the_defaults_lie_in_their_ranges():
    validate_scenario(Scenario())


# --- Fuzz: the hand-eye scenario, every key written out, with values changed ----------------------

BASE = scenario_text(load_scenario(HAND_EYE, "hand_eye"))


def value_sites(node, path=""):
    """(path, mapping node, key node) of every value in a composed YAML document."""
    if isinstance(node, yaml.MappingNode):
        for key, value in node.value:
            where = f"{path}.{key.value}" if path else key.value
            yield where, node, key
            yield from value_sites(value, where)
    elif isinstance(node, yaml.SequenceNode):
        for i, value in enumerate(node.value):
            yield from value_sites(value, f"{path}[{i}]")


NUM_SITES = len(list(value_sites(yaml.compose(BASE))))
SPECIAL = [math.nan, math.inf, -math.inf, 0, -1, -1e9, 1e9, 1e300, -1e-300, 2**70, -(2**70), True, False,
           None, "", "abc", "1e3", "nan", "-inf", [], {}, [1, 2], [math.nan] * 3, {"a": 1}, [[1, 2]]]
VALUES = st.one_of(
    st.sampled_from(SPECIAL),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(2**80), max_value=2**80),
    st.text(max_size=16),
    st.lists(st.one_of(st.floats(), st.integers(-5, 5)), max_size=4),
)


def mutated(changes) -> tuple[str, list]:
    root = yaml.compose(BASE)
    sites = list(value_sites(root))
    done = []
    for index, value in changes:
        where, mapping, key = sites[index % len(sites)]
        node = yaml.compose(yaml.safe_dump(value))
        mapping.value = [(k, node if k is key else v) for k, v in mapping.value]
        done.append((where, value))
    return yaml.serialize(root), done


def check_clean(text: str) -> None:
    """A clean load (every number finite but the documented .inf, every pose fixed) or a one-line
    ScenarioError: never another exception."""
    try:
        scenario = load_scenario_string(text)
    except ScenarioError as e:
        assert "\n" not in str(e) and str(e).strip() and "Failure at" not in str(e)
        return
    for cls, key, where, numbers in numeric_keys(scenario):
        values = np.asarray(numbers, dtype=float)
        assert np.all(np.isfinite(values) | (values == math.inf) & range_of(cls, key).off_inf), where
    assert scenario.head.X_WP.IsDeterministic() and scenario.camera.X_PB.IsDeterministic()


FUZZ = settings(max_examples=3000 if FUZZ_LONG else 150, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@FUZZ
@given(changes=st.lists(st.tuples(st.integers(0, NUM_SITES - 1), VALUES), min_size=1, max_size=3))
def test_fuzz_values_of_the_hand_eye_scenario(changes):
    text, done = mutated(changes)
    try:
        check_clean(text)
    except Exception as e:
        raise AssertionError(f"{done}: {type(e).__name__}: {e}") from e


@FUZZ
@given(at=st.integers(0, len(BASE)), cut=st.integers(0, 8), insert=st.text(max_size=12))
def test_fuzz_the_text_of_the_hand_eye_scenario(at, cut, insert):
    text = BASE[:at] + insert + BASE[at + cut:]
    try:
        check_clean(text)
    except Exception as e:
        raise AssertionError(f"at {at}, cut {cut}, insert {insert!r}: {type(e).__name__}: {e}") from e
