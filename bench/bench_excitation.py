"""Motion that excites what is unknown (issue 25, item 4): the payload identification of
``diagrams/inertia_touch.yaml`` with the babbling's random postures and with each posture chosen
for the information its rest adds (``kinesthetic.excite``), on the same motion seeds: the cells of
``diagrams/sweeps/kinesthetic_excitation.yaml`` run by ``sustain_drake.sweeps`` on Dask.

    .venv/bin/python bench/bench_excitation.py [--workers 2] [--out DIR] [--results]

Prints one row per seed: the identification time, the mass and centre-of-mass errors and the
samples at convergence, random and chosen; then, for the seeds the chooser was designed on (11,
1-9), the held-out seeds it ran once before its moves kept clear of contact (12-21) and those held
out after that (22-31) apart, the median identification times, their ratio (the target: at least
2x sooner) and the median errors.
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import bench_main, failed, metrics_of  # noqa: E402
from results_page import number  # noqa: E402

# The seeds the chooser was designed on; held out, run once before the clearance (seen since); held
# out, fixed after it.
GROUPS = {"design": {11, 1, 2, 3, 4, 5, 6, 7, 8, 9}, "held out, seen": set(range(12, 22)),
          "held out": set(range(22, 32))}
FIGURES = ("identification_time_s", "mass_error_percent", "com_error_mm", "samples_at_convergence")


def _by_seed(table) -> dict:
    """``{seed: {excite: metrics}}``; a failed cell or one never identified gives None figures."""
    seeds: dict = {}
    for _, row in table.iterrows():
        m = {} if failed(row) else metrics_of(row, "kinesthetic")
        excite = str(row["axis.kinesthetic.excite"]).lower() == "true"
        seeds.setdefault(int(row["axis.motion.seed"]), {})[excite] = {f: m.get(f) for f in FIGURES}
    return seeds


def _side(m: dict | None) -> list[str]:
    if m is None:
        return ["-"] * 4
    return [number(m["identification_time_s"], ".2f"), number(m["mass_error_percent"], ".3f"),
            number(m["com_error_mm"], ".2f"), number(m["samples_at_convergence"], "d")]


def _median(seeds: dict, excite: bool, figure: str) -> float | None:
    values = [s[excite][figure] for s in seeds.values() if excite in s]
    if any(v is None for v in values) or not values:
        return None  # a run never identified: no median time to compare
    return statistics.median(values)


def summary_lines(table) -> list[str]:
    seeds = _by_seed(table)
    lines = ["| seed | set | random: identified (s) | mass (%) | CoM (mm) | samples | chosen: identified (s) "
             "| mass (%) | CoM (mm) | samples |", "|" + "---|" * 10]
    group_of = {seed: name for name, members in GROUPS.items() for seed in members}
    order = list(GROUPS)
    for seed in sorted(seeds, key=lambda s: (order.index(group_of.get(s, "held out")), s)):
        sides = [*_side(seeds[seed].get(False)), *_side(seeds[seed].get(True))]
        lines.append("| " + " | ".join([str(seed), group_of.get(seed, "held out"), *sides]) + " |")
    for name, members in GROUPS.items():
        part = {s: v for s, v in seeds.items() if s in members}
        if not part:
            continue
        random, chosen = (_median(part, e, "identification_time_s") for e in (False, True))
        ratio = f"{random / chosen:.2f}x sooner" if random and chosen else "-"
        errors = ", ".join(f"{f.split('_')[0]} {number(_median(part, False, f), '.3f')} -> "
                           f"{number(_median(part, True, f), '.3f')}" for f in FIGURES[1:3])
        lines.append(f"- {name} seeds ({len(part)}): median identification {number(random, '.2f')} s -> "
                     f"{number(chosen, '.2f')} s ({ratio}; target >= 2x); median errors random -> chosen: "
                     f"{errors} (% and mm)")
    return lines


def main(argv=None) -> int:
    return bench_main(argv, __doc__, "kinesthetic_excitation.yaml", None, [], None,
                      extra=summary_lines, block="bench_excitation")


if __name__ == "__main__":
    raise SystemExit(main())
