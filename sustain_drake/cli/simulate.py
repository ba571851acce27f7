"""``sustain-drake simulate SCENARIO``: run a scenario, save a Meshcat replay and npz logs.

Headless by default, with a progress bar in simulated seconds (on a terminal). Writes, in the
output folder: ``replay.html`` (a self-contained Meshcat recording, open it in a browser) and
``log.npz`` (the station's vector outputs sampled at ``--log-rate``; poses as 4x4 matrices).
"""

from __future__ import annotations

import importlib
import io
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput
from tqdm import tqdm

from sustain_drake.cli.common import EXIT_OK, CliError, write_atomically
from sustain_drake.experiments import EXPERIMENTS
from sustain_drake.station import ScenarioError, build_station, load_scenario
from sustain_drake.station.meshcat import make_local_meshcat
from sustain_drake.systems.ground_truth import PoseToVector

# The station's vector outputs saved in log.npz, and its poses (saved as N x 4 x 4 arrays).
LOGGED_VECTORS = ("joint_positions", "joint_velocities", "head_joint_positions", "wrench",
                  "true_p_HP", "true_tool_mass", "true_p_KCm", "true_outboard_mass",
                  "true_p_KCo", "true_touch")
LOGGED_POSES = ("X_WH", "true_X_WC")
REPLAY_FPS = 30.0
# --seed delays the distractor's start by up to this (s), so seeds differ in its phase too.
SEED_START_SPREAD = 3.0


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "simulate", help="simulate a scenario (headless), save replay.html and log.npz",
        description="Simulate a scenario file (diagrams/*.yaml) and save a self-contained "
        "Meshcat replay (replay.html) and the logged signals (log.npz) in --out.")
    p.add_argument("scenario", type=Path, help="scenario YAML file, e.g. diagrams/hand_eye.yaml")
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


@dataclass
class SimulationResult:
    simulated: float  # s
    wall: float  # s
    replay: Path | None
    log: Path
    metrics: Path | None = None

    @property
    def realtime_factor(self) -> float:
        return self.simulated / self.wall if self.wall > 0 else math.inf


def run(args) -> int:
    result = simulate_scenario(args.scenario, duration=args.duration, out=args.out,
                               live=args.meshcat, log_rate=args.log_rate,
                               replay=not args.no_replay, seed=args.seed)
    print(f"simulated {result.simulated:g} s in {result.wall:.1f} s "
          f"({result.realtime_factor:.2f}x real time)")
    if result.replay is not None:
        print(f"replay: {result.replay}")
    print(f"log: {result.log}")
    if result.metrics is not None:
        print(f"metrics: {result.metrics}")
    return EXIT_OK


def _positive(value: float | None, name: str) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise CliError(f"{name} must be a positive number, got {value}")


