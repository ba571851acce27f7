"""Against OpenCV with a ChArUco board: the marker-based eye-to-hand calibration users run today, on
the hand-eye scene (issue 26, item 1).

For each cell of ``diagrams/sweeps/hand_eye_seeds.yaml`` (the sixteen seeds of the marker-free
loop's results) the arm holds the ChArUco board (``tool: charuco_board``) instead of the rod and
goes through the first 10, 20 and 50 stops of that seed's babbling (``baseline_scene``: the same
motion generator, joint ranges, camera and depth noise as ``diagrams/hand_eye.yaml``, a rest of
``SETTLE`` s after each move, one image per stop). Per image: the board's corners
(``CharucoDetector.detectBoard``), its pose by ``cv2.solvePnP`` on the colour image with the
camera's intrinsics, and by a rigid fit (Kabsch) to the corners' 3-D points from the depth image.
From the poses the board was seen in: ``cv2.calibrateHandEye`` (TSAI, PARK, HORAUD, ANDREFF,
DANIILIDIS) and ``cv2.calibrateRobotWorldHandEye`` (SHAH, LI), fed as OpenCV documents for a fixed
camera (``identification.opencv_hand_eye``); and ours, ``calibrate_eye_to_hand``, on ONE corner per
image (the board's ``tracked_point``, its 3-D point from the depth image).

Reported per method and number of stops, over the cells: the camera's position (mm) and rotation
(deg) error against the true ``X_WC`` (median and worst), the time to collect (simulated seconds:
the babbling's moves at its pace, ``max(min_duration, 15/8 max|dq| / max_speed)`` each, plus the
rest, up to the last stop's image) and the solver's wall time. The marker-free loop's row is read
from the hand-eye table of docs/results.md (not re-run: 4-6 min of a core per seed).

It also writes, per cell and number of stops, ``points.csv`` (``sample,point,x,y,z``: sample the
0-based row of ``poses.csv``, point the ChArUco corner id, metres in the camera frame) and
``poses.csv`` (``x,y,z,qw,qx,qy,qz``: ``X_WH``) under ``--out``, for the images with at least one
corner with a depth point, for the multi-point ``sustain-drake calibrate eye-to-hand``.

    .venv/bin/python bench/bench_baseline_hand_eye.py [--cells 0 1] [--poses 10 20 50] [--results]
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from baseline_scene import SETTLE, BoardScene, Stop, babbling_stops  # noqa: E402
from results_page import RESULTS_PAGE, publish  # noqa: E402

from sustain_drake.files import write_atomically  # noqa: E402
from sustain_drake.identification import calibrate_eye_to_hand, calibrate_eye_to_hand_points  # noqa: E402
from sustain_drake.identification.batch import MIN_POINT_SAMPLES  # noqa: E402
from sustain_drake.identification.opencv_hand_eye import (  # noqa: E402
    HAND_EYE_METHODS,
    MIN_POSES,
    ROBOT_WORLD_METHODS,
    eye_to_hand,
    pose_error,
    robot_world_eye_to_hand,
)
from sustain_drake.perception.charuco import BoardView, measure_board  # noqa: E402
from sustain_drake.recorded_data import write_poses_csv  # noqa: E402
from sustain_drake.station.scenario_files import load_scenario_string  # noqa: E402
from sustain_drake.sweeps import load_sweep  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SWEEP = ROOT / "diagrams" / "sweeps" / "hand_eye_seeds.yaml"
BUDGETS = (10, 20, 50)
SOURCES = {"pnp": "solvePnP (colour)", "depth": "Kabsch (depth)"}
OURS_ONE_POINT = "ours, `calibrate_eye_to_hand`, one corner"
OURS_ALL_POINTS = "ours, `calibrate_eye_to_hand_points`, every corner jointly"


@dataclass(frozen=True)
class CellImages:
    """A cell's stops and what each image showed, with the truth."""

    label: str  # the results table's name of the run: "scenario" or "seed N"
    stops: list[Stop]
    views: list[BoardView]
    X_WH: np.ndarray  # (n, 4, 4)
    X_WC: np.ndarray  # the camera's true pose
    corner: int  # the ChArUco corner of "ours, one point"
    image_s: list[float]  # wall time of each image's detection, PnP and depth points


@dataclass(frozen=True)
class Outcome:
    """One method on one cell and number of stops: camera errors (m, rad; None when it could not
    run), the poses it used, the solver's wall time (s) and, for ours, the verdict."""

    position: float | None
    rotation: float | None
    used: int
    solve_s: float
    converged: bool = True


