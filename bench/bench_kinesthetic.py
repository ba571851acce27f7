"""Kinesthetic coordination (issue 6) over five babbling motions: the cells of
``diagrams/sweeps/kinesthetic_seeds.yaml`` run by ``sustain_drake.sweeps`` on Dask, checked against
``experiments.targets``: identification time and accuracy, touch-point errors against the true
contacts.

    .venv/bin/python bench/bench_kinesthetic.py [--cells 0 1] [--duration 12] [--workers 2] [--results]

Prints one row per cell: when the payload was identified, the mass and centre-of-mass errors of
the adopted estimate, the touch-point errors (median / max, mm, contact forces >= 5 N), touches
felt, false touch samples, re-identifications; then, per target, on how many cells it is met
(mass <= 1 %, centre of mass <= 2 mm, touch median <= 5 mm, no false touch, no re-identification).
With a short ``--duration`` (e.g. 12 s) only the identification is compared.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import axis_text, bench_main, failed, metrics_of  # noqa: E402
from results_page import number  # noqa: E402


def row_text(row) -> str:
    if failed(row):
        return f"| {axis_text(row)} | failed: {row['error']} | | | | | | |"
    m = metrics_of(row, "kinesthetic")
    t = m["touch"]
    cells = [axis_text(row), number(m["identification_time_s"], ".2f"),
             number(m.get("mass_error_percent"), ".3f"), number(m.get("com_error_mm"), ".2f"),
             f"{number(t['median_mm'], '.2f')} / {number(t['max_mm'], '.2f')}",
             str(t.get("touches_felt", "-")), str(t["false_touch_samples"]), str(m["change_detections"])]
    return "| " + " | ".join(cells) + " |"


COLUMNS = ["cell", "identified (s)", "mass error (%)", "CoM error (mm)", "touch median / max (mm)",
           "touches felt", "false touch samples", "re-identifications"]


def main(argv=None) -> int:
    return bench_main(argv, __doc__, "kinesthetic_seeds.yaml", "kinesthetic", COLUMNS, row_text)


if __name__ == "__main__":
    raise SystemExit(main())
