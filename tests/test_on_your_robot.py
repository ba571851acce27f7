"""docs/on_your_robot.md: its script (``sustain_drake.examples.on_your_robot``) is the page's code as
written, builds from the public API, runs a short while with the coordination's default settings, and
its outputs are the documented ones; ``make_sustainable_coordination``'s docstring lists the
diagram's ports. The full run (90 s) is ``bench/bench_on_your_robot.py``."""

from __future__ import annotations

import inspect
import math
import re
from pathlib import Path

import numpy as np
import pytest
from pydrake.math import RigidTransform
from test_layers import imports_of

from sustain_drake.examples import on_your_robot
from sustain_drake.identification import coordination
from sustain_drake.loops import make_sustainable_coordination

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "on_your_robot.md"
SCRIPT = ROOT / "sustain_drake" / "examples" / "on_your_robot.py"
DURATION = 6.0  # simulated s: the camera sampled, the body found, the babbling answering requests


@pytest.fixture(scope="module")
def short_run():
    return on_your_robot.run(DURATION)


def documented_ports(doc: str) -> dict[str, dict[str, str]]:
    """``{"input_ports": {name: condition}, "output_ports": ...}`` of a ``.. pydrake_system::`` block
    (the condition is the parenthesis after the name, "" if none)."""
    block = doc.split(".. pydrake_system::", 1)[1]
    ports, section = {"input_ports": {}, "output_ports": {}}, None
    for line in block.splitlines()[1:]:
        text = line.strip()
        if text in ("input_ports:", "output_ports:"):
            section = text[:-1]
        elif text.startswith("- ") and section:
            name, _, condition = text[2:].partition(" ")
            ports[section][name] = condition.strip("()")
        elif text and not text.startswith("name:") and section:
            break
    return ports


def test_the_page_shows_the_whole_script_as_it_is():
    page = PAGE.read_text(encoding="utf-8")
    pattern = r"<!-- on-your-robot-script -->\n```python\n(.*?)```\n<!-- /on-your-robot-script -->"
    (shown,) = re.findall(pattern, page, re.DOTALL)
    assert shown == SCRIPT.read_text(encoding="utf-8")


def test_the_script_builds_from_the_public_api_only():
    """The loops' diagram, documented systems, the math's rotation angle and the models' folder: no
    station internals, experiments or command line."""
    allowed = ("sustain_drake.loops", "sustain_drake.systems.", "sustain_drake.identification.",
               "sustain_drake.station")
    imported = imports_of(SCRIPT)
    assert all(m.startswith(allowed) for m in imported), imported
    station = {m for m in imported if m.startswith("sustain_drake.station")}
    assert station <= {"sustain_drake.station", "sustain_drake.station.models_dir"}


def test_the_docstring_lists_the_diagrams_ports(short_run):
    """Every port of the built diagram is in the docstring's list, and every port listed without a
    condition (or only "optional") is on the diagram."""
    documented = documented_ports(inspect.getdoc(make_sustainable_coordination))
    diagram = short_run.robot.coordination
    for section, count, get in (("input_ports", diagram.num_input_ports(), diagram.get_input_port),
                                ("output_ports", diagram.num_output_ports(), diagram.get_output_port)):
        names = {get(i).get_name() for i in range(count)}
        assert names <= set(documented[section]), (section, names - set(documented[section]))
        always = {name for name, condition in documented[section].items() if condition in ("", "optional")}
        assert always <= names, (section, always - names)


def test_a_short_run_gives_the_documented_outputs(short_run):
    run, robot = short_run, short_run.robot
    context = robot.coordination.GetMyContextFromRoot(run.simulator.get_context())
    port = robot.coordination.GetOutputPort
    assert run.simulator.get_context().get_time() == pytest.approx(DURATION)
    # No camera yet (a first convergence needs 250 samples of a tracked point, 8.3 s at 30 fps): the
    # loop identifies, X_WC is the identity and p_HP zeros, and the run reports no camera error.
    assert run.hand_eye_mode == coordination.IDENTIFY == port("hand_eye_mode").Eval(context)[0]
    assert run.X_WC.IsExactlyIdentity() and not run.p_HP.any()
    assert math.isnan(run.camera_error_mm) and math.isnan(run.camera_error_deg)
    assert port("hand_eye_allowable_error").Eval(context)[0] == 0.0
    assert run.events == [] and port("hand_eye_events").Eval(context) == ()
    # The hand pose the loop uses is the plant's forward kinematics at the encoders' positions.
    arm_state = robot.motion.GetOutputPort("desired_state").Eval(robot.motion.GetMyContextFromRoot(
        run.simulator.get_context()))  # fmt: skip
    plant_context = robot.plant.CreateDefaultContext()
    robot.plant.SetPositions(plant_context, arm_state[:6])
    X_WH = robot.plant.GetBodyByName("gripper").body_frame().CalcPoseInWorld(plant_context)
    assert port("X_WH_used").Eval(context).IsNearlyEqualTo(X_WH, 1e-12)
    # The requests, in their documented formats: [request_id, joint, q_1..q_6] and [request_id, s].
    confirm, pause = port("motion_confirm").Eval(context), port("hand_eye_pause").Eval(context)
    assert confirm.shape == (8,) and confirm[0] >= 1 and confirm[1] in (-1, *range(6))
    assert pause.shape == (2,) and pause[0] == 0 and pause[1] == 3.0  # no convergence: no pause yet
    # The babbling answered them within its ranges: the arm moved, and stayed in them.
    lower, upper = np.array(on_your_robot.JOINT_RANGES).T
    assert np.all(arm_state[:6] >= lower - 1e-9) and np.all(arm_state[:6] <= upper + 1e-9)
    assert np.max(np.abs(arm_state[:6] - on_your_robot.START)) > 0.01
    assert port("camera_motion").Eval(context).shape == (2,)


def test_the_camera_error_is_measured_against_the_true_camera():
    true = on_your_robot.X_WC
    assert on_your_robot.camera_error(true, true) == (0.0, 0.0)
    moved = RigidTransform(true.rotation(), true.translation() + [0.003, 0.0, -0.004])
    mm, deg = on_your_robot.camera_error(moved, true)
    assert mm == pytest.approx(5.0) and deg == pytest.approx(0.0, abs=1e-6)


def test_main_prints_the_mode_and_the_camera(capsys):
    assert on_your_robot.main(["--duration", "0.2"]) == 0
    out = capsys.readouterr().out
    assert "after 0.2 s" in out and "hand_eye_mode 0 (identify)" in out
    assert "X_WC nan mm / nan deg from the true camera" in out
