"""The "On your robot" script in full (docs/on_your_robot.md): the second arm with a fixed camera
beside it, the MotionGenerator babbling, ``make_sustainable_coordination`` with its default settings,
hand-eye only, for 90 simulated s per seed. Prints every hand-eye event with the adopted camera's
error against the true camera at that moment, then a line per seed: the first convergence, the
camera's error at each adoption and at the end, the change detections (all false alarms: nothing is
disturbed) and the wall time.

    .venv/bin/python bench/bench_on_your_robot.py [--duration 90] [--seeds 0 1 2]

About 2 s of a core per simulated s (rendering 640x480 colour and depth at 30 fps).
"""

from __future__ import annotations

import argparse
import math

from sustain_drake.examples.on_your_robot import Event, run

# The hand-eye targets an adopted camera is held to (docs/results.md).
CAMERA_TARGET_MM, CAMERA_TARGET_DEG = 2.0, 0.2


def show(e: Event) -> None:
    print(f"  {e.time:7.2f} s  {e.kind:16s} {e.detail:34s} camera {e.camera_error_mm:8.2f} mm "
          f"{e.camera_error_deg:7.3f} deg", flush=True)


def summary(seed: int, result, duration: float) -> str:
    adoptions = [e for e in result.events if e.kind == "converged"]
    alarms = [e for e in result.events if e.kind == "change_detected"]
    first = f"{adoptions[0].time:.1f} s" if adoptions else "never"
    errors = ", ".join(f"{e.camera_error_mm:.2f} mm / {e.camera_error_deg:.3f} deg" for e in adoptions) or "-"
    within = sum(e.camera_error_mm <= CAMERA_TARGET_MM and e.camera_error_deg <= CAMERA_TARGET_DEG
                 for e in adoptions)
    end = ("none adopted" if math.isnan(result.camera_error_mm)
           else f"{result.camera_error_mm:.2f} mm / {result.camera_error_deg:.3f} deg")
    return (f"seed {seed}: first convergence {first}; adoptions {len(adoptions)} ({within} within "
            f"{CAMERA_TARGET_MM:g} mm / {CAMERA_TARGET_DEG:g} deg): {errors}; at {duration:g} s: mode "
            f"{result.hand_eye_mode}, camera {end}; false alarms {len(alarms)}; "
            f"{result.wall_time:.0f} s wall ({duration / result.wall_time:.2f}x real time)")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=90.0, help="simulated s per seed (default: 90)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="the motion and noise seeds")
    args = parser.parse_args(argv)
    lines = []
    for seed in args.seeds:
        print(f"seed {seed}:", flush=True)
        result = run(args.duration, seed, show)
        lines.append(summary(seed, result, args.duration))
        print(lines[-1], flush=True)
    print("\n".join(["", *lines]))


if __name__ == "__main__":
    main()
