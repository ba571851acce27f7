"""A 30-minute soak (issue 23, item 6): ``diagrams/soak.yaml`` run once, in this process, on one
core, with the process's resident memory sampled as it runs.

    .venv/bin/python bench/bench_soak.py [--out out/bench_soak] [--duration 1800] [--results]
    .venv/bin/python bench/bench_soak.py --report [--results]   # report the run already in --out

The hand-eye world for 1800 simulated seconds: the person walking behind the arm, and from 120 s
on a random disturbance every 2-5 min (a tool slip or a camera move of random size, drawn from the
scenario's ``random_disturbances.seed``). Prints, per disturbance, its time, kind and size, how
long after it the change was detected and, after the detection, re-converged, and the camera
adopted at the re-convergence (mm / deg); then the totals against the targets: every change
detected within 1 s and re-converged within 15 s, no false alarm, each adopted camera within 2 mm
and 0.2 deg, resident memory growth under 5 % from minute 5 to minute 30. Memory is the process's
resident set (``/proc/self/statm``) every simulated minute; the logs the run keeps for its metrics
go to disk every simulated minute (``experiments.log_spool``), and the samples they hold in memory
at each reading are reported beside it. ``--out`` holds ``metrics.json``, ``log.npz``,
``hand_eye_fig9.png``, ``memory.json`` (with the commit the run ran at, which ``--results`` stamps
on the page) and ``soak.md`` (the printed table).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from results_page import number, publish  # noqa: E402

from sustain_drake.experiments.log_spool import log_sinks  # noqa: E402
from sustain_drake.files import write_atomically  # noqa: E402
from sustain_drake.provenance import source_commit  # noqa: E402
from sustain_drake.station.scenario_files import load_scenario  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "diagrams" / "soak.yaml"
# Simulated seconds between memory samples, and the two samples whose growth the target bounds.
MEMORY_EVERY_S = 60.0
GROWTH_FROM_S, GROWTH_TO_S = 300.0, 1800.0
MAX_GROWTH = 0.05  # the target: under 5 % from minute 5 to minute 30
# log.npz's samples per simulated second: a record for plots (the metrics read the experiment's own
# logs, at hand_eye.log_rate); simulate's 100 Hz would keep ~100 MB of logs over 30 minutes.
LOG_RATE_HZ = 10.0


def resident_bytes() -> int:
    """This process's resident set size (bytes), from /proc/self/statm (Linux)."""
    with open("/proc/self/statm", encoding="ascii") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def log_bytes(simulator) -> int:
    """The bytes of samples the diagram's vector logs hold in memory now (samples x (size + time) x
    8); the run moves them to disk every ``LOG_SPOOL_INTERVAL`` (``experiments.log_spool``)."""
    context, total = simulator.get_context(), 0
    for sink in log_sinks(simulator.get_system()):
        log = sink.FindLog(context)  # FindLog takes the root context
        total += 8 * log.num_samples() * (log.get_input_size() + 1)
    return total


class MemoryMonitor:
    """``simulate_scenario``'s ``on_step``: the resident memory and the logs' size every
    ``every`` simulated seconds (reads only), written to ``path`` as they come (a run stopped early
    keeps its samples so far) and printed as progress."""

    def __init__(self, every: float, path: Path):
        self.every, self.next, self.samples, self.path = every, every, [], path
        self.start, self.commit = time.perf_counter(), source_commit()

    def __call__(self, t: float, simulator) -> None:
        if t + 1e-9 < self.next:
            return
        self.next += self.every
        self.samples.append({"time_s": round(t, 6), "wall_s": time.perf_counter() - self.start,
                             "rss_mb": resident_bytes() / 1e6, "logs_mb": log_bytes(simulator) / 1e6})
        self.write()
        s = self.samples[-1]
        print(f"{t:.0f} sim s in {s['wall_s']:.0f} wall s: resident {s['rss_mb']:.0f} MB, logs "
              f"{s['logs_mb']:.1f} MB", flush=True)

    def write(self, wall: float | None = None) -> None:
        data = {"commit": self.commit, "every_s": self.every, "samples": self.samples,
                "wall_s": time.perf_counter() - self.start if wall is None else wall}
        write_atomically(self.path, json.dumps(data, indent=2) + "\n")


