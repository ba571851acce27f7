"""The Meshcat overlay (issue 28, item 4): the replay shows the estimated camera's frustum and the
followed point beside the true ones, hidden while not valid; checked on the recording of a short
station run (a scripted tool point: no rendering) decoded from the replay's HTML."""

from __future__ import annotations

import base64
import re
from pathlib import Path
from types import SimpleNamespace

import msgpack
import numpy as np
import pytest
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.sensors import CameraInfo
from test_hand_eye import add_scripted_loop

from sustain_drake.identification import coordination
from sustain_drake.loops.inspection import add_estimate_overlay, add_inspection
from sustain_drake.station import camera_info
from sustain_drake.station.meshcat import make_local_meshcat
from sustain_drake.systems.estimate_overlay import frustum_segments

ROOT = Path(__file__).resolve().parents[1]
FPS = 32.0  # the recording's frames per second


def recorded_tracks(html: str) -> dict[str, dict[str, list]]:
    """``{path: {track: [(frame, value), ...]}}`` of the animation in a Meshcat ``StaticHtml()``
    (its commands are base64 msgpack; the recording is the ``set_animation`` one)."""
    tracks = {}
    for blob in re.findall(r'fetch\("data:application/octet-binary;base64,([A-Za-z0-9+/=]+)"\)', html):
        message = msgpack.unpackb(base64.b64decode(blob), raw=False, strict_map_key=False)
        if message.get("type") == "set_animation":
            for animation in message["animations"]:
                tracks[animation["path"]] = {t["name"]: [(k["time"], k["value"]) for k in t["keys"]]
                                             for t in animation["clip"]["tracks"]}  # fmt: skip
    return tracks


def test_the_frustum_reaches_the_image_corners():
    info = CameraInfo(640, 480, 1.0)
    starts, ends = frustum_segments(info, 0.5)
    assert starts.shape == ends.shape == (3, 9)
    np.testing.assert_array_equal(starts[:, :4], 0.0)  # four edges from the optical centre
    K = info.intrinsic_matrix()
    pixels = (K @ ends[:, :4]) / ends[2, :4]
    np.testing.assert_allclose(pixels[:2].T, [[0, 0], [640, 0], [640, 480], [0, 480]], atol=1e-9)
    np.testing.assert_allclose(ends[2, :8], 0.5)
    assert ends[1, 8] < starts[1, 8]  # the tick points up in the image (-y)


@pytest.fixture(scope="module")
def recorded_run():
    """12 s of the station with a scripted tool point (converges by 11 s), the overlay recorded."""
    builder = DiagramBuilder()
    scripted = add_scripted_loop(builder, [])
    scenario, station, source = scripted.scenario, scripted.station, scripted.source
    candidates, machine = scripted.candidates, scripted.machine
    loop = SimpleNamespace(candidates=candidates, state_machine=machine,
                           candidate_features=lambda: source.GetOutputPort("tracked_features"))  # fmt: skip
    inspection = add_inspection(builder, loop, None)
    meshcat = make_local_meshcat()
    X_WH, true_X_WC = station.GetOutputPort("X_WH"), station.GetOutputPort("true_X_WC")
    overlay = add_estimate_overlay(builder, meshcat, camera_info(scenario), inspection, X_WH, true_X_WC)
    diagram = builder.Build()
    meshcat.StartRecording(frames_per_second=FPS, set_visualizations_while_recording=False)
    simulator = Simulator(diagram)
    simulator.AdvanceTo(12.0)
    meshcat.StopRecording()
    meshcat.PublishRecording()
    context = simulator.get_context()
    return SimpleNamespace(html=meshcat.StaticHtml(), meshcat=meshcat, overlay=overlay, station=station,
                           inspection=inspection, machine=machine, context=context)  # fmt: skip


def _last(track: list):
    return max(track, key=lambda key: key[0])[1]


def _first(track: list):
    return min(track, key=lambda key: key[0])[1]


def _pose(tracks: dict, path: str) -> RigidTransform:
    """The last recorded pose of ``path`` (three.js quaternions are ``[x, y, z, w]``)."""
    x, y, z, w = _last(tracks[path][".quaternion"])
    return RigidTransform(RotationMatrix(Quaternion(w, x, y, z)), _last(tracks[path][".position"]))


def test_the_replay_shows_the_estimated_camera_and_point_beside_the_truth(recorded_run):
    run = recorded_run
    machine_context = run.machine.GetMyContextFromRoot(run.context)
    assert run.machine.GetOutputPort("mode").Eval(machine_context)[0] == coordination.OBSERVE
    tracks = recorded_tracks(run.html)
    paths = {name: run.overlay.path(name)
             for name in ("estimated_camera", "true_camera", "estimated_point", "true_point")}  # fmt: skip
    for path in paths.values():
        assert run.meshcat.HasPath(path) and path in tracks, path
    # Hidden before the first convergence (nothing valid yet), shown at the end.
    for name in ("estimated_camera", "estimated_point", "true_point"):
        assert _first(tracks[paths[name]][".visible"]) is False, name
        assert _last(tracks[paths[name]][".visible"]) is True, name
    assert _first(tracks[paths["true_camera"]][".visible"]) is True
    # At the end, the frusta where the estimate and the truth put the camera.
    adopted = run.inspection.adopted
    adopted_context = adopted.GetMyContextFromRoot(run.context)
    X_WC = adopted.GetOutputPort("X_WC").Eval(adopted_context)
    true_X_WC = run.station.GetOutputPort("true_X_WC").Eval(run.station.GetMyContextFromRoot(run.context))
    assert _pose(tracks, paths["estimated_camera"]).IsNearlyEqualTo(X_WC, 1e-9)
    assert _pose(tracks, paths["true_camera"]).IsNearlyEqualTo(true_X_WC, 1e-9)
    assert not X_WC.IsNearlyEqualTo(true_X_WC, 1e-6)  # two different poses drawn, a few mm apart
    assert np.linalg.norm(X_WC.translation() - true_X_WC.translation()) < 0.03
    # The followed point: the estimate X_WH p_HP within 2 cm of where the true camera puts it.
    estimated, true = (np.array(_last(tracks[paths[name]][".position"]))
                       for name in ("estimated_point", "true_point"))
    assert np.linalg.norm(estimated - true) < 0.02
