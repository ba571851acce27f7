"""Motion that excites what is unknown, the hand-eye half (issue 25, item 4): the first
identification of ``diagrams/hand_eye.yaml`` with today's configuration, with fewer samples before
a point may converge, with the identifying motion's postures chosen for the information their
moves add (``hand_eye.excite``) and with a wider reach for them: the cells of
``diagrams/sweeps/hand_eye_excitation.yaml`` on Dask.

    .venv/bin/python bench/bench_hand_eye_excitation.py [--workers 2] [--out DIR] [--results]

Prints one row per run (seed): per variant, the first convergence after the adopted point was
found and the first adopted camera's errors; then per variant the medians and the ratio of the
median first convergence to today's (the target: at least 2x sooner, errors no worse).
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import bench_main, failed, metrics_of  # noqa: E402
from results_page import number  # noqa: E402

from sustain_drake.station.scenario_files import load_scenario_string  # noqa: E402


def _variant(row) -> tuple:
    """``(sort key, "N samples, chosen|farthest within R rad")`` from the cell's scenario: the most
    samples first (today's configuration), then by reach, the farthest draw before the chosen."""
    h = load_scenario_string(row["scenario"]).hand_eye
    pick = "chosen" if h.excite else "farthest"
    return ((-h.min_samples, h.identifying_motion_reach, h.excite),
            f"{h.min_samples} samples, {pick} within {h.identifying_motion_reach:g} rad")


def _figures(row) -> dict:
    """The first convergence after the point was found (s) and the first adopted camera's position
    (mm) and rotation (deg) errors; None where nothing converged or the cell failed."""
    m = {} if failed(row) else metrics_of(row, "hand_eye")
    first = (m.get("adopted") or [None])[0]
    return {"after_found_s": m.get("first_convergence_after_found_s"),
            "position_mm": None if first is None else first["camera_position_error_mm"],
            "rotation_deg": None if first is None else first["camera_rotation_error_deg"]}


def _median(values: list) -> float | None:
    return None if not values or any(v is None for v in values) else statistics.median(values)


def summary_lines(table) -> list[str]:
    runs: dict = {}
    keys: dict = {}
    for _, row in table.iterrows():
        key, name = _variant(row)
        keys[name] = key
        runs.setdefault(str(row["axis.seed"]), {})[name] = _figures(row)
    variants = sorted(keys, key=keys.get)
    runs = dict(sorted(runs.items(), key=lambda item: -1 if item[0] in ("~", "None") else int(item[0])))
    header = "| seed | " + " | ".join(f"{v}: after found (s) | camera mm / deg" for v in variants) + " |"
    lines = [header, "|" + "---|" * (1 + 2 * len(variants))]
    for seed, by_variant in runs.items():
        cells = []
        for v in variants:
            f = by_variant.get(v, {})
            cells += [number(f.get("after_found_s"), ".1f"),
                      f"{number(f.get('position_mm'), '.2f')} / {number(f.get('rotation_deg'), '.3f')}"]
        lines.append(f"| {seed} | " + " | ".join(cells) + " |")
    base = _median([r.get(variants[0], {}).get("after_found_s") for r in runs.values()]) if variants else None
    for v in variants:
        medians = {k: _median([r.get(v, {}).get(k) for r in runs.values()])
                   for k in ("after_found_s", "position_mm", "rotation_deg")}
        t = medians["after_found_s"]
        ratio = f"{base / t:.2f}x sooner than {variants[0]}" if base and t else "-"
        lines.append(f"- {v} ({len(runs)} runs): median first convergence {number(t, '.2f')} s after the "
                     f"point was found ({ratio}; target >= 2x); median first camera "
                     f"{number(medians['position_mm'], '.2f')} mm / "
                     f"{number(medians['rotation_deg'], '.3f')} deg")
    return lines


def main(argv=None) -> int:
    return bench_main(argv, __doc__, "hand_eye_excitation.yaml", None, [], None,
                      extra=summary_lines, block="bench_hand_eye_excitation")


if __name__ == "__main__":
    raise SystemExit(main())
