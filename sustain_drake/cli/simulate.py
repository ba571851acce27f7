"""``sustain-drake simulate SCENARIO``: run a scenario, save a Meshcat replay, npz logs and metrics.

Headless by default, with a progress bar in simulated seconds (on a terminal). Writes, in the
output folder: ``replay.html`` (a self-contained Meshcat recording, open it in a browser),
``log.npz`` (the station's vector outputs sampled at ``--log-rate``; poses as 4x4 matrices) and,
with an experiment enabled, ``metrics.json`` (see ``experiments.run``).
"""

from __future__ import annotations

import math
from pathlib import Path

from sustain_drake.cli.common import EXIT_OK, CliError
from sustain_drake.experiments.run import RunError, simulate_file
from sustain_drake.station import ScenarioError
from sustain_drake.station.scenario import SEED_START_SPREAD


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
    p.add_argument("--out", type=Path, help="output folder (default out/<scenario name>)")
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
    try:
        result = simulate_file(args.scenario, args.name, args.seed, args.out, duration=args.duration,
                               live=args.meshcat, log_rate=args.log_rate, replay=not args.no_replay)
    except (ScenarioError, RunError) as e:
        raise CliError(str(e)) from None
    print(f"simulated {result.simulated:g} s in {result.wall:.1f} s "
          f"({result.realtime_factor:.2f}x real time)")
    if result.replay is not None:
        print(f"replay: {result.replay}")
    print(f"log: {result.log}")
    if result.metrics is not None:
        print(f"metrics: {result.metrics}")
    return EXIT_OK