def run(args) -> None:
    """Runs the soak into ``args.out``: the run's outputs and ``memory.json``."""
    from sustain_drake.experiments.run import simulate_scenario

    scenario = load_scenario(args.scenario)
    monitor = MemoryMonitor(MEMORY_EVERY_S, args.out / "memory.json")
    result = simulate_scenario(scenario, args.out, label=f"{args.scenario.name}:soak", duration=args.duration,
                               log_rate=LOG_RATE_HZ, replay=False, on_step=monitor)
    monitor.write(result.wall)


def _verdict(ok: bool) -> str:
    return "met" if ok else "**not met**"


def _size(d, drawn) -> str:
    """A disturbance's size, from the scenario's draw at its time."""
    match = [x for x in drawn if abs(x.time - d["time_s"]) < 1e-6]
    if not match:
        return "-"
    x = match[0]
    if x.kind == "head_move":
        return f"turn {x.size:.3f} rad (pan {x.change[0]:+.3f}, tilt {x.change[1]:+.3f})"
    return f"slide {x.change[0] * 1e3:+.1f} mm, pivot {x.change[1]:+.3f} rad"


def memory_growth(samples: list[dict], end: float) -> dict | None:
    """The resident memory at minute 5 and at the run's end (minute 30), its growth and the growth
    net of the logs' (None: the run had no sample at or after minute 5)."""
    first = [s for s in samples if s["time_s"] >= GROWTH_FROM_S - 1e-6]
    last = [s for s in samples if s["time_s"] >= min(GROWTH_TO_S, end) - 1e-6]
    if not first or not last:
        return None
    a, b = first[0], last[-1]
    growth = (b["rss_mb"] - a["rss_mb"]) / a["rss_mb"]
    logs = (b["logs_mb"] - a["logs_mb"]) / a["rss_mb"]
    return {"from": a, "to": b, "growth": growth, "logs_growth": logs, "growth_without_logs": growth - logs}


def report(args) -> list[str]:
    """The table of ``args.out``'s run and its totals against the targets (a run without its
    metrics yet, stopped or still running: its memory so far)."""
    memory = json.loads((args.out / "memory.json").read_text(encoding="utf-8"))
    if not (args.out / "metrics.json").is_file():
        end = memory["samples"][-1]["time_s"] if memory["samples"] else 0.0
        return ([f"- no metrics.json: the run stopped (or is still running) after {end:g} simulated s"]
                + memory_lines(memory, end))
    metrics = json.loads((args.out / "metrics.json").read_text(encoding="utf-8"))
    he = metrics["hand_eye"]
    scenario = load_scenario(args.scenario)
    from sustain_drake.station.random_disturbances import draw

    drawn = draw(scenario.random_disturbances, scenario.duration, (scenario.head.pan, scenario.head.tilt),
                 (scenario.tool.slide, scenario.tool.pivot))
    end = metrics["duration_s"]
    happened = [d for d in he["disturbances"] if d["time_s"] < end]
    lines = ["| time | kind | size | detected after | re-converged after (from detection) "
             "| adopted camera after it (mm / deg) |", "|---|---|---|---|---|---|"]
    for d in happened:
        a = d.get("adopted_after")
        camera = ("-" if a is None
                  else f"{a['camera_position_error_mm']:.2f} / {a['camera_rotation_error_deg']:.3f}")
        lines.append(f"| {d['time_s']:.1f} s | {d['kind']} | {_size(d, drawn)} | "
                     f"{number(d['detection_latency_s'])} s ({d['detected_by'] or 'not detected'}) | "
                     f"{number(d['reconvergence_after_detection_s'], '.1f')} s | {camera} |")
    lines += [""] + totals(he, happened, memory, end)
    return lines


