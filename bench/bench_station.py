"""Real-time factor of the simulated world (issue 3's benchmark).

Simulates ``diagrams/hand_eye.yaml`` for 10 simulated seconds with the camera on (colour and
depth rendered by VTK at the scenario's 30 Hz, depth noise on, the person walking in view) and
prints simulated seconds per wall-clock second (higher is faster; the target is >= 2). Variants:
the same at 320x240 (the scenario's size before the hand-eye accuracy work moved it to 640x480),
without the camera (physics and sensors only), and with the Meshcat replay being recorded (what
``sustain-drake simulate`` does). Then the render cost per frame of each image at both sizes
(the sensor's colour and depth ports evaluated at 40 arm postures), which says where a faster
camera would have to save.

    .venv/bin/python bench/bench_station.py [--seconds 10] [--repeat 3] [--variants ...]

The machine is shared and noisy: the median of ``--repeat`` runs is reported.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator

from sustain_drake.station import build_station, load_scenario
from sustain_drake.station.meshcat import make_local_meshcat

SCENARIO = Path(__file__).resolve().parents[1] / "diagrams" / "hand_eye.yaml"


def scenario_variant(name: str):
    s = load_scenario(SCENARIO)
    s.distractor.start_time = 0.0  # the person walks in view during the whole run
    if name == "320x240":
        s.camera.width, s.camera.height = 320, 240
    elif name == "no camera":
        s.camera.rgb = s.camera.depth = s.camera.label = False
    return s


def realtime_factor(name: str, seconds: float) -> float:
    meshcat = make_local_meshcat() if name == "with replay" else None
    diagram = build_station(scenario_variant(name), meshcat=meshcat)
    simulator = Simulator(diagram)
    if meshcat is not None:
        meshcat.StartRecording(frames_per_second=30.0, set_visualizations_while_recording=False)
    simulator.Initialize()
    simulator.AdvanceTo(0.05)  # the renderer's first frame (shader compilation) is set-up
    start = time.perf_counter()
    simulator.AdvanceTo(0.05 + seconds)
    wall = time.perf_counter() - start
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()
        meshcat.StaticHtml()
    return seconds / wall


VARIANTS = ("hand_eye.yaml", "320x240", "no camera", "with replay")


def render_ms(name: str, postures: int = 40) -> dict:
    """Median wall time (ms) of one colour and one depth render, each at ``postures`` arm
    postures (a new posture invalidates the cached image, so every call renders)."""
    diagram = build_station(scenario_variant(name))
    context = diagram.CreateDefaultContext()
    sensor = diagram.GetSubsystemByName("rgbd_sensor")
    plant = diagram.GetSubsystemByName("plant")
    sensor_context = sensor.GetMyContextFromRoot(context)
    plant_context = plant.GetMyContextFromRoot(context)
    q0 = plant.GetPositions(plant_context)
    result = {}
    for image, port in (("colour", sensor.color_image_output_port()),
                        ("depth", sensor.depth_image_32F_output_port())):
        times = []
        for k in range(postures + 1):
            plant.SetPositions(plant_context, q0 + 0.01 * np.sin(k + np.arange(q0.size)))
            start = time.perf_counter()
            port.Eval(sensor_context)
            times.append(time.perf_counter() - start)
        result[image] = 1e3 * statistics.median(times[1:])  # the first compiles the shaders
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--variants", nargs="*", default=list(VARIANTS), choices=VARIANTS)
    args = parser.parse_args()
    camera = load_scenario(SCENARIO).camera
    print(f"real-time factor over {args.seconds:g} simulated s (median of {args.repeat}); "
          f"hand_eye.yaml renders {camera.width}x{camera.height}")
    for name in args.variants:
        factors = [realtime_factor(name, args.seconds) for _ in range(args.repeat)]
        print(f"  {name:26s} {statistics.median(factors):5.2f}x  "
              f"(runs: {', '.join(f'{f:.2f}' for f in factors)})", flush=True)
    print("render time per frame (median of 40 postures)")
    for name in ("hand_eye.yaml", "320x240"):
        ms = render_ms(name)
        print(f"  {name:26s} colour {ms['colour']:5.1f} ms, depth {ms['depth']:5.1f} ms", flush=True)


if __name__ == "__main__":
    main()