def simulate_scenario(scenario_path: Path, duration: float | None = None,
                      out: Path | None = None, live: bool = False, log_rate: float = 100.0,
                      replay: bool = True, seed: int | None = None) -> SimulationResult:
    """Runs a scenario; bad input raises ``CliError`` (one line) before anything is written.
    ``seed`` overrides the scenario's seeds (:func:`apply_seed`)."""
    _positive(duration, "--duration")
    _positive(log_rate, "--log-rate")
    try:
        scenario = load_scenario(scenario_path)
    except ScenarioError as e:
        raise CliError(str(e)) from None
    if seed is not None:
        apply_seed(scenario, seed)
    duration = scenario.duration if duration is None else duration
    out = Path("out") / Path(scenario_path).stem if out is None else Path(out)
    if out.exists() and not out.is_dir():
        raise CliError(f"--out {out} exists and is not a folder")

    meshcat = make_local_meshcat() if (replay or live) else None
    try:
        station = build_station(scenario, meshcat=meshcat)
    except ScenarioError as e:
        raise CliError(f"{scenario_path}: {e}") from None
    if live:
        print(f"Meshcat (this machine only): {meshcat.web_url()}", flush=True)
    builder = DiagramBuilder()
    builder.AddSystem(station)
    loggers = {name: LogVectorOutput(station.GetOutputPort(name), builder, 1.0 / log_rate)
               for name in LOGGED_VECTORS}
    for name in LOGGED_POSES:
        matrix = builder.AddSystem(PoseToVector())
        matrix.set_name(f"{name}_matrix")
        builder.Connect(station.GetOutputPort(name), matrix.get_input_port())
        loggers[name] = LogVectorOutput(matrix.get_output_port(), builder, 1.0 / log_rate)
    experiments = {}
    for section, module_name in EXPERIMENTS.items():
        if getattr(scenario, section).enabled:
            module = importlib.import_module(module_name)
            try:
                experiments[section] = (module, module.add_to_diagram(builder, station, scenario, meshcat))
            except ScenarioError as e:  # an experiment's settings the world or its systems refuse
                raise CliError(f"{scenario_path}: {e}") from None
    diagram = builder.Build()

    simulator = Simulator(diagram)
    if live:
        simulator.set_target_realtime_rate(1.0)
    if meshcat is not None and replay:
        meshcat.StartRecording(frames_per_second=REPLAY_FPS,
                               set_visualizations_while_recording=live)
    simulator.Initialize()
    start = time.perf_counter()
    step = min(0.1, duration)
    with tqdm(total=round(duration, 3), unit="sim s", disable=not sys.stderr.isatty(),
              bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} sim s [{elapsed}<{remaining}]") as bar:
        t = 0.0
        while t < duration - 1e-9:
            t = min(t + step, duration)
            simulator.AdvanceTo(t)
            bar.update(t - bar.n)
    wall = time.perf_counter() - start

    out.mkdir(parents=True, exist_ok=True)
    replay_path = None
    if meshcat is not None and replay:
        meshcat.StopRecording()
        meshcat.PublishRecording()
        replay_path = out / "replay.html"
        write_atomically(replay_path, meshcat.StaticHtml())
    log_path = out / "log.npz"
    write_atomically(log_path, _npz_bytes(diagram, simulator, loggers, scenario_path))
    metrics_path = None
    if experiments:
        metrics = {"scenario": str(scenario_path), "duration_s": duration, "wall_s": wall}
        for section, (module, handle) in experiments.items():
            metrics[section] = module.finish(handle, diagram, simulator.get_context(), out)
        metrics_path = out / "metrics.json"
        write_atomically(metrics_path, json.dumps(metrics, indent=2, allow_nan=False) + "\n")
    return SimulationResult(duration, wall, replay_path, log_path, metrics_path)


def apply_seed(scenario, seed: int) -> None:
    """One seed for a whole run: the motion generator's, the depth and wrench noise's, and the
    distractor's start, delayed by a seeded 0-``SEED_START_SPREAD`` s."""
    if seed < 0:
        raise CliError(f"--seed must be >= 0, got {seed}")
    scenario.motion.seed = seed
    # Offsets keep the noise streams apart from the motion's (generators seeded (seed, k)).
    scenario.depth_noise.seed = seed + 1000
    scenario.wrench_sensor.seed = seed + 2000
    delay = np.random.default_rng([seed, 2024]).uniform(0.0, SEED_START_SPREAD)
    scenario.distractor.start_time += float(delay)


def _npz_bytes(diagram, simulator, loggers, scenario_path: Path) -> bytes:
    context = simulator.get_context()
    arrays = {}
    for name, logger in loggers.items():
        log = logger.FindLog(context)
        arrays.setdefault("time", log.sample_times())
        data = log.data().T  # samples x size
        arrays[name] = data.reshape(-1, 4, 4) if name in LOGGED_POSES else data
    arrays["scenario"] = np.array(Path(scenario_path).read_text())
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    return buffer.getvalue()

