"""Tuning on the scene matrix: runs cells of its TUNING set with some hand-eye settings changed, for
a part of the run, and prints each run's adoptions (issue 27; never the held-out set).

    .venv/bin/python bench/bench_scene_variant.py --cells 9 15 17 --duration 45 \\
        --set hand_eye.min_samples=200

Each ``--set KEY=VALUE`` is a dotted scenario key and a YAML value, as a sweep's axes are. The runs
go to ``--out``/cell<N> (log.npz, metrics.json); ``--duration`` 45 s stops before the matrix's first
slip (45-50 s), enough to compare first adoptions. docs/hand_eye_record.md keeps what was tried.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import yaml
from pydrake.common.yaml import yaml_load_typed

sys.path.insert(0, str(Path(__file__).resolve().parent))
from make_scene_matrix import SWEEPS  # noqa: E402

from sustain_drake.experiments.run import simulate_scenario  # noqa: E402
from sustain_drake.station.scenario import Scenario, ScenarioError
from sustain_drake.station.scenario_files import load_scenario_string, validate_scenario
from sustain_drake.sweeps import load_sweep  # noqa: E402
from sustain_drake.sweeps.spec import override_document  # noqa: E402


def _with_settings(scenario, settings: list[str]):
    """``scenario`` with each ``KEY=VALUE`` (dotted key, YAML value) merged in as a sweep's axis is."""
    values = {}
    for setting in settings:
        key, sep, value = setting.partition("=")
        if not sep or not key:
            raise SystemExit(f"--set {setting!r}: expected KEY=VALUE")
        try:
            values[key] = yaml.compose(value)
        except yaml.YAMLError as e:
            raise SystemExit(f"--set {setting!r}: not YAML ({str(e).splitlines()[0]})") from None
    if not values:
        return scenario
    try:
        return yaml_load_typed(schema=Scenario, data=override_document(values), defaults=scenario)
    except (RuntimeError, ValueError) as e:
        raise SystemExit(f"--set: {str(e).splitlines()[0]}") from None


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cells", type=int, nargs="+", required=True, help="tuning cells to run")
    p.add_argument("--duration", type=float, default=45.0, help="simulated seconds (default 45)")
    p.add_argument("--set", dest="settings", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--out", type=Path, default=Path("out/scene_variant"))
    args = p.parse_args(argv)
    sweep = load_sweep(SWEEPS / "scene_matrix_tuning.yaml")
    for index in args.cells:
        if not 0 <= index < len(sweep.cells):
            raise SystemExit(f"the tuning set has cells 0-{len(sweep.cells) - 1}, not {index}")
        scenario = _with_settings(load_scenario_string(sweep.cells[index].scenario_text), args.settings)
        try:
            validate_scenario(scenario, experiments=True)
        except ScenarioError as e:
            raise SystemExit(str(e)) from None
        out = args.out / f"cell{index}"
        simulate_scenario(scenario, out, duration=args.duration, replay=False)
        m = json.loads((out / "metrics.json").read_text())["hand_eye"]
        adoptions = "; ".join(
            f"{a['time_s']:.1f} s: {a['camera_position_error_mm']:.1f} mm / "
            f"{a['camera_rotation_error_deg']:.2f} deg, tool point {a['tool_point_error_mm']:.1f} mm"
            for a in m["adopted"]) or "nothing adopted"
        print(f"cell {index}: {adoptions}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
