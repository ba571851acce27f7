"""A sweep file: a base scenario and axes of overrides, expanded into cells (whole scenarios).

.. code-block:: yaml

    scenario: ../hand_eye.yaml    # the base scenario file, relative to this file
    scenario_name: hand_eye       # optional: which scenario of a file of several
    duration: 130                 # optional: simulated seconds of every cell (default: the scenario's)
    grid:                         # every combination of these axes' values
      seed: [~, 1, 2]             # `seed` is station.scenario_files.with_seed; ~ keeps the scenario's seeds
      camera.width: [640, 1280]
    zip:                          # these axes together, value by value (lists of equal length)
      camera.width: [640, 1280]
      camera.height: [480, 720]

An axis is a scenario key by its dotted path (``motion.seed``, ``head.X_WP``, ``disturbances``);
its values are YAML, tags included (``!HeadMove {...}``). A cell is the base scenario with one
value of each axis merged in the way ``yaml_load_typed`` merges a file onto defaults (a mapping
sets only the keys it names; a list replaces the whole list). The cells are every combination of
the grid's axes, each combined with every row of the zip (a sampled design is a zip alone).
Every cell is built and validated when the file is loaded, so a bad path or value is a one-line
``SweepError`` before anything runs.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import yaml
from pydrake.common.yaml import yaml_load_typed

from sustain_drake.station.scenario import Scenario, ScenarioError, one_line, scenario_text
from sustain_drake.station.scenario_files import load_scenario, validate_scenario, with_seed

SEED_AXIS = "seed"
KEYS = ("scenario", "scenario_name", "duration", "grid", "zip")
_MAP = "tag:yaml.org,2002:map"
_STR = "tag:yaml.org,2002:str"
_NULL = "tag:yaml.org,2002:null"


class SweepError(ValueError):
    """A sweep file that cannot be run; the message is one line for the user."""


@dataclass(frozen=True)
class Cell:
    index: int
    overrides: tuple[tuple[str, str], ...]  # (axis, its value as one line of YAML), axis order
    scenario_text: str  # the whole scenario of this cell, every key (station.scenario_text)
    duration: float  # simulated seconds

    @property
    def id(self) -> str:
        """Names the cell by what it runs: the same scenario and duration, the same id."""
        text = f"{self.scenario_text}\nduration: {self.duration!r}\n"
        return hashlib.sha1(text.encode("utf-8")).hexdigest()[:12]


@dataclass(frozen=True)
class Sweep:
    path: Path
    base: Path
    scenario_name: str | None
    axes: tuple[str, ...]
    cells: tuple[Cell, ...]


def load_sweep(filename: str | Path) -> Sweep:
    """Reads a sweep file and builds every cell (see the module docstring)."""
    path = Path(filename)
    try:
        root = yaml.compose(path.read_text(encoding="utf-8"), Loader=yaml.SafeLoader)
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as e:
        raise SweepError(f"{path}: not a readable YAML file ({one_line(e)})") from None
    if not isinstance(root, yaml.MappingNode):
        raise SweepError(f"{path}: a sweep file is a mapping with the keys {', '.join(KEYS)}")
    top = {key.value: value for key, value in root.value}
    unknown = sorted(set(top) - set(KEYS))
    if unknown:
        raise SweepError(f"{path}: unknown key(s) {', '.join(unknown)} (a sweep file has "
                         f"{', '.join(KEYS)})")
    if "scenario" not in top:
        raise SweepError(f"{path}: no 'scenario' (the base scenario file)")
    base = (path.parent / _scalar(top["scenario"], "scenario", path)).resolve()
    name = _scalar(top["scenario_name"], "scenario_name", path) if "scenario_name" in top else None
    try:
        scenario = load_scenario(base, name)
    except ScenarioError as e:
        raise SweepError(f"{path}: the base scenario: {e}") from None
    duration = scenario.duration
    if "duration" in top:
        duration = _positive(_scalar(top["duration"], "duration", path), path)
    grid = _axes(top.get("grid"), "grid", path)
    zipped = _axes(top.get("zip"), "zip", path)
    both = sorted(set(grid) & set(zipped))
    if both:
        raise SweepError(f"{path}: the axis {both[0]} is both in grid and in zip")
    axes = (*grid, *zipped)
    for a, b in itertools.permutations(axes, 2):
        if b.startswith(a + "."):
            raise SweepError(f"{path}: the axes {a} and {b} overlap (one holds the other)")
    for axis in axes:
        _check_path(scenario, axis, path)
    lengths = {len(values) for values in zipped.values()}
    if len(lengths) > 1:
        raise SweepError(f"{path}: the zip's axes need lists of one length, got "
                         + ", ".join(f"{a}: {len(v)}" for a, v in zipped.items()))
    rows = list(zip(*zipped.values(), strict=True)) if zipped else [()]
    cells = []
    for combination in itertools.product(*grid.values()):
        for row in rows:
            values = dict(zip(axes, (*combination, *row), strict=True))
            cells.append(_cell(len(cells), scenario, values, duration, path))
    seen: dict[str, int] = {}
    for cell in cells:
        if cell.id in seen:
            raise SweepError(f"{path}: cells {seen[cell.id]} and {cell.index} run the same scenario")
        seen[cell.id] = cell.index
    return Sweep(path, base, name, axes, tuple(cells))


def _cell(index: int, base: Scenario, values: dict[str, yaml.Node], duration: float,
          path: Path) -> Cell:
    overrides = tuple((axis, node_text(node)) for axis, node in values.items())
    where = f"{path}: cell {index} ({', '.join(f'{a}={v}' for a, v in overrides)})"
    settings = {axis: node for axis, node in values.items() if axis != SEED_AXIS}
    try:
        scenario = base
        if settings:
            scenario = yaml_load_typed(schema=Scenario, data=override_document(settings), defaults=base)
            validate_scenario(scenario, experiments=True)
        if SEED_AXIS in values:
            seed = yaml.safe_load(yaml.serialize(values[SEED_AXIS]))
            if seed is not None:
                scenario = with_seed(scenario, seed)
    except Exception as e:  # yaml_load_typed raises RuntimeError/ValueError; ScenarioError
        raise SweepError(f"{where}: {one_line(e)}") from None
    return Cell(index, overrides, scenario_text(scenario), duration)


def override_document(values: dict[str, yaml.Node]) -> str:
    """The YAML mapping that sets each dotted path to its value: ``{"a.b": 1, "a.c": 2}`` ->
    ``a: {b: 1, c: 2}``, the values' nodes (and their tags) kept as written."""
    tree: dict = {}
    for axis, node in values.items():
        *parents, leaf = axis.split(".")
        level = tree
        for part in parents:
            level = level.setdefault(part, {})
        level[leaf] = node

    def to_node(item) -> yaml.Node:
        if isinstance(item, yaml.Node):
            return item
        return yaml.MappingNode(_MAP, [(yaml.ScalarNode(_STR, k), to_node(v)) for k, v in item.items()])
    return yaml.serialize(to_node(tree), Dumper=yaml.SafeDumper)


