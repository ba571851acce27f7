"""``sustain-drake simulate`` and ``graph``: outputs, and one-line errors for bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_estimate_overlay import recorded_tracks

from sustain_drake.cli.main import main
from sustain_drake.station.scenario import scenario_text
from sustain_drake.station.scenario_files import load_scenario_string

ROOT = Path(__file__).resolve().parents[1]
HAND_EYE = ROOT / "diagrams" / "hand_eye.yaml"


def test_simulate_writes_a_replay_and_logs(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["simulate", str(HAND_EYE), "--duration", "0.3", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert str(out / "replay.html") in printed
    html = (out / "replay.html").read_text()
    assert "<html" in html.lower() and len(html) > 10_000
    assert 'src="http' not in html  # self-contained: no scripts fetched from the network
    # The overlay: the true camera's frustum from the start, the estimated one hidden (none yet).
    tracks = recorded_tracks(html)
    assert tracks["/overlay/true_camera"][".visible"][0][1] is True
    assert all(visible is False for _, visible in tracks["/overlay/estimated_camera"][".visible"])
    log = np.load(out / "log.npz")
    t = log["time"]
    assert t[0] == 0.0 and t[-1] == pytest.approx(0.3, abs=0.011)
    assert np.all(np.diff(t) > 0)
    assert log["joint_positions"].shape == (len(t), 5)
    assert log["wrench"].shape == (len(t), 6)
    assert log["X_WH"].shape == (len(t), 4, 4)
    np.testing.assert_allclose(log["X_WH"][:, 3], [[0, 0, 0, 1]] * len(t))
    assert np.all(np.isfinite(log["true_X_WC"]))
    # The scenario as run, every key written out: it loads back to the same scenario.
    ran = str(log["scenario"])
    assert "slide: 0.04" in ran and "!HeadMove" in ran and "max_candidates: 8" in ran
    assert scenario_text(load_scenario_string(ran)) == ran


def test_graph_writes_dot(tmp_path, capsys):
    out = tmp_path / "g" / "hand_eye.dot"
    assert main(["graph", str(HAND_EYE), "--out", str(out)]) == 0
    dot = out.read_text()
    assert dot.startswith("digraph") and "wrench_sensor" in dot and "motion_generator" in dot


@pytest.mark.parametrize("args, words", [
    (["simulate", "missing.yaml"], "no such scenario file"),
    (["simulate", str(HAND_EYE), "--duration", "nan"], "--duration"),
    (["simulate", str(HAND_EYE), "--duration", "0"], "--duration"),
    (["simulate", str(HAND_EYE), "--log-rate", "-5"], "--log-rate"),
    (["graph", str(HAND_EYE), "--out", "x.png"], ".dot"),
])
def test_bad_arguments_are_one_line_errors(tmp_path, capsys, args, words):
    assert main(args) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1 and "Traceback" not in err


@pytest.mark.parametrize("command", ["simulate", "graph"])
def test_a_scenario_the_world_cannot_be_built_from_is_a_one_line_error(tmp_path, capsys,
                                                                       command):
    bad = tmp_path / "bad.yaml"
    bad.write_text("camera: {X_PB: {base_frame: 'head::camera_mnt'}}\n")
    assert main([command, str(bad), "--out", str(tmp_path / "o.dot")]) == 2
    err = capsys.readouterr().err
    assert "camera_mnt" in err and err.count("\n") == 1 and "Traceback" not in err


def test_misspelled_key_is_one_line_error_naming_it(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("duration: 1\nmotion: {sead: 3}\n")
    assert main(["simulate", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "sead" in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists()  # nothing written on bad input


def test_an_experiment_setting_its_systems_refuse_is_one_line_error(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("duration: 1\ncamera: {rgb: true, depth: true}\nmotion: {joint_ranges: "
                   "[[-0.7, 0.7], [0.2, 0.9], [0.7, 1.5], [-0.3, 1.0], [-1.2, 1.2]]}\n"
                   "hand_eye: {enabled: true, identifying_motion_interval: 1.0, "
                   "identifying_motion_max_hold: 0.5}\n")
    assert main(["simulate", str(bad), "--out", str(tmp_path / "o"), "--no-replay"]) == 2
    err = capsys.readouterr().err
    assert "max_hold" in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "o").exists()  # nothing written on bad input


def test_graph_writes_svg_when_dot_is_installed(tmp_path, monkeypatch, capsys):
    # A stand-in for graphviz's dot on PATH: it must receive the .dot text on stdin.
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    fake = bin_dir / "dot"
    fake.write_text('#!/bin/sh\n[ "$1" = "-Tsvg" ] || exit 1\n'
                    'grep -q digraph && echo "<svg>station</svg>"\n')
    fake.chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}:/usr/bin:/bin")
    out = tmp_path / "g" / "hand_eye.dot"
    assert main(["graph", str(HAND_EYE), "--out", str(out)]) == 0
    assert out.with_suffix(".svg").read_text().strip() == "<svg>station</svg>"
    assert str(out.with_suffix(".svg")) in capsys.readouterr().out
