"""Kinesthetic coordination (issue 6) over several babbling seeds: identification time and
accuracy, touch-point errors against the true contacts.

Runs ``diagrams/inertia_touch.yaml`` (the whole scenario, headless, no replay) once per motion
seed and prints one row per seed plus the worst case: when the payload was identified, the mass
and centre-of-mass errors of the adopted estimate, and the touch-point errors (median / max, mm,
contact forces >= 5 N), touches felt, false touch samples.

    .venv/bin/python bench/bench_kinesthetic.py [--seeds 11 1 2 3 4] [--duration 80] [--gap G]

``--gap`` overrides the convergence gap ``kinesthetic.coordination.min_gap_ratio`` (with a short
``--duration``, e.g. 12 s, only the identification is compared).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

sys.path.insert(0, str(Path(__file__).resolve().parent))
from seeds import publish  # noqa: E402  (bench/seeds.py)

from sustain_drake.experiments import kinesthetic  # noqa: E402
from sustain_drake.station import build_station, load_scenario  # noqa: E402

SCENARIO = Path(__file__).resolve().parents[1] / "diagrams" / "inertia_touch.yaml"


def run(seed: int, duration: float, gap: float | None = None) -> dict:
    scenario = load_scenario(SCENARIO)
    scenario.motion.seed = seed
    if gap is not None:
        scenario.kinesthetic.coordination.min_gap_ratio = gap
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(scenario))
    handle = kinesthetic.add_to_diagram(builder, station, scenario)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(duration)
    with tempfile.TemporaryDirectory() as out:
        return kinesthetic.finish(handle, diagram, simulator.get_context(), out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[11, 1, 2, 3, 4])
    parser.add_argument("--duration", type=float, default=80.0)
    parser.add_argument("--gap", type=float, help="override the payload's min_gap_ratio")
    parser.add_argument("--results", action="store_true", help="also write the table on docs/results.md")
    args = parser.parse_args()
    table = ["| seed | identified (s) | mass error (%) | CoM error (mm) | touch median / max (mm) "
             "| touches felt | false touch samples | re-identifications |",
             "|---|---|---|---|---|---|---|---|"]
    print("\n".join(table))
    for seed in args.seeds:
        m = run(seed, args.duration, args.gap)
        t = m["touch"]

        cells = [str(seed), _num(m["identification_time_s"], ".2f"), _num(m.get("mass_error_percent"), ".3f"),
                 _num(m.get("com_error_mm"), ".2f"),
                 f"{_num(t['median_mm'], '.2f')} / {_num(t['max_mm'], '.2f')}",
                 str(t.get("touches_felt", "-")), str(t["false_touch_samples"]), str(m["change_detections"])]
        table.append("| " + " | ".join(cells) + " |")
        print(table[-1], flush=True)
    if args.results:
        publish("bench_kinesthetic", table)


def _num(value, fmt: str) -> str:
    return "-" if value is None else format(value, fmt)


if __name__ == "__main__":
    main()