def node_text(node: yaml.Node) -> str:
    """A value as one line of YAML (flow style, tags kept): how the table and messages show it."""
    def flow(n: yaml.Node) -> yaml.Node:
        if isinstance(n, yaml.SequenceNode):
            return yaml.SequenceNode(n.tag, [flow(x) for x in n.value], flow_style=True)
        if isinstance(n, yaml.MappingNode):
            return yaml.MappingNode(n.tag, [(flow(k), flow(v)) for k, v in n.value], flow_style=True)
        return n
    text = yaml.serialize(flow(node), Dumper=yaml.SafeDumper, width=math.inf)
    return text.removesuffix("\n").removesuffix("\n...").strip()


def _axes(node: yaml.Node | None, key: str, path: Path) -> dict[str, list[yaml.Node]]:
    if node is None or (isinstance(node, yaml.ScalarNode) and node.tag == _NULL):
        return {}
    if not isinstance(node, yaml.MappingNode):
        raise SweepError(f"{path}: {key} maps scenario keys (dotted paths) to lists of values")
    axes = {}
    for k, v in node.value:
        axis = k.value
        if not isinstance(k, yaml.ScalarNode) or not axis or axis in axes:
            raise SweepError(f"{path}: {key}: {axis!r} is not a key or is repeated")
        if not isinstance(v, yaml.SequenceNode) or not v.value:
            raise SweepError(f"{path}: {key}.{axis}: needs a non-empty list of values")
        axes[axis] = list(v.value)
    return axes


def _check_path(scenario: Scenario, axis: str, path: Path) -> None:
    """A one-line error unless ``axis`` names a key of the scenario (or is ``seed``)."""
    if axis == SEED_AXIS:
        return
    value, walked = scenario, []
    for part in axis.split("."):
        names = _field_names(value)
        if names is None:
            raise SweepError(f"{path}: axis {axis}: {'.'.join(walked)} has no keys below it "
                             "(set it whole)")
        if part not in names:
            where = ".".join(walked) or "the scenario"
            raise SweepError(f"{path}: axis {axis}: {where} has no key {part!r} "
                             f"(it has {', '.join(names)})")
        value = getattr(value, part)
        walked.append(part)


def _field_names(value) -> list[str] | None:
    """The keys of a scenario section: a dataclass's fields or a Drake struct's ``__fields__``."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return [f.name for f in dataclasses.fields(value)]
    fields = getattr(type(value), "__fields__", None)
    if isinstance(fields, tuple | list) and fields and hasattr(fields[0], "name"):
        return [f.name for f in fields]
    return None


def _scalar(node: yaml.Node, key: str, path: Path) -> str:
    if not isinstance(node, yaml.ScalarNode) or node.tag == _NULL:
        raise SweepError(f"{path}: {key} needs a single value")
    return node.value


def _positive(text: str, path: Path) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise SweepError(f"{path}: duration must be a positive number of seconds, got {text!r}")
    return value
