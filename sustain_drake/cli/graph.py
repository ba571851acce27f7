"""``sustain-drake graph SCENARIO``: the station's block graph as Graphviz ``.dot`` (and ``.svg``
when Graphviz's ``dot`` is installed)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from sustain_drake.cli.common import EXIT_OK, CliError
from sustain_drake.files import OutputPathError, check_output_paths, write_atomically
from sustain_drake.station import ScenarioError, build_station, load_scenario


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "graph", help="write a scenario's block diagram as .dot (and .svg with graphviz)")
    p.add_argument("scenario", type=Path, help="scenario YAML file, e.g. diagrams/hand_eye.yaml")
    p.add_argument("--out", type=Path,
                   help="output .dot file (default out/graph/<scenario name>.dot), checked writable "
                   "before the station is built; the .svg goes beside it (an older .svg there is "
                   "removed when graphviz is missing, so the two always match)")
    p.add_argument("--max-depth", type=int, default=1,
                   help="how many levels of sub-diagrams to expand (default %(default)s)")
    p.set_defaults(handler=run)


def run(args) -> int:
    dot_path, svg_path = write_graph(args.scenario, args.out, args.max_depth)
    print(f"graph: {dot_path}")
    if svg_path is not None:
        print(f"graph: {svg_path}")
    else:
        print("(install graphviz for an .svg: dot was not found on PATH)")
    return EXIT_OK


def write_graph(scenario_path: Path, out: Path | None = None,
                max_depth: int = 1) -> tuple[Path, Path | None]:
    if max_depth < 0:
        raise CliError(f"--max-depth must be >= 0, got {max_depth}")
    try:
        scenario = load_scenario(scenario_path)
    except ScenarioError as e:
        raise CliError(str(e)) from None
    out = Path("out") / "graph" / f"{Path(scenario_path).stem}.dot" if out is None else Path(out)
    if out.suffix != ".dot":
        raise CliError(f"--out must end in .dot, got {out}")
    svg = out.with_suffix(".svg")
    try:  # before the station is built
        check_output_paths({"--out": out, "--out's .svg": svg}, {"scenario": scenario_path})
    except OutputPathError as e:
        raise CliError(str(e)) from None
    try:
        diagram = build_station(scenario)
    except ScenarioError as e:
        raise CliError(f"{scenario_path}: {e}") from None
    dot = diagram.GetGraphvizString(max_depth=max_depth)
    write_atomically(out, dot)
    dot_program = shutil.which("dot")
    if dot_program is None:
        svg.unlink(missing_ok=True)  # an older graph's picture
        return out, None
    result = subprocess.run([dot_program, "-Tsvg"], input=dot.encode(), capture_output=True,
                            check=False, timeout=120)
    if result.returncode != 0:
        svg.unlink(missing_ok=True)
        raise CliError(f"graphviz dot failed: {result.stderr.decode(errors='replace').strip()}")
    write_atomically(svg, result.stdout)
    return out, svg