def cell_label(cell) -> str:
    seed = dict(cell.overrides).get("seed", "~")
    return "scenario" if seed in ("~", "null", "") else f"seed {seed}"


def collect(cell, count: int, principal_shift: float = 0.0) -> CellImages:
    """The first ``count`` stops of the cell's babbling, one image each, measured with the camera's
    intrinsics (their principal point moved by ``principal_shift`` px in u and v)."""
    scene = BoardScene(load_scenario_string(cell.scenario_text, cell_label(cell)))
    stops = babbling_stops(scene.scenario, *scene.joint_ranges(), count)
    intrinsics = dataclasses.replace(scene.intrinsics, cx=scene.intrinsics.cx + principal_shift,
                                     cy=scene.intrinsics.cy + principal_shift)
    views, X_WH, image_s = [], [], []
    for stop in stops:
        shot = scene.shot(stop.q, stop.time)
        start = time.perf_counter()
        views.append(measure_board(scene.finder, shot.color, shot.depth, intrinsics))
        image_s.append(time.perf_counter() - start)
        X_WH.append(shot.X_WH)
    return CellImages(cell_label(cell), stops, views, np.array(X_WH), scene.X_WC, scene.tracked_corner(),
                      image_s)


def _timed(solve, *args, repeat: int = 3):
    """``solve(*args)`` and its least wall time over ``repeat`` calls (the machine is shared)."""
    seconds = []
    for _ in range(repeat):
        start = time.perf_counter()
        result = solve(*args)
        seconds.append(time.perf_counter() - start)
    return result, min(seconds)


def solve_all(images: CellImages, n: int) -> dict[tuple[str, str], Outcome]:
    """Every method on the first ``n`` stops: ``{(method, board pose source): Outcome}``."""
    out = {}
    views, X_WH = images.views[:n], images.X_WH[:n]
    for source in SOURCES:
        seen = [i for i, v in enumerate(views) if getattr(v, f"X_CB_{source}") is not None]
        X_CB = np.array([getattr(views[i], f"X_CB_{source}") for i in seen]).reshape(-1, 4, 4)
        runs = [(f"calibrateHandEye {m}", eye_to_hand, m) for m in HAND_EYE_METHODS]
        runs += [(f"calibrateRobotWorldHandEye {m}", lambda *a: robot_world_eye_to_hand(*a)[0], m)
                 for m in ROBOT_WORLD_METHODS]
        for name, solve, method in runs:
            if len(seen) < MIN_POSES:
                out[name, source] = Outcome(None, None, len(seen), 0.0)
                continue
            X_WC, seconds = _timed(solve, X_WH[seen], X_CB, method)
            out[name, source] = Outcome(*pose_error(X_WC, images.X_WC), len(seen), seconds)
    p_C, rows = [], []
    for i, view in enumerate(views):
        hit = np.flatnonzero(view.ids == images.corner)
        if hit.size and np.isfinite(view.p_CQ[hit[0]]).all():
            p_C.append(view.p_CQ[hit[0]])
            rows.append(i)
    if len(rows) < MIN_POSES:
        out[OURS_ONE_POINT, "one"] = Outcome(None, None, len(rows), 0.0, False)
    else:
        result, seconds = _timed(calibrate_eye_to_hand, np.array(p_C), X_WH[rows])
        out[OURS_ONE_POINT, "one"] = Outcome(*pose_error(result.X_WC, images.X_WC), len(rows), seconds,
                                             result.converged)
    out[OURS_ALL_POINTS, "all"] = _every_corner_jointly(views, X_WH, images.X_WC)
    return out


def _every_corner_jointly(views: list, X_WH: np.ndarray, X_WC: np.ndarray) -> Outcome:
    """Ours on every corner with a depth point, one camera and one ``p_HP`` per corner (the corners
    seen in fewer than ``MIN_POINT_SAMPLES`` images left out, as the command line leaves them out)."""
    tracks: dict[int, tuple[list, list]] = {}
    for i, view in enumerate(views):
        for corner, p in zip(view.ids.tolist(), view.p_CQ, strict=True):
            if np.isfinite(p).all():
                tracks.setdefault(corner, ([], []))[0].append(i)
                tracks[corner][1].append(p)
    points = {c: (np.array(s), np.array(p)) for c, (s, p) in tracks.items() if len(s) >= MIN_POINT_SAMPLES}
    images = len({i for s, _ in points.values() for i in s})
    if images < MIN_POSES or not points:
        return Outcome(None, None, images, 0.0, False)
    result, seconds = _timed(calibrate_eye_to_hand_points, points, X_WH)
    return Outcome(*pose_error(result.X_WC, X_WC), images, seconds, result.converged)


