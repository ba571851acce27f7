"""Running a scenario: the station, the enabled experiments and their metrics, in one Diagram.

``simulate_scenario`` is what ``sustain-drake simulate`` and the benches call. It writes, in the
output folder: ``replay.html`` (a self-contained Meshcat recording), ``log.npz`` (the station's
vector outputs sampled at ``log_rate``; poses as 4x4 matrices) and ``metrics.json`` (every enabled
experiment's metrics). Bad input raises ``RunError`` or ``ScenarioError`` (one line) before
anything is written.
"""

from __future__ import annotations

import importlib
import io
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput
from tqdm import tqdm

from sustain_drake.experiments import EXPERIMENTS
from sustain_drake.experiments.log_spool import LogSpool
from sustain_drake.files import write_atomically
from sustain_drake.station import Scenario, build_station, load_scenario
from sustain_drake.station.meshcat import make_local_meshcat
from sustain_drake.station.scenario import scenario_text
from sustain_drake.station.scenario_files import scenario_label, with_seed
from sustain_drake.systems.ground_truth import PoseToVector

# The station's vector outputs saved in log.npz, and its poses (saved as N x 4 x 4 arrays).
LOGGED_VECTORS = ("joint_positions", "joint_velocities", "head_joint_positions", "wrench",
                  "true_p_HP", "true_tool_mass", "true_p_KCm", "true_outboard_mass",
                  "true_p_KCo", "true_touch")
LOGGED_POSES = ("X_WH", "true_X_WC", "true_X_HT")
REPLAY_FPS = 30.0


class RunError(ValueError):
    """A run's argument that cannot be used; the message is one line for the user."""


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


def _positive(value: float | None, name: str) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise RunError(f"{name} must be a positive number, got {value}")


def simulate_scenario(scenario: Scenario, out: str | Path, *, label: str = "scenario",
                      duration: float | None = None, live: bool = False, log_rate: float = 100.0,
                      replay: bool = True, on_step: Callable[[float, Simulator], None] | None = None
                      ) -> SimulationResult:
    """Simulates ``scenario`` (a loaded ``Scenario``: see ``station.load_scenario`` and
    ``station.scenario_files.with_seed``) for ``duration`` s (default: the scenario's) and writes its
    outputs into the folder ``out``; ``label`` names the run in ``metrics.json``. ``live`` also shows
    it in Meshcat (localhost) in real time. ``on_step(t, simulator)``, if given, is called after each
    0.1 s step (a bench's monitor, e.g. of memory; it must not change the simulation). Raises
    ``RunError`` or ``ScenarioError`` (one line) before anything is written."""
    _positive(duration, "duration")
    _positive(log_rate, "log rate")
    duration = scenario.duration if duration is None else duration
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise RunError(f"{out} exists and is not a folder")

    meshcat = make_local_meshcat() if (replay or live) else None
    station = build_station(scenario, meshcat=meshcat)
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
            experiments[section] = (module, module.add_to_diagram(builder, station, scenario, meshcat))
    diagram = builder.Build()

    simulator = Simulator(diagram)
    if live:
        simulator.set_target_realtime_rate(1.0)
    if meshcat is not None and replay:
        meshcat.StartRecording(frames_per_second=REPLAY_FPS,
                               set_visualizations_while_recording=live)
    simulator.Initialize()
    start = time.perf_counter()
    with LogSpool(diagram) as spool:  # the logs on disk while the run goes on (flat memory)
        _advance(simulator, duration, spool, on_step)
        spool.restore(simulator.get_context())
    wall = time.perf_counter() - start

    out.mkdir(parents=True, exist_ok=True)
    replay_path = None
    if meshcat is not None and replay:
        meshcat.StopRecording()
        meshcat.PublishRecording()
        replay_path = out / "replay.html"
        write_atomically(replay_path, meshcat.StaticHtml())
    log_path = out / "log.npz"
    write_atomically(log_path, _npz_bytes(simulator, loggers, scenario))
    metrics_path = None
    if experiments:
        metrics = {"scenario": label, "duration_s": duration, "wall_s": wall}
        for section, (module, handle) in experiments.items():
            metrics[section] = module.finish(handle, diagram, simulator.get_context(), out)
        metrics_path = out / "metrics.json"
        write_atomically(metrics_path, json.dumps(metrics, indent=2, allow_nan=False) + "\n")
    return SimulationResult(duration, wall, replay_path, log_path, metrics_path)


# s of simulated time between moves of the logs to disk (LogSpool): a minute of a hand-eye run's
# logs is about 2 MB, so the logs' buffers stay that small
LOG_SPOOL_INTERVAL = 60.0


def _advance(simulator, duration: float, spool: LogSpool, on_step) -> None:
    """Advances ``simulator`` to ``duration`` in 0.1 s steps (a progress bar on a terminal), the
    logs moved to disk every ``LOG_SPOOL_INTERVAL``, ``on_step(t, simulator)`` after each step."""
    step = min(0.1, duration)
    next_drain = LOG_SPOOL_INTERVAL
    with tqdm(total=round(duration, 3), unit="sim s", disable=not sys.stderr.isatty(),
              bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} sim s [{elapsed}<{remaining}]") as bar:
        t = 0.0
        while t < duration - 1e-9:
            t = min(t + step, duration)
            simulator.AdvanceTo(t)
            if t >= next_drain - 1e-9:
                spool.drain(simulator.get_context())
                next_drain += LOG_SPOOL_INTERVAL
            if on_step is not None:
                on_step(t, simulator)
            bar.update(t - bar.n)


def simulate_file(path: str | Path, name: str | None = None, seed: int | None = None,
                  out: str | Path | None = None, **options) -> SimulationResult:
    """Loads scenario ``name`` of the file ``path`` (``station.load_scenario``), with ``seed`` applied
    (``station.scenario_files.with_seed``; None: the scenario's own seeds), and simulates it into ``out``
    (default ``out/<scenario name>``); ``options`` go to ``simulate_scenario``."""
    scenario = load_scenario(path, name)
    if seed is not None:
        scenario = with_seed(scenario, seed)
    label = scenario_label(path, name)
    out = Path("out") / label if out is None else Path(out)
    return simulate_scenario(scenario, out, label=f"{path}:{label}", **options)


def _npz_bytes(simulator, loggers, scenario: Scenario) -> bytes:
    context = simulator.get_context()
    arrays = {}
    for name, logger in loggers.items():
        log = logger.FindLog(context)
        arrays.setdefault("time", log.sample_times())
        data = log.data().T  # samples x size
        arrays[name] = data.reshape(-1, 4, 4) if name in LOGGED_POSES else data
    arrays["scenario"] = np.array(scenario_text(scenario))  # the scenario as run, every key
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    return buffer.getvalue()

