"""Hand-eye on scenes it was not tuned on (issue 27): the cells of the scene matrix
(``diagrams/sweeps/scene_matrix_{tuning,held_out}.yaml``, written by ``make_scene_matrix.py``) run by
``sustain_drake.sweeps`` on Dask and checked against ``experiments.targets``.

    .venv/bin/python bench/bench_scene_matrix.py --split tuning [--cells 0 1] [--workers 2] [--results]
    .venv/bin/python bench/bench_scene_matrix.py --split held_out [--results]
    .venv/bin/python bench/bench_scene_matrix.py --split tuning --arm second  (the second arm's cells)

Every cell is a whole run (110 s) of diagrams/hand_eye.yaml with the code's default hand-eye
settings in another scene: camera placement, resolution, tool, lighting, the person's path, the
slips and the camera move, the motion seed. Prints one row per cell (its scene by name, the first
convergence, the adoptions, the changes, false alarms, wrong adoptions, the worst tool point in use
and whether every target is met) and, per target, on how many cells it is met. Never tune on the
held-out set: run it to report, after the tuning set's changes are final.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import pandas as pd  # noqa: E402
from common import bench_main, failed, metrics_of  # noqa: E402
from make_scene_matrix import design, second_arm_design  # noqa: E402
from results_page import number  # noqa: E402

from sustain_drake.sweeps import every_target_met  # noqa: E402

SPLITS = ("tuning", "held_out")


def _met_all(row) -> bool:
    return bool(every_target_met(pd.DataFrame([row])).iloc[0])


def _scene(c: dict) -> str:
    if "placement" not in c:  # the second arm's cells
        return (f"second arm, 640x480, {c['tool']}, {c['lights']}, person behind, {c['disturbances']}, "
                f"seed {c['seed']}")
    return (f"{c['placement']}, {c['camera']}, {c['tool']}, {c['lights']}, person {c['person']}, "
            f"{c['disturbances']}, seed {c['seed']}")


def region_coverage(table) -> tuple[int, int]:
    """``(inside, judged)``: of the adoptions that report their camera's 95 % region (``metrics.json``'s
    ``camera_region_95_mm``/``_deg``), how many hold the true error in both."""
    inside = judged = 0
    for _, row in table.iterrows():
        if failed(row):
            continue
        for a in metrics_of(row, "hand_eye").get("adopted", []):
            if a.get("camera_region_95_mm") is None:
                continue
            judged += 1
            inside += (a["camera_position_error_mm"] <= a["camera_region_95_mm"]
                       and a["camera_rotation_error_deg"] <= a["camera_region_95_deg"])
    return inside, judged


def row_maker(cells: list[dict]):
    def row_text(row) -> str:
        scene = _scene(cells[int(row["cell"])])
        if failed(row):
            return f"| {row['cell']} | {scene} | failed: {row['error']} | | | | | | no |"
        m = metrics_of(row, "hand_eye")
        adoptions = "; ".join(
            f"{a['time_s']:.1f} s: {a['camera_position_error_mm']:.1f} / "
            f"{a['camera_rotation_error_deg']:.2f}, {a['tool_point_error_mm']:.1f}" for a in m["adopted"])
        changes = "; ".join(
            f"{d['kind'].replace('tool_', '').replace('head_', '')} {d['time_s']:.0f} s: "
            f"{number(d['detection_latency_s'])} s, {number(d['reconvergence_after_detection_s'], '.1f')} s"
            for d in m["disturbances"])
        in_use = (m.get("tool_point_in_use_worst") or {}).get("error_mm")
        return (f"| {row['cell']} | {scene} | {number(m['first_convergence_after_found_s'], '.1f')} s "
                f"| {adoptions or 'none'} | {changes} | {m['num_false_alarms']} "
                f"| {m.get('num_wrong_adoptions', '-')} | {number(in_use, '.1f')} "
                f"| {'yes' if _met_all(row) else 'no'} |")

    return row_text


COLUMNS = ["cell", "scene: placement, camera, tool, lights, person, disturbances, seed",
           "first convergence after found", "adoptions: time, camera mm / deg, tool point mm",
           "changes: detected after, re-converged after", "false alarms", "wrong adoptions",
           "tool point in use worst mm", "every target"]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--split", choices=SPLITS, required=True)
    parser.add_argument("--arm", choices=("first", "second"), default="first")
    args, rest = parser.parse_known_args(argv)
    name = "scene_matrix" if args.arm == "first" else "scene_matrix_second_arm"
    cells = (design() if args.arm == "first" else second_arm_design())[args.split]

    def every_target(table) -> list[str]:
        met = int(every_target_met(table).sum()) if not table.empty else 0
        converged = sum(bool(metrics_of(r, "hand_eye").get("adopted")) for _, r in table.iterrows())
        lines = [f"- every hand-eye target: met on {met} of {len(table)} cells ({args.split} set); "
                 f"a camera adopted on {converged}, an honest 'not converged' (none adopted) on "
                 f"{len(table) - converged}"]
        inside, judged = region_coverage(table)
        if judged:
            lines.append(f"- the adopted camera inside its own 95 % region (position and rotation): "
                         f"{inside} of {judged} adoptions that report one")
        return lines

    return bench_main(rest, __doc__, f"{name}_{args.split}.yaml", "hand_eye", COLUMNS,
                      row_maker(cells), extra=every_target, block=f"bench_{name}_{args.split}")


if __name__ == "__main__":
    raise SystemExit(main())