def write_csvs(images: CellImages, n: int, folder: Path) -> None:
    """``points.csv`` and ``poses.csv`` of the first ``n`` stops (the images with a depth point)."""
    points, rows = ["sample,point,x,y,z"], []
    for view, X_WH in zip(images.views[:n], images.X_WH[:n], strict=True):
        good = np.isfinite(view.p_CQ).all(axis=1)
        if good.any():
            points += [f"{len(rows)},{i},{p[0]!r},{p[1]!r},{p[2]!r}"
                       for i, p in zip(view.ids[good].tolist(), view.p_CQ[good].tolist(), strict=True)]
            rows.append(X_WH)
    folder.mkdir(parents=True, exist_ok=True)
    write_atomically(folder / "points.csv", "\n".join(points) + "\n")
    write_atomically(folder / "poses.csv", write_poses_csv(np.array(rows).reshape(-1, 4, 4)))


def loop_results(page: Path = RESULTS_PAGE) -> tuple[dict[str, tuple[float, float, float, float]], str]:
    """The marker-free loop's runs in the hand-eye table of the results page: ``{run: (first
    convergence after the tool point s, adoption time s, camera mm, camera deg)}``, and the commit(s)
    the table was measured at (the block's own line, else the section's "Measured at")."""
    text = page.read_text(encoding="utf-8")
    block = text.split("<!-- BEGIN bench_hand_eye -->", 1)[1].split("<!-- END bench_hand_eye -->", 1)[0]
    # The table as bench_hand_eye writes it ("| 0 | seed=~ | 8.4 s | 11.5 s identified: 0.14 / 0.01,"),
    # or its earlier hand-written form ("| scenario | 8.4 s | 11.5 s: **0.33 / 0.03**").
    rows = re.findall(r"^\| \d+ \| seed=(~|\d+) \| ([\d.]+) s \| ([\d.]+) s identified: ([\d.]+) / ([\d.]+),",
                      block, flags=re.M)
    rows = [("scenario" if r[0] == "~" else f"seed {r[0]}", *r[1:]) for r in rows]
    rows += re.findall(r"^\| (scenario|seed \d+) \| ([\d.]+) s \| ([\d.]+) s: \*\*([\d.]+) / ([\d.]+)\*\*",
                       block, flags=re.M)
    runs = {r[0]: tuple(float(x) for x in r[1:]) for r in rows}
    cells_at = re.search(r"cells run at commit\(s\): (.*)", block)
    commits = re.findall(r"`([0-9a-f]{7,40})`", cells_at.group(1)) if cells_at else []
    commits = commits or re.findall(r"commit `([0-9a-f]{7,40})`", block)
    if not commits:
        section = text.split("## Hand-eye", 1)[1].split("<!-- BEGIN bench_hand_eye -->", 1)[0]
        measured = re.search(r"\*\*Measured at:\*\*([^;.]*)", section)
        commits = re.findall(r"`([0-9a-f]{7,40})`", measured.group(1)) if measured else []
    return runs, " / ".join(commits) or "unknown commit"


def _median_worst(values: list[float], scale: float, digits: int, failed: int = 0) -> str:
    if not values:
        return "-"
    worst = "fail" if failed else f"{scale * max(values):.{digits}f}"
    return f"{scale * statistics.median(values):.{digits}f} ({worst})"


