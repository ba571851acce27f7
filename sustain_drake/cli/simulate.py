"""``sustain-drake simulate SCENARIO``: run a scenario, save a Meshcat replay, npz logs and metrics.

Headless by default, with a progress bar in simulated seconds (on a terminal). Writes, in the
output folder: ``replay.html`` (a self-contained Meshcat recording, open it in a browser),
``log.npz`` (the station's vector outputs sampled at ``--log-rate``; poses as 4x4 matrices) and,
with an experiment enabled, ``metrics.json`` (see ``experiments.run``); the kinesthetic experiment
also writes the identified payload, ``payload.yaml`` (``calibration_export.payload_yaml``: with its
rotational inertia in the dynamic mode).

Before the run: the scenario is loaded and checked, and the output folder is created and checked
writable, so a bad input or folder costs no simulation. After a successful run, the outputs of an
earlier run in the folder that this run did not write again (e.g. ``replay.html`` after
``--no-replay``) are removed; a failed run leaves the folder as it was.
"""

from __future__ import annotations

import math
from pathlib import Path

from sustain_drake.cli.common import EXIT_OK, CliError
from sustain_drake.experiments.run import RunError, simulate_file
from sustain_drake.files import (
    OutputPathError,
    existing_files,
    prepare_folder,
    remove_created,
    remove_unchanged,
)
from sustain_drake.station import ScenarioError, load_scenario
from sustain_drake.station.scenario_files import SEED_START_SPREAD, scenario_label, with_seed

# What a run writes in its folder (experiments.run and the experiments' finish): glob patterns.
RUN_OUTPUTS = ("replay.html", "log.npz", "metrics.json", "likelihood_*.png", "body_vs_truth.png",
               "hand_eye_fig9.png", "kinesthetic_*.png", "payload.yaml")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "simulate", help="simulate a scenario (headless), save replay.html, log.npz, metrics.json",
        description="Simulate a scenario file (diagrams/*.yaml) and save a self-contained "
        "Meshcat replay (replay.html), the logged signals (log.npz) and the experiments' metrics "
        "(metrics.json) in --out.")
    p.add_argument("scenario", type=Path, help="scenario YAML file, e.g. diagrams/hand_eye.yaml")
    p.add_argument("--scenario-name", dest="name",
                   help="which scenario of a file of several (default: the one named like the file)")
    p.add_argument("--duration", type=float, help="simulated seconds (default: the scenario's)")
    p.add_argument("--out", type=Path,
                   help="output folder (default out/<scenario name>), created and checked writable "
                   "before the run; after a successful run, an earlier run's outputs there that this "
                   "run did not write again (replay.html, log.npz, metrics.json, pictures) are removed; "
                   "a failed run leaves them")
    p.add_argument("--meshcat", action="store_true",
                   help="also show the simulation live in Meshcat (localhost only), in real time")
    p.add_argument("--log-rate", type=float, default=100.0,
                   help="samples per simulated second in log.npz (default %(default)s)")
    p.add_argument("--no-replay", action="store_true", help="do not record replay.html")
    p.add_argument("--seed", type=int,
                   help="override the scenario's seeds: motion, sensor noise (depth, wrench) "
                   f"and the distractor's start (delayed by 0-{SEED_START_SPREAD:g} s)")
    p.set_defaults(handler=run)


def run(args) -> int:
    for flag, value in (("--duration", args.duration), ("--log-rate", args.log_rate)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise CliError(f"{flag} must be a positive number, got {value}")
    if args.seed is not None and args.seed < 0:
        raise CliError(f"--seed must be an integer >= 0, got {args.seed}")
    try:  # every scenario problem before a file is touched
        scenario = load_scenario(args.scenario, args.name)
        if args.seed is not None:
            with_seed(scenario, args.seed)
        out = Path("out") / scenario_label(args.scenario, args.name) if args.out is None else args.out
    except ScenarioError as e:
        raise CliError(str(e)) from None
    created, earlier = prepare_out(out)
    try:
        result = simulate_file(args.scenario, args.name, args.seed, out, duration=args.duration,
                               live=args.meshcat, log_rate=args.log_rate, replay=not args.no_replay)
    except (ScenarioError, RunError) as e:
        remove_created(created)
        raise CliError(str(e)) from None
    except BaseException:
        remove_created(created)
        raise
    stale = remove_unchanged(earlier)
    print(f"simulated {result.simulated:g} s in {result.wall:.1f} s "
          f"({result.realtime_factor:.2f}x real time)")
    if result.replay is not None:
        print(f"replay: {result.replay}")
    print(f"log: {result.log}")
    if result.metrics is not None:
        print(f"metrics: {result.metrics}")
    if stale:
        print(f"removed an earlier run's {', '.join(p.name for p in sorted(stale))} from {out}")
    return EXIT_OK


def prepare_out(out: Path) -> tuple[list[Path], dict]:
    """Creates ``out`` and checks it writable, before the run; returns the folders created and the
    outputs of an earlier run found in it. Raises ``CliError``."""
    try:
        created = prepare_folder(out, "--out")
    except OutputPathError as e:
        raise CliError(str(e)) from None
    for pattern in RUN_OUTPUTS:
        for path in out.glob(pattern):
            if path.is_dir():
                remove_created(created)
                raise CliError(f"--out {out}: {path.name} is a folder, where the run writes a file; "
                               "move it or choose another --out")
    return created, existing_files(out, RUN_OUTPUTS)
