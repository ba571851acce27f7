"""Scenario files: a file of one scenario or of several named ones read into a ``Scenario``, checked
before anything is built (``station.validation``), named for a run's outputs, and given one seed.

``scenario`` holds the dataclasses; ``scenario_yaml`` the YAML-level checks; ``validation`` the
ranges; this module puts them together (nothing imports it back)."""

import copy
import dataclasses
from pathlib import Path

import numpy as np
import yaml
from pydrake.common.yaml import yaml_load_typed

from sustain_drake.station.scenario import Scenario, ScenarioError, one_line
from sustain_drake.station.scenario_yaml import (
    check_duplicate_keys,
    load_problem,
    raw_document,
    shape_problem,
)
from sustain_drake.station.validation import validate_scenario

__all__ = ["SEED_START_SPREAD", "load_scenario", "load_scenario_string", "scenario_label", "scenario_name_in",
           "validate_scenario", "with_seed"]


def load_scenario(filename: str | Path, scenario_name: str | None = None) -> Scenario:
    """Loads and checks a scenario file; every problem is a one-line ``ScenarioError`` naming the
    key, raised before anything is built (see ``validate_scenario``).

    A file is either one scenario (its top-level keys are ``Scenario`` fields) or several named
    scenarios (its top-level keys are names; a variant is a YAML merge of a base, ``<<: *base``).
    ``scenario_name`` picks one of several; None picks the one named like the file (``hand_eye``
    in ``hand_eye.yaml``) or the only one. A key given twice in one mapping is an error."""
    path = Path(filename)
    name = scenario_name_in(path, scenario_name)
    try:
        return _load_text(path.read_text(encoding="utf-8"), name)
    except (OSError, UnicodeDecodeError) as e:
        raise ScenarioError(f"{path}: not a readable YAML file ({one_line(e)})") from None
    except ScenarioError as e:
        raise ScenarioError(f"{_where(path, name)}: {e}") from None


def _load_text(text: str, name: str | None) -> Scenario:
    """The scenario ``name`` (None: the whole document) of the YAML ``text``, checked."""
    check_duplicate_keys(text)
    raw = raw_document(text)
    root = raw.get(name) if isinstance(raw, dict) and name is not None else raw
    if isinstance(root, dict):
        problem = shape_problem(root, Scenario, "")
        if problem:
            raise ScenarioError(problem)
    try:
        scenario = yaml_load_typed(schema=Scenario, data=text, child_name=name)
    except Exception as e:  # yaml_load_typed raises RuntimeError/ValueError/TypeError/yaml errors
        raise ScenarioError(load_problem(text, name, e)) from None
    validate_scenario(scenario, experiments=True)
    return scenario


def scenario_name_in(filename: str | Path, scenario_name: str | None = None) -> str | None:
    """The name of the scenario ``load_scenario`` reads from ``filename``: None for a file that is
    one scenario, else ``scenario_name`` checked against the file's names (see ``load_scenario``)."""
    path = Path(filename)
    if not path.is_file():
        raise ScenarioError(f"{path}: no such scenario file")
    names = _top_level_keys(path)
    fields = {f.name for f in dataclasses.fields(Scenario)}
    if set(names) <= fields:  # one scenario
        if scenario_name is not None:
            raise ScenarioError(f"{path} holds one scenario, not named ones: leave out the scenario name "
                                f"({scenario_name!r})")
        return None
    if scenario_name is None:
        if path.stem in names or len(names) == 1:
            return path.stem if path.stem in names else names[0]
        raise ScenarioError(f"{path} holds the scenarios {', '.join(names)}: name one")
    if scenario_name not in names:
        raise ScenarioError(f"{path} has no scenario {scenario_name!r} (it has {', '.join(names)})")
    return scenario_name


def scenario_label(filename: str | Path, scenario_name: str | None = None) -> str:
    """A run's name for its outputs: the scenario's name, or the file's stem for a one-scenario file."""
    return scenario_name_in(filename, scenario_name) or Path(filename).stem


def _top_level_keys(path: Path) -> list[str]:
    """The top-level keys of a YAML file, read without building its values (tags are Drake's)."""
    try:
        node = yaml.compose(path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError, OSError) as e:
        raise ScenarioError(f"{path}: not a readable YAML file ({one_line(e)})") from None
    if node is None:
        return []
    if not isinstance(node, yaml.MappingNode):
        raise ScenarioError(f"{path}: a scenario file is a mapping of keys to values")
    return [k.value for k, _ in node.value]


def _where(path: Path, name: str | None) -> str:
    return f"{path}" if name is None else f"{path} [{name}]"


def load_scenario_string(data: str, name: str = "<string>") -> Scenario:
    """Like ``load_scenario`` for the YAML text of one scenario (tests, embedding, sweeps)."""
    try:
        return _load_text(data, None)
    except ScenarioError as e:
        raise ScenarioError(f"{name}: {e}") from None


# A seed delays the distractor's start by up to this (s), so seeds differ in its phase too.
SEED_START_SPREAD = 3.0


def with_seed(scenario: Scenario, seed: int) -> Scenario:
    """A copy of ``scenario`` with one seed for the whole run: the motion generator's, the depth and
    wrench noise's (offset, to keep the streams apart), and the distractor's start, delayed by a
    seeded 0-``SEED_START_SPREAD`` s."""
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ScenarioError(f"a seed must be an integer >= 0, got {seed!r}")
    seeded = copy.deepcopy(scenario)
    seeded.motion.seed = int(seed)
    seeded.depth_noise.seed = int(seed) + 1000
    seeded.wrench_sensor.seed = int(seed) + 2000
    delay = np.random.default_rng([int(seed), 2024]).uniform(0.0, SEED_START_SPREAD)
    seeded.distractor.start_time += float(delay)
    validate_scenario(seeded, experiments=True)
    return seeded