def table(cells: list[CellImages], budgets, results) -> list[str]:
    """The markdown table: a row per number of stops and method, over the cells."""
    lines = ["| stops | method | board pose from | solved | camera position mm, median (worst) "
             "| camera rotation deg, median (worst) | collect s, median (worst) | solve ms, median (worst) |",
             "|---|---|---|---|---|---|---|---|"]
    for n in budgets:
        collect_s = [c.stops[n - 1].time for c in cells]
        for key in results[cells[0].label][n]:
            outcomes = [results[c.label][n][key] for c in cells]
            # OpenCV's solvers return a camera whatever the data; ours only with a converged verdict.
            ran = [o for o in outcomes if o.position is not None and o.converged]
            failed = 0 if key[1] in ("one", "all") else len(outcomes) - len(ran)
            solved = len(ran)
            source = {"one": f"corner {cells[0].corner}, depth", "all": "every corner, depth"}.get(
                key[1]) or SOURCES[key[1]]
            used = statistics.median(o.used for o in outcomes)
            lines.append(
                f"| {n} ({used:g} seen) | {key[0]} | {source} | {solved}/{len(cells)} "
                f"| {_median_worst([o.position for o in ran], 1e3, 2, failed)} "
                f"| {_median_worst([o.rotation for o in ran], np.degrees(1.0), 3, failed)} "
                f"| {_median_worst(collect_s, 1.0, 1)} | {_median_worst([o.solve_s for o in ran], 1e3, 2)} |")
    return lines


def loop_row(cells: list[CellImages]) -> list[str]:
    """The marker-free loop on the same runs, from the results page (not re-run)."""
    runs, commits = loop_results()
    found = [runs[c.label] for c in cells if c.label in runs]
    if not found:
        return []
    first, adopted, mm, deg = zip(*found, strict=True)
    return [f"| 130 s run | ours, marker-free loop (hand-eye table, measured at `{commits}`) "
            f"| rod points, no board | {len(found)}/{len(cells)} "
            f"| {statistics.median(mm):.2f} ({max(mm):.2f}) | {statistics.median(deg):.3f} ({max(deg):.3f}) "
            f"| {statistics.median(adopted):.1f} ({max(adopted):.1f}) "
            f"| online (converged {statistics.median(first):.1f} s after the tool point was found) |"]


def summary(cells: list[CellImages], budget: int) -> list[str]:
    """How often the board was seen, how the stops were timed, what an image costs."""
    seen = [sum(v.X_CB_pnp is not None for v in c.views[:budget]) for c in cells]
    image_ms = [1e3 * s for c in cells for s in c.image_s]
    return [f"- {len(cells)} runs; a board pose (>= 6 corners) in {sum(seen)} of {budget * len(cells)} "
            f"images ({100 * sum(seen) / (budget * len(cells)):.0f} %); \"seen\": the median number of "
            "images a method used (with a board pose; for ours, with the corner's depth point)",
            "- ours (one corner; every corner jointly): errors over the runs whose verdict converged "
            "(\"solved\"; the others give "
            "no camera: too few samples or not identified), OpenCV's over every run",
            f"- collect: the babbling's moves at its pace and a {SETTLE:g} s rest before each image; "
            f"detection, PnP and depth points {statistics.median(image_ms):.0f} ms per image (wall, "
            "not in the solve column)"]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cells", type=int, nargs="+", help="only these cells of the sweep (indices)")
    p.add_argument("--poses", type=int, nargs="+", default=list(BUDGETS), help="stops per calibration")
    p.add_argument("--out", type=Path, default=ROOT / "out" / "bench_baseline_hand_eye",
                   help="where the points and poses CSVs go")
    p.add_argument("--principal-point-shift", type=float, default=0.0, metavar="PX",
                   help="move the intrinsics' principal point by this in u and v (px) for the "
                   "measurements (-0.5: where the renderer puts it, see docs/results.md)")
    p.add_argument("--results", action="store_true", help="also write the table on docs/results.md")
    args = p.parse_args(argv)
    if args.results and (args.cells or sorted(args.poses) != list(BUDGETS) or args.principal_point_shift):
        raise SystemExit("--results publishes every cell with the default --poses and intrinsics only")
    cells = load_sweep(SWEEP).cells
    if args.cells:
        cells = [c for c in cells if c.index in set(args.cells)]
    budgets = sorted(set(args.poses))
    measured, results = [], {}
    for cell in cells:
        images = collect(cell, max(budgets), args.principal_point_shift)
        measured.append(images)
        results[images.label] = {n: solve_all(images, n) for n in budgets}
        for n in budgets:
            write_csvs(images, n, args.out / images.label.replace(" ", "_") / f"poses_{n}")
        print(f"{images.label}: board seen in {sum(v.X_CB_pnp is not None for v in images.views)} of "
              f"{len(images.views)} images", flush=True)
    lines = table(measured, budgets, results) + loop_row(measured) + [""] + summary(measured, max(budgets))
    print("\n".join(lines))
    if args.results:
        publish("bench_baseline_hand_eye", lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
