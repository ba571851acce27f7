"""The hand-eye loop's wrench watch alone (``hand_eye.slip_from_wrench``): the payload loop in its
dynamic mode on the wrist wrench of ``diagrams/hand_eye.yaml``'s world, without the camera (no
rendering, so a run costs about half a second of a core per simulated second). Per motion seed: when
it first identified the held tool (arm, gripper and rod outboard of the sensor), each change it
detected against the scenario's slips (a detection more than ``--window`` s after every slip is a
false alarm), and the wall time.

    .venv/bin/python bench/bench_wrench_watch.py [--scenario-name hand_eye] [--seeds 1 2 13] [--duration 130]

The arm's motion is the scenario's babbling without the hand-eye loop's pauses and confirming
trials (no camera, no loop), so it is a check of the wrench's side alone; whole runs with both are
``bench/bench_hand_eye.py`` and ``bench/bench_soak.py``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from sustain_drake.experiments.hand_eye import connect_station_wrench
from sustain_drake.identification import coordination
from sustain_drake.loops.hand_eye import wrench_watch_config
from sustain_drake.loops.payload import add_payload_loop
from sustain_drake.station import build_station, load_scenario
from sustain_drake.station.scenario import ToolSlip, arm_of, timeline
from sustain_drake.station.scenario_files import with_seed

ROOT = Path(__file__).resolve().parents[1]


def run(scenario_name: str, seed: int | None, duration: float | None) -> tuple[list, list, float, float]:
    """One run: the watch's events, the times of the scenario's slips within the run, the simulated
    and the wall time (s)."""
    scenario = load_scenario(ROOT / "diagrams" / "hand_eye.yaml", scenario_name)
    if seed is not None:
        scenario = with_seed(scenario, seed)
    scenario.camera.rgb = scenario.camera.depth = scenario.camera.label = False
    scenario.hand_eye.enabled = False
    scenario.duration = duration or scenario.duration
    builder = DiagramBuilder()
    station = builder.AddSystem(build_station(scenario))
    watch = add_payload_loop(builder, len(arm_of(scenario).joints), wrench_watch_config())
    connect_station_wrench(builder, station, watch)
    simulator = Simulator(builder.Build())
    start = time.perf_counter()
    simulator.AdvanceTo(scenario.duration)
    wall = time.perf_counter() - start
    machine = watch.state_machine
    events = machine.events(machine.GetMyContextFromRoot(simulator.get_context()))
    slips = [d.time for d in timeline(scenario) if isinstance(d, ToolSlip) and d.time < scenario.duration]
    return list(events), slips, scenario.duration, wall


def summary(seed, events, slips: list[float], window: float, duration: float, wall: float) -> str:
    converged = [e.time for e in events if e.kind == coordination.CONVERGED]
    detections = [e.time for e in events if e.kind == coordination.CHANGE_DETECTED]
    latencies = []
    for slip in slips:
        after = [t - slip for t in detections if 0.0 <= t - slip <= window]
        latencies.append(f"slip {slip:g} s: " + (f"{after[0]:.2f} s" if after else "not detected"))
    alarms = [t for t in detections if not any(0.0 <= t - s <= window for s in slips)]
    first = f"{converged[0]:.1f} s" if converged else "never"
    return (f"seed {seed if seed is not None else 'scenario'}: identified at {first}; "
            f"{'; '.join(latencies) or 'no slip'}; false alarms {len(alarms)}"
            f"{' at ' + ', '.join(f'{t:.1f} s' for t in alarms) if alarms else ''}; "
            f"{wall:.0f} s wall for {duration:g} s")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario-name", default="hand_eye", help="a scenario of diagrams/hand_eye.yaml")
    parser.add_argument("--seeds", type=int, nargs="*", default=None,
                        help="motion seeds (default: the scenario's own)")
    parser.add_argument("--duration", type=float, help="simulated s (default: the scenario's)")
    parser.add_argument("--window", type=float, default=1.0,
                        help="s after a slip within which a detection is that slip's (default: 1)")
    args = parser.parse_args(argv)
    lines = []
    for seed in args.seeds or [None]:
        events, slips, duration, wall = run(args.scenario_name, seed, args.duration)
        for e in events:
            print(f"  {e.time:8.2f} s  {e.kind:16s} {e.detail}", flush=True)
        lines.append(summary(seed, events, slips, args.window, duration, wall))
        print(lines[-1], flush=True)
    print("\n".join(["", *lines]))


if __name__ == "__main__":
    main()
