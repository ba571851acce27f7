"""The simulated world: scenarios load, build and simulate offline; images, labels, ground truth
and disturbances behave as documented."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydrake.common.yaml import yaml_dump_typed
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator

from sustain_drake.station import (
    EXPORTED_OUTPUTS,
    ScenarioError,
    build_station,
    load_scenario,
    models_dir,
)
from sustain_drake.station.scenario import HeadMove, Scenario, ToolSlip, arm_of
from sustain_drake.station.scenario_files import load_scenario_string

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = sorted((ROOT / "diagrams").glob("*.yaml"))


def quiet_scenario(**changes) -> Scenario:
    """A fast scenario: no camera, no distractor, the arm holding its initial posture."""
    s = Scenario()
    s.camera.rgb = s.camera.depth = s.camera.label = False
    s.distractor.enabled = False
    s.motion.joint_ranges = [[q, q] for q in s.motion.initial_posture]
    for key, value in changes.items():
        setattr(s, key, value)
    return s


def simulate(diagram, t: float):
    simulator = Simulator(diagram)
    simulator.AdvanceTo(t)
    return simulator.get_context()


def test_the_papers_three_scenarios_exist():
    assert {p.name for p in SCENARIOS} >= {
        "body_detection.yaml", "hand_eye.yaml", "inertia_touch.yaml"}


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_each_scenario_builds_and_simulates_half_a_second(path):
    scenario = load_scenario(path)
    diagram = build_station(scenario)
    context = simulate(diagram, 0.5)
    assert context.get_time() == pytest.approx(0.5)
    for name in ("joint_positions", "joint_velocities", "wrench", "true_p_HP"):
        value = diagram.GetOutputPort(name).Eval(context)
        assert np.all(np.isfinite(value)), name
    q = diagram.GetOutputPort("joint_positions").Eval(context)
    assert q.shape == (len(arm_of(scenario).joints),)  # 5 on the first arm, 6 on the second


def test_hand_eye_timeline_is_the_papers():
    s = load_scenario(ROOT / "diagrams" / "hand_eye.yaml")
    assert s.duration == 130.0
    assert s.tool.model == "rod"
    slips = [e.time for e in s.disturbances if isinstance(e, ToolSlip)]
    moves = [e.time for e in s.disturbances if isinstance(e, HeadMove)]
    assert slips == [75.0] and moves == [113.0]
    assert s.camera.fps == 30.0


def test_models_are_ours_and_offline():
    files = [p for p in models_dir().rglob("*") if p.suffix in (".sdf", ".urdf", ".xml")]
    assert len(files) >= 6
    for p in files:
        assert "drake_models" not in p.read_text(), p
    for p in SCENARIOS:
        assert "drake_models" not in p.read_text(), p


@pytest.fixture(scope="module")
def camera_run():
    """The default world (640x480 camera with labels), 0.41 s in, with the person in view."""
    s = Scenario()
    s.distractor.waypoints = [[-1.0, 0.0], [-1.0, 0.5]]
    s.distractor.start_time = 0.0
    diagram = build_station(s)
    return diagram, simulate(diagram, 0.41)


def test_images_are_not_empty(camera_run):
    diagram, context = camera_run
    color = diagram.GetOutputPort("color_image").Eval(context).data
    depth = diagram.GetOutputPort("depth_image").Eval(context).data
    assert color.shape == (480, 640, 4) and depth.shape == (480, 640, 1)
    assert color[:, :, :3].std() > 10  # not a blank frame
    finite = np.isfinite(depth) & (depth > 0)
    assert finite.mean() > 0.5
    assert 0.3 < np.median(depth[finite]) < 5.0
    t = diagram.GetOutputPort("image_time").Eval(context)[0]
    assert t == pytest.approx(12 / 30)  # sampled at 30 Hz


def test_label_image_marks_the_arm(camera_run):
    diagram, context = camera_run
    plant = diagram.GetSubsystemByName("plant")
    label = diagram.GetOutputPort("label_image").Eval(context).data[:, :, 0]
    arm = plant.GetModelInstanceByName("arm")
    arm_labels = [int(i) for i in plant.GetBodyIndices(arm)]
    person = plant.GetModelInstanceByName("person")
    person_labels = [int(i) for i in plant.GetBodyIndices(person)]
    arm_pixels = np.isin(label, arm_labels)
    assert arm_pixels.sum() > 500
    assert np.isin(label, person_labels).sum() > 500  # the distractor is labelled apart
    assert not np.any(arm_pixels & np.isin(label, person_labels))
    # The arm's pixels are where the arm projects: around the projected hand position.
    X_WC = diagram.GetOutputPort("true_X_WC").Eval(context)
    X_WH = diagram.GetOutputPort("X_WH").Eval(context)
    p_CH = X_WC.inverse() @ X_WH.translation()
    assert p_CH[2] > 0  # in front of the camera
    f = 240 / np.tan(np.radians(45) / 2)  # FovDegrees y = 45 at 480 rows
    u, v = 320 + f * p_CH[0] / p_CH[2], 240 + f * p_CH[1] / p_CH[2]
    rows, cols = np.nonzero(arm_pixels)
    assert np.min(np.hypot(cols - u, rows - v)) < 15


def test_depth_noise_grows_with_range():
    from sustain_drake.systems.depth_noise import DepthNoiseModel
    model = DepthNoiseModel()
    rng = np.random.default_rng(0)
    near = model.apply(np.full((100, 100, 1), 0.5, np.float32), rng) - 0.5
    far = model.apply(np.full((100, 100, 1), 3.0, np.float32), rng) - 3.0
    assert near.std() == pytest.approx(model.sigma(0.5), rel=0.05)
    assert far.std() == pytest.approx(model.sigma(3.0), rel=0.05)
    assert far.std() > 5 * near.std()
    special = model.apply(np.array([[0.0], [np.inf]], np.float32), rng)
    assert special[0, 0] == 0.0 and np.isinf(special[1, 0])


def test_tool_slip_changes_the_true_tool_point():
    s = quiet_scenario()
    s.disturbances = [ToolSlip(time=0.2, slide=0.03, pivot=0.3, duration=0.05)]
    diagram = build_station(s)
    simulator = Simulator(diagram)
    context = simulator.get_context()
    simulator.AdvanceTo(0.15)
    before = diagram.GetOutputPort("true_p_HP").Eval(context).copy()
    com_before = diagram.GetOutputPort("true_p_KCm").Eval(context).copy()
    X_WC_before = RigidTransform(diagram.GetOutputPort("true_X_WC").Eval(context))  # a copy
    simulator.AdvanceTo(0.6)
    after = diagram.GetOutputPort("true_p_HP").Eval(context)
    # The tip was 0.25 m along z from the grasp point (0.09 m from H); after the slip it is
    # displaced by the slide and turned by the pivot about the closing axis x.
    np.testing.assert_allclose(before, [0, 0, 0.09 + 0.25], atol=2e-3)
    expected = np.array([0, -0.25 * np.sin(0.3), 0.09 + 0.03 + 0.25 * np.cos(0.3)])
    np.testing.assert_allclose(after, expected, atol=3e-3)
    assert np.linalg.norm(diagram.GetOutputPort("true_p_KCm").Eval(context) - com_before) > 0.02
    # The camera did not move.
    X_WC_after = diagram.GetOutputPort("true_X_WC").Eval(context)
    assert X_WC_after.IsNearlyEqualTo(X_WC_before, 1e-6)


def test_head_move_changes_the_true_camera_pose():
    s = quiet_scenario()
    s.disturbances = [HeadMove(time=0.1, pan=0.3, tilt=0.5, duration=0.2)]
    diagram = build_station(s)
    simulator = Simulator(diagram)
    context = simulator.get_context()
    simulator.AdvanceTo(0.05)
    X_WC_before = RigidTransform(diagram.GetOutputPort("true_X_WC").Eval(context))  # a copy
    simulator.AdvanceTo(1.0)
    X_WC_after = diagram.GetOutputPort("true_X_WC").Eval(context)
    head = diagram.GetOutputPort("head_joint_positions").Eval(context)
    np.testing.assert_allclose(head, [0.3, 0.5], atol=0.01)
    angle = np.arccos(np.clip(
        (np.trace((X_WC_before.rotation().inverse() @ X_WC_after.rotation()).matrix()) - 1) / 2,
        -1, 1))
    assert angle > 0.25


def test_exported_ports_match_the_documented_list():
    diagram = build_station(Scenario())
    names = {diagram.get_output_port(i).get_name() for i in range(diagram.num_output_ports())}
    assert names == set(EXPORTED_OUTPUTS)
    inputs = {diagram.get_input_port(i).get_name() for i in range(diagram.num_input_ports())}
    assert inputs == {"motion_pause", "motion_confirm", "motion_goal"}


@pytest.mark.parametrize("text, key", [
    ("durration: 3\n", "durration"),
    ("motion: {max_sped: 1.0}\n", "max_sped"),
    ("camera: {fsp: 30}\n", "fsp"),
    ("disturbances: [!ToolSlip {tim: 3.0}]\n", "tim"),
])
def test_a_misspelled_key_names_the_key(tmp_path, text, key):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ScenarioError) as error:
        load_scenario(path)
    message = str(error.value)
    assert key in message and "\n" not in message and str(path) in message


@pytest.mark.parametrize("text, words", [
    ("duration: -1\n", "duration"),
    ("duration: .nan\n", "duration"),
    ("motion: {initial_posture: [0, 1]}\n", "initial_posture"),
    ("tool: {model: hammer}\n", "tool.model"),
    ("disturbances: [!Slip {time: 3.0}]\n", "!Slip"),
    ("disturbances: [!Touch {time: 1, p_TQ: [0, 0]}]\n", "p_TQ"),
    ("wrench_sensor: {bias: [1, 2]}\n", "bias"),
    ("camera: {z_near: 9}\n", "camera"),
    ("[1, 2]\n", "dict"),
    # The hand-eye settings, checked at load even with their experiment off.
    ("hand_eye: {max_candidates: 0}\n", "hand_eye.max_candidates must be"),
    ("hand_eye: {tool_radius: -0.1}\n", "hand_eye.tool_radius must be"),
    # The loop's constants are no scenario keys (hand_eye_parts).
    ("hand_eye: {candidates: {max_candidates: 4}}\n", "candidates"),
    ("hand_eye: {refinement: {corner_window_px: 3}}\n", "refinement"),
])
def test_bad_values_are_one_line_errors(text, words):
    with pytest.raises(ScenarioError) as error:
        load_scenario_string(text)
    assert words in str(error.value) and "\n" not in str(error.value)


def test_missing_scenario_file_is_a_clear_error(tmp_path):
    with pytest.raises(ScenarioError, match="no such scenario file"):
        load_scenario(tmp_path / "nope.yaml")


def test_cloned_contexts_simulate_identically():
    diagram = build_station(quiet_scenario(motion=Scenario().motion))
    simulator = Simulator(diagram)
    simulator.AdvanceTo(0.3)
    clone = simulator.get_context().Clone()
    simulator.AdvanceTo(0.6)
    other = Simulator(diagram, clone)
    other.AdvanceTo(0.6)
    for name in ("joint_positions", "wrench"):
        np.testing.assert_array_equal(
            diagram.GetOutputPort(name).Eval(simulator.get_context()),
            diagram.GetOutputPort(name).Eval(other.get_context()))


def _sag_at_rest(gravity_compensation: bool) -> float:
    """Largest joint drift (rad) of the arm holding its initial posture for 0.5 s."""
    s = quiet_scenario()
    s.motion.gravity_compensation = gravity_compensation
    diagram = build_station(s)
    context = simulate(diagram, 0.5)
    q = diagram.GetOutputPort("joint_positions").Eval(context)
    return float(np.max(np.abs(q - np.asarray(s.motion.initial_posture))))


def test_gravity_compensation_holds_the_arm_up():
    # Without it the PD joints sag ~0.008 rad under the arm's weight; with it only the held
    # tool's weight (unknown to the arm's controller model) is left, ~5x less.
    uncompensated, compensated = _sag_at_rest(False), _sag_at_rest(True)
    assert uncompensated > 0.005
    assert compensated < 0.25 * uncompensated


def test_backdrop_gives_the_static_scene_corners():
    """The posters (``backdrop.enabled``) sit on the back wall, ~4 m from the head, and give the
    image's static upper part (above the arm, which stays below the wall's horizon line here)
    Shi-Tomasi corners, where the plain wall has none."""
    import cv2

    def upper_corners_and_depth(enabled: bool):
        s = Scenario()
        s.camera.width, s.camera.height, s.camera.label = 320, 240, False
        s.distractor.enabled = False
        s.backdrop.enabled = enabled
        diagram = build_station(s)
        context = simulate(diagram, 0.1)
        color = diagram.GetOutputPort("color_image").Eval(context).data[:, :, :3]
        depth = diagram.GetOutputPort("depth_image").Eval(context).data[:, :, 0]
        gray = cv2.cvtColor(np.ascontiguousarray(color), cv2.COLOR_RGB2GRAY)
        upper = np.zeros_like(gray)
        upper[:60] = 255  # the top quarter: wall only (the arm's tip stays lower)
        corners = cv2.goodFeaturesToTrack(gray, 300, 0.01, 8, mask=upper)
        return 0 if corners is None else len(corners), np.median(depth[:60])

    plain, plain_depth = upper_corners_and_depth(False)
    posters, posters_depth = upper_corners_and_depth(True)
    assert plain <= 2 < 20 <= posters
    # The posters are on the wall: the same depth within their 3 cm offset and the depth noise.
    assert 3.5 < posters_depth < 5.0 and abs(posters_depth - plain_depth) < 0.1


def test_named_variants_are_merges_of_the_base_scenario():
    """``hand_eye_steady`` is a YAML merge of ``hand_eye`` in one file: it differs in its duration
    and disturbances only."""
    path = ROOT / "diagrams" / "hand_eye.yaml"
    base = load_scenario(path)  # the one named like the file
    assert yaml_dump_typed(base) == yaml_dump_typed(load_scenario(path, "hand_eye"))
    steady = load_scenario(path, "hand_eye_steady")
    assert (steady.duration, steady.disturbances, len(base.disturbances)) == (600.0, [], 2)
    steady.duration, steady.disturbances = base.duration, base.disturbances
    assert yaml_dump_typed(steady) == yaml_dump_typed(base)  # Drake's configs define no ==


def test_a_file_of_named_scenarios_is_read_by_name(tmp_path):
    """One scenario per file, or several by name; every wrong name is a one-line error naming the
    choices."""
    plain = tmp_path / "plain.yaml"
    plain.write_text("duration: 3.0\n")
    assert load_scenario(plain).duration == 3.0
    with pytest.raises(ScenarioError, match="holds one scenario"):
        load_scenario(plain, "plain")
    named = tmp_path / "two.yaml"
    named.write_text("a: &a\n  duration: 4.0\nb:\n  <<: *a\n  duration: 5.0\n")
    assert (load_scenario(named, "a").duration, load_scenario(named, "b").duration) == (4.0, 5.0)
    with pytest.raises(ScenarioError, match=r"holds the scenarios a, b: name one"):
        load_scenario(named)
    with pytest.raises(ScenarioError, match=r"has no scenario 'c' \(it has a, b\)"):
        load_scenario(named, "c")
    named.write_text("a:\n  duration: -1.0\n")
    with pytest.raises(ScenarioError, match=r"two.yaml \[a\]: duration must be a number above 0"):
        load_scenario(named)  # the only one
    named.write_text("- 1\n- 2\n")
    with pytest.raises(ScenarioError, match="a mapping of keys to values"):
        load_scenario(named)