def totals(he: dict, happened: list[dict], memory: dict, end: float) -> list[str]:
    """The targets' lines: each met or not, with the worst value."""
    latencies = [d["detection_latency_s"] for d in happened]
    reconv = [d["reconvergence_after_detection_s"] for d in happened]
    detected = [x for x in latencies if x is not None and x <= 1.0]
    settled = [x for x in reconv if x is not None and x <= 15.0]
    after = [d.get("adopted_after") for d in happened]
    cams = [a for a in after if a is not None]
    good = [a for a in cams if a["camera_position_error_mm"] <= 2.0 and a["camera_rotation_error_deg"] <= 0.2]
    worst_mm = max((a["camera_position_error_mm"] for a in cams), default=None)
    worst_deg = max((a["camera_rotation_error_deg"] for a in cams), default=None)
    n = len(happened)
    first = he["adopted"][0] if he["adopted"] else None
    lines = [
        f"- {n} disturbances in {end:g} s ({sum(d['kind'] == 'tool_slip' for d in happened)} slips, "
        f"{sum(d['kind'] == 'head_move' for d in happened)} camera moves); first convergence "
        + ("never" if first is None else f"at {first['time_s']:.1f} s "
           f"({first['camera_position_error_mm']:.2f} mm / {first['camera_rotation_error_deg']:.3f} deg)"),
        f"- detected within 1 s: {len(detected)} of {n} ({_verdict(len(detected) == n)}; worst measured "
        f"{number(max((x for x in latencies if x is not None), default=None))} s)",
        f"- re-converged within 15 s of the detection: {len(settled)} of {n} "
        f"({_verdict(len(settled) == n)}; worst measured "
        f"{number(max((x for x in reconv if x is not None), default=None), '.1f')} s)",
        f"- false alarms: {he['num_false_alarms']} ({_verdict(he['num_false_alarms'] == 0)}"
        + (f": at {', '.join(f'{t:.1f} s' for t in he['false_alarms_s'])})" if he["false_alarms_s"] else ")"),
        f"- adopted camera within 2 mm / 0.2 deg after each re-convergence: {len(good)} of {n} "
        f"({_verdict(len(good) == n)}; worst {number(worst_mm)} mm / {number(worst_deg, '.3f')} deg); every "
        f"adoption of the run: {len(he['adopted'])}, wrong adoptions {he['num_wrong_adoptions']}",
    ]
    return lines + memory_lines(memory, end)


def memory_lines(memory: dict, end: float) -> list[str]:
    """The resident memory's growth against the target, its series and the run's wall time."""
    lines = []
    growth = memory_growth(memory["samples"], end)
    if growth is None:
        lines.append("- resident memory: the run did not reach minute 5")
    else:
        a, b = growth["from"], growth["to"]
        lines.append(
            f"- resident memory {a['rss_mb']:.0f} MB at {a['time_s'] / 60:.0f} min, {b['rss_mb']:.0f} MB at "
            f"{b['time_s'] / 60:.0f} min: growth {100 * growth['growth']:.1f} % "
            f"({_verdict(growth['growth'] < MAX_GROWTH)} against < 5 %); the logs' samples in memory (the "
            f"rest is on disk) changed by {b['logs_mb'] - a['logs_mb']:+.1f} MB "
            f"({100 * growth['logs_growth']:+.1f} %), the rest {100 * growth['growth_without_logs']:+.1f} %")
        series = ", ".join(f"{s['time_s'] / 60:.0f} min {s['rss_mb']:.0f}" for s in memory["samples"]
                           if round(s["time_s"]) % 300 == 0)
        lines.append(f"- resident memory (MB) by simulated minute: {series}")
    lines.append(f"- wall time {memory['wall_s'] / 60:.0f} min for {end / 60:.0f} simulated min "
                 f"({end / memory['wall_s']:.2f}x real time), one process")
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", type=Path, default=SCENARIO,
                   help="the soak's scenario (default %(default)s)")
    p.add_argument("--out", type=Path, default=ROOT / "out" / "bench_soak", help="the run's folder")
    p.add_argument("--duration", type=float, help="simulated seconds (default: the scenario's)")
    p.add_argument("--report", action="store_true", help="run nothing: report the run already in --out")
    p.add_argument("--results", action="store_true", help="also write the table on docs/results.md")
    args = p.parse_args(argv)
    if args.results and (args.duration or args.scenario != SCENARIO):
        raise SystemExit("--results publishes the whole default soak only (no --duration or --scenario)")
    if not args.report:
        run(args)
    elif not (args.out / "memory.json").is_file():
        raise SystemExit(f"{args.out} holds no soak run (memory.json) yet")
    lines = report(args)
    write_atomically(args.out / "soak.md", "\n".join(lines) + "\n")
    print("\n".join(lines))
    if args.results:  # stamped with the commit the run ran at (a report may come later)
        memory = json.loads((args.out / "memory.json").read_text(encoding="utf-8"))
        publish("bench_soak", lines, commit=memory.get("commit", "not recorded in memory.json"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
