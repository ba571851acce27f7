"""Render cost per frame of the hand-eye camera, and what it is made of (issue 24, item 3).

``diagrams/hand_eye.yaml`` renders 640x480 colour and depth at 30 fps with Drake's RenderEngineVtk,
which on this machine draws through Mesa's llvmpipe (software OpenGL). This times, in one run, the
colour and the depth render of one frame of the station's scene (arm babbling postures, person and
posters in view) under the variants that matter:

- Mesa settings, each in its own worker process (Mesa reads them when the GL context is made):
  ``stock`` (LP_NUM_THREADS=1: llvmpipe rasterises on one thread, the one-core target),
  ``no FXAA`` (the same, with VTK's FXAA fragment shader replaced by a plain copy of the frame
  through Mesa's MESA_SHADER_READ_PATH: RenderEngineVtk always ends a colour render with an FXAA
  pass, 50-75 ns per pixel on one llvmpipe thread, whatever the scene), ``2 threads``
  (LP_NUM_THREADS=2, llvmpipe's default on this 2-core machine: same work, less wall time only
  when the other core is free);
- renderers in each worker (each its own RenderEngineVtk in the station's SceneGraph, rendered in
  turn at every posture, so load changes on the shared machine hit them alike): the station's
  two ``ROOM_LIGHTS`` (the default), only the ceiling light, no lights given (Drake's fallback: one
  directional light fixed to the camera), 320x240, and an empty view (the camera looking up at
  nothing: the fixed cost).

Per row: the median over ``--frames`` postures of the wall time and of the process's CPU time
(all threads; less disturbed by other work on the machine), then the median over ``--repeat``
workers; the bound on the real-time factor at 30 fps if rendering were the only work; and how the
colour image differs from its reference (the stock row with the same renderer, or the stock
default for the stock rows), from numpy (``same`` = bit-identical).

``--closed-loop SECONDS`` also simulates the whole closed loop (``simulate_scenario``, no replay,
the person walking from t = 0) per Mesa setting, and splits its wall and CPU time per camera frame into
colour render, depth render, depth noise and the rest (physics and perception).

    .venv/bin/python bench/bench_render.py [--frames 30] [--repeat 3] [--closed-loop 5]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from results_page import publish  # noqa: E402  (bench/results_page.py)

SCENARIO = Path(__file__).resolve().parents[1] / "diagrams" / "hand_eye.yaml"

# Mesa settings: name -> environment (LP_NUM_THREADS and the FXAA shader replacement).
ENVS = ("stock", "no FXAA", "2 threads")
# Renderers / cameras timed in each worker: name -> (lights, width, height, empty view).
RENDERERS = {
    "ROOM_LIGHTS (default)": ("room", 640, 480, False),
    "1 light (ceiling)": ("ceiling", 640, 480, False),
    "no lights (headlight)": ("none", 640, 480, False),
    "320x240": ("room", 320, 240, False),
    "empty view": ("room", 640, 480, True),
}
DEFAULT = "ROOM_LIGHTS (default)"
SAVED_FRAMES = 3  # images kept per renderer for the comparisons

# Replaces VTK's FXAA fragment shader (vtkOpenGLFXAAFilter) with a copy of its input texture.
# It declares the same uniforms (VTK sets them) and reads texCoord (VTK binds texCoordIn).
COPY_SHADER = """#version 150
// Replaces VTK's vtkOpenGLFXAAFilter fragment shader: a plain copy (no anti-aliasing).
in vec2 texCoord;
uniform sampler2D Input;
uniform vec2 InvTexSize;
uniform float RelativeContrastThreshold;
uniform float HardContrastThreshold;
uniform float SubpixelBlendLimit;
uniform float SubpixelContrastThreshold;
uniform int EndpointSearchIterations;
out vec4 fragOutput0;
void main()
{
  fragOutput0 = texelFetch(Input, ivec2(texCoord / InvTexSize), 0);
}
"""


def load_hand_eye():
    from sustain_drake.station import load_scenario

    scenario = load_scenario(SCENARIO)
    scenario.distractor.start_time = 0.0  # the person walks in view during the whole run
    return scenario


def worker(frames: int, images_path: str | None) -> dict:
    """Times every renderer of RENDERERS at ``frames`` arm postures (in this process's Mesa
    setting) and returns the per-frame samples; saves the first images to ``images_path``."""
    from pydrake.geometry import (
        ColorRenderCamera,
        DepthRenderCamera,
        MakeRenderEngineVtk,
        RenderCameraCore,
        RenderEngineVtkParams,
    )
    from pydrake.math import RigidTransform
    from pydrake.systems.sensors import CameraInfo

    from sustain_drake.station import build_station
    from sustain_drake.station.build import ROOM_LIGHTS

    scenario = load_hand_eye()
    diagram = build_station(scenario)
    context = diagram.CreateDefaultContext()
    scene_graph = diagram.GetSubsystemByName("scene_graph")
    plant = diagram.GetSubsystemByName("plant")
    sensor = diagram.GetSubsystemByName("rgbd_sensor")
    sg_context = scene_graph.GetMyMutableContextFromRoot(context)
    plant_context = plant.GetMyContextFromRoot(context)
    sensor_context = sensor.GetMyContextFromRoot(context)
    station_core = sensor.GetColorRenderCamera(sensor_context).core()
    depth_range = sensor.GetDepthRenderCamera(sensor_context).depth_range()
    parent = sensor.GetParentFrameId(sensor_context)
    X_PB = sensor.GetX_PB(sensor_context)
    world = scene_graph.model_inspector().world_frame_id()
    X_W_up = RigidTransform([0.0, 0.0, 3.0])  # camera z (view axis) = world up: nothing in view
    rgba = scenario.camera.background
    lights = {"room": ROOM_LIGHTS, "ceiling": ROOM_LIGHTS[:1], "none": []}

    cameras = {}
    for name, (light, width, height, empty) in RENDERERS.items():
        renderer = f"bench_{len(cameras)}"
        scene_graph.AddRenderer(sg_context, renderer, MakeRenderEngineVtk(RenderEngineVtkParams(
            default_clear_color=[rgba.r(), rgba.g(), rgba.b()], lights=lights[light])))
        info = CameraInfo(width, height, station_core.intrinsics().fov_y())
        core = RenderCameraCore(renderer, info, station_core.clipping(),
                                station_core.sensor_pose_in_camera_body())
        cameras[name] = (ColorRenderCamera(core, False), DepthRenderCamera(core, depth_range),
                         (world, X_W_up) if empty else (parent, X_PB))

    q0 = plant.GetPositions(plant_context)
    samples = {name: {"colour": [], "colour_cpu": [], "depth": [], "depth_cpu": []}
               for name in cameras}
    saved = {}
    warmup = 2  # the first renders compile the shaders
    for k in range(warmup + frames):
        plant.SetPositions(plant_context, q0 + 0.01 * np.sin(k + np.arange(q0.size)))
        query = scene_graph.get_query_output_port().Eval(sg_context)
        query.GetPoseInWorld(parent)  # the pose update (all renderers) before any timing
        for name, (color_camera, depth_camera, (frame, X_FB)) in cameras.items():
            wall, cpu = time.perf_counter(), time.process_time()
            colour = query.RenderColorImage(color_camera, frame, X_FB)
            wall_c, cpu_c = time.perf_counter(), time.process_time()
            depth = query.RenderDepthImage(depth_camera, frame, X_FB)
            wall_d, cpu_d = time.perf_counter(), time.process_time()
            if k < warmup:
                continue
            s = samples[name]
            s["colour"].append(wall_c - wall)
            s["colour_cpu"].append(cpu_c - cpu)
            s["depth"].append(wall_d - wall_c)
            s["depth_cpu"].append(cpu_d - cpu_c)
            if k - warmup < SAVED_FRAMES:
                index = list(cameras).index(name)
                saved[f"c{index}_{k - warmup}"] = np.array(colour.data, copy=True)
                saved[f"d{index}_{k - warmup}"] = np.array(depth.data, copy=True)
            if name == "empty view" and k == warmup:
                s["finite_depth_px"] = int(np.isfinite(depth.data).sum())
    if images_path:
        np.savez(images_path, **saved)
    return samples


def closed_loop_worker(seconds: float) -> dict:
    """Simulates the whole closed loop for ``seconds`` (no replay) and returns, between the first
    and the last camera frame, the wall and CPU time in all and in the camera sampler's colour
    render, depth render and depth noise."""
    from pydrake.systems.sensors import ImageDepth32F

    from sustain_drake.experiments.run import simulate_scenario
    from sustain_drake.systems import camera_sampler

    parts = ("colour", "depth", "depth noise")
    spent = {f"{part} {clock}": 0.0 for part in parts for clock in ("wall", "cpu")}
    marks = []  # (wall, cpu) at the end of each camera frame

    def timed(part, first, call):
        wall, cpu = time.perf_counter(), time.process_time()
        value = call()
        if not first:
            spent[f"{part} wall"] += time.perf_counter() - wall
            spent[f"{part} cpu"] += time.process_time() - cpu
        return value

    def timed_sample(self, context, state):  # RgbdCameraSampler._sample, timed
        t = context.get_time()
        first = not marks
        for name in self._names:
            part = "colour" if name == "color_image" else "depth"
            image = timed(part, first, lambda name=name: self._inputs[name].Eval(context))
            if name == "depth_image" and self._noise is not None:
                def noisy(image=image):
                    rng = np.random.default_rng([self._seed, int(np.floor(t * self._fps + 1e-6))])
                    out = ImageDepth32F(image.width(), image.height())
                    out.mutable_data[:] = self._noise.apply(image.data, rng)
                    return out
                image = timed("depth noise", first, noisy)
            state.get_mutable_abstract_state(int(self._states[name])).set_value(image)
        state.get_mutable_discrete_state(self._time).set_value([t])
        marks.append((time.perf_counter(), time.process_time()))

    camera_sampler.RgbdCameraSampler._sample = timed_sample
    with tempfile.TemporaryDirectory() as out:
        simulate_scenario(load_hand_eye(), out, duration=seconds, replay=False)
    spent["frames"] = len(marks) - 1
    spent["wall"] = marks[-1][0] - marks[0][0]
    spent["cpu"] = marks[-1][1] - marks[0][1]
    spent["seconds"] = spent["frames"] / load_hand_eye().camera.fps
    return spent


def fxaa_replacement(folder: Path) -> Path | None:
    """Writes the copy shader under the name Mesa gives VTK's FXAA fragment shader (the SHA-1 of
    its source, found by dumping the shaders of one colour render) into ``folder``/read; None if
    the driver is not Mesa or dumps nothing."""
    dump, read = folder / "dump", folder / "read"
    dump.mkdir(parents=True)
    read.mkdir(parents=True)
    env = dict(os.environ, MESA_SHADER_DUMP_PATH=str(dump), LP_NUM_THREADS="1")
    subprocess.run([sys.executable, __file__, "--worker", "--frames", "1"], env=env, check=True,
                   stdout=subprocess.DEVNULL)
    for shader in sorted(dump.glob("FS_*.glsl")):
        if "vtkOpenGLFXAAFilter" in shader.read_text(errors="replace"):
            (read / shader.name).write_text(COPY_SHADER)
            return read
    return None


def run_worker(args_list: list[str], env: dict) -> dict:
    out = subprocess.run([sys.executable, __file__, "--worker", *args_list], env=env, check=True,
                         capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def compare(images: tuple[dict, dict], index: int, ref_index: int) -> str:
    """How the colour images of renderer ``index`` in ``images[0]`` differ from those of renderer
    ``ref_index`` in ``images[1]`` (numpy, over the saved frames), and whether the depth images
    are bit-identical."""
    new, ref = images
    colour = [(new[f"c{index}_{f}"], ref[f"c{ref_index}_{f}"]) for f in range(SAVED_FRAMES)]
    depth_same = all(np.array_equal(new[f"d{index}_{f}"], ref[f"d{ref_index}_{f}"])
                     for f in range(SAVED_FRAMES))
    if all(np.array_equal(a, b) for a, b in colour):
        text = "same"
    else:
        differ = np.mean([(a != b).any(axis=-1).mean() for a, b in colour])
        delta = max(np.abs(a.astype(int) - b.astype(int)).max() for a, b in colour)
        text = f"{100 * differ:.1f}% px differ (max {delta})"
    return text + ("; depth same" if depth_same else "; depth DIFFERS")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--envs", nargs="*", default=list(ENVS), choices=ENVS)
    parser.add_argument("--closed-loop", type=float, default=0.0, metavar="SECONDS",
                        help="also split the whole closed loop's time (0: skip)")
    parser.add_argument("--results", action="store_true", help="also write the table on docs/results.md")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--images", help=argparse.SUPPRESS)
    parser.add_argument("--loop-seconds", type=float, default=0.0, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        if args.loop_seconds > 0:
            print(json.dumps(closed_loop_worker(args.loop_seconds)))
        else:
            print(json.dumps(worker(args.frames, args.images)))
        return

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        envs = {}
        for name in args.envs:
            env = dict(os.environ, LP_NUM_THREADS="2" if name == "2 threads" else "1")
            env.pop("MESA_SHADER_READ_PATH", None)
            if name == "no FXAA":
                read = fxaa_replacement(tmp / "fxaa")
                if read is None:
                    print("no FXAA: Mesa dumped no FXAA shader (not Mesa?); row skipped")
                    continue
                env["MESA_SHADER_READ_PATH"] = str(read)
            envs[name] = env

        runs = {name: [] for name in envs}
        images = {}
        for r in range(args.repeat):  # the settings interleaved, so drifts in load hit all alike
            for name, env in envs.items():
                path = tmp / f"images_{len(images)}.npz" if r == 0 else None
                extra = ["--images", str(path)] if path else []
                runs[name].append(run_worker(["--frames", str(args.frames), *extra], env))
                if path:
                    images[name] = dict(np.load(path))

        loop = {}
        if args.closed_loop > 0:
            for name in ("stock", "no FXAA"):
                if name in envs:
                    loop[name] = run_worker(["--loop-seconds", str(args.closed_loop)], envs[name])

    lines = []

    def emit(text: str = "") -> None:
        lines.append(text)
        print(text, flush=True)

    def ms(name, renderer, key):
        return 1e3 * statistics.median(statistics.median(run[renderer][key]) for run in runs[name])

    emit(f"render time per frame of hand_eye.yaml's scene (median of {args.frames} postures, "
          f"then of {args.repeat} workers); colour vs its reference: stock row with the same "
          "renderer, or the stock default")
    emit()
    emit("| Mesa | renderer | colour ms | depth ms | colour CPU ms | depth CPU ms | "
          "RTF bound wall / CPU | colour image vs reference |")
    emit("|---|---|---:|---:|---:|---:|---:|---|")
    names = list(RENDERERS)
    for name in envs:
        for index, renderer in enumerate(names):
            colour, depth = ms(name, renderer, "colour"), ms(name, renderer, "depth")
            colour_cpu, depth_cpu = ms(name, renderer, "colour_cpu"), ms(name, renderer, "depth_cpu")
            reference = None
            if name != "stock" and "stock" in images:
                reference = ("stock", index)
            elif name == "stock" and renderer != DEFAULT and RENDERERS[renderer][1] == 640:
                reference = ("stock", names.index(DEFAULT))
            same = "reference" if name == "stock" else "n/a (no stock row)"
            if renderer == "empty view":
                finite = runs[name][0][renderer].get("finite_depth_px", -1)
                same = f"nothing in view ({finite} depth px)"
            elif reference is not None:
                ref_name, ref_index = reference
                same = compare((images[name], images[ref_name]), index, ref_index)
            emit(f"| {name} | {renderer} | {colour:.1f} | {depth:.1f} | {colour_cpu:.1f} | "
                  f"{depth_cpu:.1f} | {1e3 / 30 / (colour + depth):.2f}x / "
                  f"{1e3 / 30 / (colour_cpu + depth_cpu):.2f}x | {same} |")
    if loop:
        emit()
        emit(f"closed loop, {args.closed_loop:g} simulated s (simulate_scenario, no replay, between "
              "the first and the last camera frame), ms per camera frame, wall / CPU")
        emit()
        emit("| Mesa | RTF wall / CPU | colour | depth | depth noise | rest (physics, perception) |")
        emit("|---|---:|---:|---:|---:|---:|")
        for name, spent in loop.items():
            n = spent["frames"]
            cells = []
            for part in ("colour", "depth", "depth noise"):
                cells.append(f"{1e3 * spent[part + ' wall'] / n:.1f} / "
                             f"{1e3 * spent[part + ' cpu'] / n:.1f}")
            rest = [spent[clock] - sum(spent[f"{p} {clock}"] for p in ("colour", "depth", "depth noise"))
                    for clock in ("wall", "cpu")]
            emit(f"| {name} | {spent['seconds'] / spent['wall']:.2f}x / "
                  f"{spent['seconds'] / spent['cpu']:.2f}x | {' | '.join(cells)} | "
                  f"{1e3 * rest[0] / n:.1f} / {1e3 * rest[1] / n:.1f} |")
    if args.results:
        publish("bench_render", lines)


if __name__ == "__main__":
    main()
