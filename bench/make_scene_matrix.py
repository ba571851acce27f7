"""Writes the hand-eye scene matrix (issue 27): sampled scenes around diagrams/hand_eye.yaml, split
into a tuning set and a held-out set, as two sweep files.

    .venv/bin/python bench/make_scene_matrix.py   # diagrams/sweeps/scene_matrix_{tuning,held_out}.yaml

The split is drawn once from a fixed seed and committed before any tuning; the files are the
record (re-running this script must reproduce them byte for byte; a test checks). Every cell is a
whole run with a slip and a camera move. Axes and their values:

- camera placement: six head poses around the arm, each aimed at the workspace point ``TARGET``;
- camera: 640x480, 1280x720 and 720x720 (one field of view, 45 deg vertical);
- tool appearance: the checker rod, four workshop tools and no tool (the gripper's own points);
- lighting: Drake's default light, or one dimmer light from the side;
- the person: behind the arm, or walking between the camera and the arm;
- disturbances: five timelines of slips (1 cm / 0.1 rad to 5 cm / 0.5 rad, one with two slips) and
  camera moves (0.03 to 0.2 rad); without a tool, the camera moves only;
- the motion seed (the seed axis: motion, sensor noise and the person's start).

Each split holds every value of every axis at least twice (a balanced shuffle per axis). The second
arm (diagrams/second_arm.yaml, the code's default settings) has eight cells of its own, four per
split: its own camera placement, four textured tools, the lightings and the timelines
(``scene_matrix_second_arm_{tuning,held_out}.yaml``).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SWEEPS = ROOT / "diagrams" / "sweeps"
SEED = 27  # the split and the shuffles; fixed before any cell ran
CELLS_PER_SPLIT = 24
DURATION = 110.0  # s: first convergence, two changes, and 15 s after the last for re-convergence

# The head's tilt axis stands 0.57 m above the post's foot (models/head.sdf).
EYE_HEIGHT = 0.57
# The scenario's own head: the post 1.4 m in front of the arm, facing it, tilted down 0.1 rad.
FRONT_DISTANCE = 1.4
FRONT_TILT = 0.1
# The point the other heads aim at: the middle of the held rod, averaged over the babbling of
# hand_eye.yaml (its logged hand poses and rod tip over 30 s).
TARGET = np.array([0.54, 0.0, 0.40])
AIM_RANGE = 0.8  # m from TARGET to the high head's eye


def _placement(azimuth_deg: float, post_distance: float, elevation_deg: float | None = None) -> dict:
    """A head aimed at TARGET: its post at ``post_distance`` from the arm's base along the azimuth
    (0: the scenario's front), or with ``elevation_deg`` its eye on a ray from TARGET raised by that
    angle at AIM_RANGE; the post's pose (foot, yaw) and the tilt that aims it."""
    a = math.radians(azimuth_deg)
    direction = np.array([math.cos(a), math.sin(a)])
    if elevation_deg is None:
        foot = np.array([*(post_distance * direction), 0.0])
    else:
        e = math.radians(elevation_deg)
        eye = TARGET + AIM_RANGE * np.array([math.cos(e) * direction[0], math.cos(e) * direction[1],
                                             math.sin(e)])
        foot = eye - [0.0, 0.0, EYE_HEIGHT]
    d = TARGET - (foot + [0.0, 0.0, EYE_HEIGHT])
    return {"foot": foot, "yaw": math.atan2(d[1], d[0]), "tilt": math.atan2(-d[2], math.hypot(d[0], d[1]))}


PLACEMENTS = {
    "front": {"foot": np.array([FRONT_DISTANCE, 0.0, 0.0]), "yaw": math.pi, "tilt": FRONT_TILT},
    "left45": _placement(45.0, FRONT_DISTANCE),
    "right45": _placement(-45.0, FRONT_DISTANCE),
    "high": _placement(0.0, 0.0, elevation_deg=40.0),
    # 1.1 m from the base (0.56 m from TARGET): closer, the babbling reaches the head
    "near": _placement(0.0, 1.1),
    "far": _placement(0.0, 2.2),
}
CAMERAS = {"640x480": (640, 480), "1280x720": (1280, 720), "720x720": (720, 720)}
TOOLS = ("rod", "wood_handle", "metal_bar", "speckle_bar", "plain_bar", "none")
LIGHTS = {
    "default": [],  # the station's room lights (a ceiling light and a dimmer one at the camera)
    # Dimmer and from the side: one light from the arm's left, a little from above, and a faint fill
    # at the camera, 58 % of the room lights' total intensity.
    "dim_side": [{"type": "directional", "frame": "world", "direction": [0.2, -1.0, -0.4], "intensity": 0.6},
                 {"type": "directional", "frame": "camera", "direction": [0.0, 0.0, 1.0], "intensity": 0.15}],
}
PERSONS = ("behind", "between")
# (slips as (time s, slide m, pivot rad), camera moves as (time s, size rad)); the move turns the
# head by its size, split between pan and tilt (0.6, 0.8).
DISTURBANCES = {
    "small": ([(50.0, 0.01, 0.1)], [(88.0, 0.03)]),
    "medium": ([(50.0, 0.02, 0.2)], [(88.0, 0.08)]),
    "large": ([(50.0, 0.04, 0.35)], [(88.0, 0.15)]),
    "largest": ([(50.0, 0.05, 0.5)], [(88.0, 0.2)]),
    "two_slips": ([(45.0, 0.02, 0.15), (66.0, -0.01, -0.1)], [(88.0, 0.1)]),
}


def _yaml_float(x: float) -> str:
    return repr(round(float(x), 6))


def _head(name: str) -> str:
    p = PLACEMENTS[name]
    x, y, z = (_yaml_float(v) for v in p["foot"])
    return (f"{{X_WP: {{translation: [{x}, {y}, {z}], rotation: !Rpy {{deg: [0.0, 0.0, "
            f"{_yaml_float(math.degrees(p['yaw']))}]}}}}, pan: 0.0, tilt: {_yaml_float(p['tilt'])}}}")


def _person(placement: str, where: str) -> str:
    """The person's path, perpendicular to the line from the workspace point to the camera: 1.8 m
    beyond the workspace point (behind the arm) or halfway to the camera (between)."""
    p = PLACEMENTS[placement]
    eye = p["foot"] + [0.0, 0.0, EYE_HEIGHT]
    toward = (eye - TARGET)[:2]
    toward /= np.linalg.norm(toward)
    side = np.array([-toward[1], toward[0]])
    if where == "behind":
        centre = TARGET[:2] - 1.8 * toward
    else:
        centre = TARGET[:2] + 0.5 * np.linalg.norm((eye - TARGET)[:2]) * toward
    a, b = centre - 2.5 * side, centre + 2.5 * side
    ends = ", ".join(f"[{_yaml_float(p[0])}, {_yaml_float(p[1])}]" for p in (a, b))
    return f"{{waypoints: [{ends}]}}"


def _disturbances(placement: str, name: str, tool: str) -> str:
    """The timeline ``name`` for a head at ``placement``; without a tool, its camera moves only."""
    slips, moves = DISTURBANCES[name]
    slips = slips if tool != "none" else []
    tilt = PLACEMENTS[placement]["tilt"]
    items = [f"!ToolSlip {{time: {t}, slide: {s}, pivot: {p}, duration: 0.1}}" for t, s, p in slips]
    items += [f"!HeadMove {{time: {t}, pan: {_yaml_float(0.6 * a)}, tilt: {_yaml_float(tilt + 0.8 * a)}, "
              "duration: 0.5}" for t, a in moves]
    return "[" + ", ".join(items) + "]"


def _balanced(values, n: int, rng) -> list:
    """``n`` values, each as often as the others (within one), in a random order."""
    values = list(values)
    out = (values * (n // len(values) + 1))[:n]
    rng.shuffle(out)
    return out


def design() -> dict[str, list[dict]]:
    """The cells of each split: one value per axis (names), and a seed per cell."""
    rng = np.random.default_rng(SEED)
    seeds = rng.permutation(np.arange(100, 100 + 2 * CELLS_PER_SPLIT)).tolist()
    splits = {}
    for k, split in enumerate(("tuning", "held_out")):
        n = CELLS_PER_SPLIT
        axes = {"placement": _balanced(PLACEMENTS, n, rng), "camera": _balanced(CAMERAS, n, rng),
                "tool": _balanced(TOOLS, n, rng), "lights": _balanced(LIGHTS, n, rng),
                "person": _balanced(PERSONS, n, rng), "disturbances": _balanced(DISTURBANCES, n, rng)}
        splits[split] = [{**{a: v[i] for a, v in axes.items()}, "seed": seeds[k * n + i]} for i in range(n)]
    return splits


def _lights(name: str) -> str:
    lights = LIGHTS[name]
    if not lights:
        return "[]"
    parts = []
    for light in lights:
        parts.append(f"{{type: {light['type']}, frame: {light['frame']}, direction: {light['direction']}, "
                     f"intensity: {light['intensity']}}}")
    return "[" + ", ".join(parts) + "]"


def sweep_text(split: str, cells: list[dict]) -> str:
    columns = {
        "seed": [str(c["seed"]) for c in cells],
        "head": [_head(c["placement"]) for c in cells],
        "camera.width": [str(CAMERAS[c["camera"]][0]) for c in cells],
        "camera.height": [str(CAMERAS[c["camera"]][1]) for c in cells],
        "tool.model": [c["tool"] for c in cells],
        "lights": [_lights(c["lights"]) for c in cells],
        "distractor": [_person(c["placement"], c["person"]) for c in cells],
        "disturbances": [_disturbances(c["placement"], c["disturbances"], c["tool"]) for c in cells],
    }
    lines = [
        f"# The hand-eye scene matrix, {split.replace('_', '-')} set (issue 27): written by",
        "# bench/make_scene_matrix.py (its docstring: axes, values, split); do not edit by hand.",
        f"#   .venv/bin/python bench/bench_scene_matrix.py --split {split}",
        "# Cells, by the names of their axis values (each has its own motion seed, the seed axis):",
    ]
    for i, c in enumerate(cells):
        lines.append(f"#   {i:2d}: {c['placement']}, {c['camera']}, {c['tool']}, lights {c['lights']}, "
                     f"person {c['person']}, disturbances {c['disturbances']}")
    lines += ["scenario: ../hand_eye.yaml", "scenario_name: hand_eye", f"duration: {DURATION}", "zip:"]
    for axis, values in columns.items():
        lines.append(f"  {axis}:")
        lines += [f"    - {v}" for v in values]
    return "\n".join(lines) + "\n"


# The second arm (diagrams/second_arm.yaml: its own head 45 deg around it, the person behind it),
# with the code's default settings: the tools with texture, the lightings and the timelines vary.
SECOND_ARM_CELLS_PER_SPLIT = 4
SECOND_ARM_TOOLS = ("rod", "wood_handle", "speckle_bar", "metal_bar")
SECOND_ARM_TILT = 0.1  # rad: second_arm.yaml's head


def second_arm_design() -> dict[str, list[dict]]:
    """The second arm's cells of each split (drawn after ``design``'s, from their own stream)."""
    rng = np.random.default_rng(SEED + 1)
    n = SECOND_ARM_CELLS_PER_SPLIT
    seeds = rng.permutation(np.arange(200, 200 + 2 * n)).tolist()
    tools = _balanced(SECOND_ARM_TOOLS, 2 * n, rng)
    timelines = _balanced(DISTURBANCES, 2 * n, rng)
    lights = _balanced(LIGHTS, 2 * n, rng)
    return {split: [{"tool": tools[k * n + i], "disturbances": timelines[k * n + i],
                     "lights": lights[k * n + i], "seed": seeds[k * n + i]} for i in range(n)]
            for k, split in enumerate(("tuning", "held_out"))}


def second_arm_sweep_text(split: str, cells: list[dict]) -> str:
    def timeline(c):
        slips, moves = DISTURBANCES[c["disturbances"]]
        items = [f"!ToolSlip {{time: {t}, slide: {s}, pivot: {p}, duration: 0.1}}" for t, s, p in slips]
        items += [f"!HeadMove {{time: {t}, pan: {_yaml_float(0.6 * a)}, "
                  f"tilt: {_yaml_float(SECOND_ARM_TILT + 0.8 * a)}, duration: 0.5}}" for t, a in moves]
        return "[" + ", ".join(items) + "]"

    lines = [f"# The second arm's cells of the scene matrix, {split.replace('_', '-')} set (issue 27):",
             "# written by bench/make_scene_matrix.py; do not edit by hand.",
             f"#   .venv/bin/python bench/bench_scene_matrix.py --split {split} --arm second", "# Cells:"]
    lines += [f"#   {i}: {c['tool']}, lights {c['lights']}, disturbances {c['disturbances']}"
              for i, c in enumerate(cells)]
    lines += ["scenario: ../second_arm.yaml", "scenario_name: second_arm", f"duration: {DURATION}", "zip:"]
    columns = {"seed": [str(c["seed"]) for c in cells], "tool.model": [c["tool"] for c in cells],
               "lights": [_lights(c["lights"]) for c in cells], "disturbances": [timeline(c) for c in cells]}
    for axis, values in columns.items():
        lines.append(f"  {axis}:")
        lines += [f"    - {v}" for v in values]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=SWEEPS, help="folder of the sweep files")
    args = parser.parse_args(argv)
    for split, cells in design().items():
        path = args.out / f"scene_matrix_{split}.yaml"
        path.write_text(sweep_text(split, cells))
        print(path)
    for split, cells in second_arm_design().items():
        path = args.out / f"scene_matrix_second_arm_{split}.yaml"
        path.write_text(second_arm_sweep_text(split, cells))
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
