"""What the run's logs cost in resident memory, kept in memory or moved to disk every simulated minute
(``experiments.log_spool``; issue 23's soak memory target).

    .venv/bin/python bench/bench_log_memory.py [--duration 900] [--log-rate 100] [--results]

Runs ``diagrams/inertia_touch.yaml`` (no camera: minutes of simulated time in a minute or two of wall
time) twice, each in a fresh process: with the logs drained to disk every ``LOG_SPOOL_INTERVAL`` as
``simulate_scenario`` does, and with them kept in memory (the interval set beyond the run). Prints
the resident set (``/proc/self/statm``) every simulated minute and its growth from minute 2 to the
end, for both; the outputs of the two runs are the same (``tests/test_log_spool.py``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from results_page import publish  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
FROM_S = 120.0  # s: the growth is measured from here (the first drain and the first buffers are done)


def one_run(duration: float, log_rate: float, drained: bool) -> list[tuple[float, float]]:
    """``[(simulated s, resident MB)]`` every simulated minute of one run, in this process."""
    from bench_soak import resident_bytes

    from sustain_drake.experiments import run
    from sustain_drake.station import load_scenario

    if not drained:
        run.LOG_SPOOL_INTERVAL = float("inf")
    samples = []

    def on_step(t, simulator):
        if abs(t / 60.0 - round(t / 60.0)) < 1e-6:
            samples.append((t, resident_bytes() / 1e6))

    scenario = load_scenario(ROOT / "diagrams" / "inertia_touch.yaml")
    with tempfile.TemporaryDirectory() as out:
        run.simulate_scenario(scenario, out, duration=duration, replay=False, log_rate=log_rate,
                              on_step=on_step)
    return samples


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=900.0, help="simulated s per run")
    parser.add_argument("--log-rate", type=float, default=100.0, help="log.npz's samples per s")
    parser.add_argument("--results", action="store_true", help="publish the table in docs/results.md")
    parser.add_argument("--one", choices=("drained", "kept"), help=argparse.SUPPRESS)  # a child run
    args = parser.parse_args()
    if args.one:
        print(json.dumps(one_run(args.duration, args.log_rate, args.one == "drained")))
        return 0
    series = {}
    for mode in ("drained", "kept"):  # each in a fresh process: no memory left from the other
        out = subprocess.run([sys.executable, __file__, "--one", mode, "--duration", str(args.duration),
                              "--log-rate", str(args.log_rate)], check=True, capture_output=True, text=True)
        series[mode] = json.loads(out.stdout.strip().splitlines()[-1])
    lines = [f"`inertia_touch.yaml`, {args.duration:.0f} simulated s, `log.npz` at {args.log_rate:g} Hz; "
             "resident memory (MB) by simulated minute:", "",
             "| logs | " + " | ".join(f"{t / 60:.0f} min" for t, _ in series["kept"]) + f" | growth from "
             f"minute {FROM_S / 60:.0f} |", "|---|" + "---:|" * (len(series["kept"]) + 1)]
    for mode, label in (("drained", "on disk every minute (the default)"), ("kept", "kept in memory")):
        start = min(series[mode], key=lambda sample: abs(sample[0] - FROM_S))[1]  # t is a sum of steps
        end = series[mode][-1][1]
        growth = f"{100 * (end - start) / start:+.1f} %"
        lines.append(f"| {label} | " + " | ".join(f"{v:.0f}" for _, v in series[mode]) + f" | {growth} |")
    print("\n".join(lines))
    if args.results:
        publish("bench_log_memory", lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
