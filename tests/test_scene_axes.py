"""The scene's appearance axes (issue 27): the held tool's look (``tool.model``: the rod and four
workshop tools without a checker) and the lighting (``lights``). Each tool is built, held by the
gripper, rendered with its own texture and seen by the tracker's corner detector as its texture
allows; a dimmer light from the side darkens the image and lights one side of the tool."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import cv2
import numpy as np
import pytest
from pydrake.common.schema import Transform
from pydrake.geometry import LightParameter
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator

from sustain_drake.perception.optical_flow import TrackerParams
from sustain_drake.station import ScenarioError, build_station, models_dir
from sustain_drake.station.build import ROOM_LIGHTS
from sustain_drake.station.models import TOOL_FILES
from sustain_drake.station.scenario import TOOL_MODELS, Scenario
from sustain_drake.station.scenario_files import load_scenario_string

ROOT = Path(__file__).resolve().parents[1]
WORKSHOP = ("wood_handle", "metal_bar", "speckle_bar", "plain_bar")
TEXTURED = ("rod", "wood_handle", "speckle_bar")  # textures made of marks all over
# The second lighting set-up of docs/scenarios.md: one directional light from the arm's side (+y,
# from the camera's side of the arm, from above), 0.6: under half the room's two (0.8 + 0.5).
SIDE_LIGHT = [LightParameter(type="directional", frame="world", direction=[-0.5, -1.0, -0.5],
                             intensity=0.6)]


def still_scenario(model: str, lights=(), yaw: float = 0.0) -> Scenario:
    """The default world holding ``model`` at the arm's initial posture, no person; the tool turned
    by ``yaw`` about its own axis."""
    s = Scenario()
    s.distractor.enabled = False
    s.motion.joint_ranges = [[q, q] for q in s.motion.initial_posture]
    s.tool.model = model
    s.tool.X_GT = Transform(RigidTransform(RollPitchYaw(0.0, 0.0, yaw), [0.0, 0.0, 0.0]))
    s.lights = list(lights)
    return s


def render(scenario: Scenario):
    """The first colour image (RGB) and the held tool's pixels (from the label image)."""
    diagram = build_station(scenario)
    simulator = Simulator(diagram)
    simulator.AdvanceTo(0.05)
    context = simulator.get_context()
    color = diagram.GetOutputPort("color_image").Eval(context).data[:, :, :3].copy()
    label = diagram.GetOutputPort("label_image").Eval(context).data[:, :, 0]
    tool = int(diagram.GetSubsystemByName("plant").GetBodyByName("tool").index())
    return color, label == tool


@pytest.fixture(scope="module")
def renders():
    return {model: render(still_scenario(model)) for model in ("rod", *WORKSHOP)}


def test_every_tool_is_a_scenario_choice():
    assert TOOL_MODELS == ("rod", "box", *WORKSHOP, "charuco_board", "none")
    for model in TOOL_FILES:
        assert (models_dir() / TOOL_FILES[model]).is_file()
    assert load_scenario_string("tool: {model: speckle_bar}\n").tool.model == "speckle_bar"
    with pytest.raises(ScenarioError, match="tool.model must be one of rod, box, wood_handle"):
        load_scenario_string("tool: {model: hammer}\n")


@pytest.mark.parametrize("model", WORKSHOP)
def test_the_bars_have_the_rods_grip_and_tool_frame(model):
    """50 mm square like the rod (one gripper closing holds them all), 0.25-0.35 m long from 0.05 m
    behind the grasp point, the tracked point at the tip."""
    obj = (models_dir() / "meshes" / f"{model}.obj").read_text().splitlines()
    v = np.array([[float(x) for x in line.split()[1:]] for line in obj if line.startswith("v ")])
    np.testing.assert_allclose(v[:, :2].min(0), [-0.025, -0.025])
    np.testing.assert_allclose(v[:, :2].max(0), [0.025, 0.025])
    assert v[:, 2].min() == pytest.approx(-0.05)
    assert 0.25 <= v[:, 2].max() - v[:, 2].min() <= 0.35
    diagram = build_station(still_scenario(model))
    plant = diagram.GetSubsystemByName("plant")
    tip = plant.GetFrameByName("tracked_point").GetFixedPoseInBodyFrame().translation()
    np.testing.assert_allclose(tip, [0.0, 0.0, v[:, 2].max()])
    body = plant.GetBodyByName("tool")
    assert 0.2 <= body.default_mass() <= 1.0  # kg: wood, aluminium and PVC of this size
    assert body.default_com()[2] == pytest.approx(v[:, 2].mean())


@pytest.mark.parametrize("model", WORKSHOP)
def test_each_tool_stays_in_the_gripper_while_the_arm_moves(model):
    s = still_scenario(model)
    s.motion = Scenario().motion  # babbling
    s.camera.rgb = s.camera.depth = s.camera.label = False
    diagram = build_station(s)
    plant = diagram.GetSubsystemByName("plant")
    tip = plant.GetFrameByName("tracked_point").GetFixedPoseInBodyFrame().translation()
    simulator = Simulator(diagram)
    context = simulator.get_context()
    q0 = diagram.GetOutputPort("joint_positions").Eval(context).copy()
    for t in (0.5, 1.0, 1.5):
        simulator.AdvanceTo(t)
        # The tip is where the grasp (0.09 m along the hand's z) holds it: true_p_HP, as the rod's.
        p_HP = diagram.GetOutputPort("true_p_HP").Eval(context)
        np.testing.assert_allclose(p_HP, [0.0, 0.0, 0.09 + tip[2]], atol=2e-3)
    assert np.abs(diagram.GetOutputPort("joint_positions").Eval(context) - q0).max() > 0.05  # it moved
    mass = diagram.GetOutputPort("true_tool_mass").Eval(context)[0]
    assert mass == pytest.approx(plant.GetBodyByName("tool").default_mass())


def test_each_tool_renders_with_its_own_texture(renders):
    means, stds = {}, {}
    for model, (color, mask) in renders.items():
        assert mask.sum() > 3000, model  # in view, ~40 x 170 px at 0.7 m
        means[model] = color[mask].astype(float).mean(0)
        stds[model] = cv2.cvtColor(color, cv2.COLOR_RGB2GRAY)[mask].std()
    for a in means:
        for b in means:
            if a < b:
                assert np.linalg.norm(means[a] - means[b]) > 20, (a, b)
    assert stds["speckle_bar"] > 50 and stds["rod"] > 50  # black-and-white marks
    assert stds["plain_bar"] < 20  # one colour: only the shading of its faces


def _corners_inside(color: np.ndarray, mask: np.ndarray) -> int:
    """Shi-Tomasi corners of the whole image with the tracker's settings that lie inside the tool's
    silhouette shrunk by 5 px (a corner of the silhouette itself is not the texture's)."""
    p = TrackerParams()
    gray = cv2.cvtColor(color, cv2.COLOR_RGB2GRAY)
    corners = cv2.goodFeaturesToTrack(gray, p.max_corners, p.quality_level, p.min_distance_px,
                                      blockSize=p.block_size)
    inner = cv2.erode(mask.astype(np.uint8), np.ones((11, 11), np.uint8)).astype(bool)
    points = np.zeros((0, 2)) if corners is None else corners.reshape(-1, 2)
    return int(sum(inner[int(round(y)), int(round(x))] for x, y in points))


def test_the_tracker_finds_corners_on_textures_and_none_on_the_plain_bar(renders):
    counts = {model: _corners_inside(*renders[model]) for model in renders}
    assert all(counts[m] >= 15 for m in TEXTURED), counts
    assert counts["metal_bar"] >= 2, counts  # its logo (the paint's wear is too faint)
    assert counts["plain_bar"] <= 1, counts


def _halves(color: np.ndarray, mask: np.ndarray) -> tuple[float, float, float]:
    """Mean grey of the tool and of its left and right halves (split in each image row)."""
    gray = cv2.cvtColor(color, cv2.COLOR_RGB2GRAY).astype(float)
    cols = np.arange(gray.shape[1])[None, :]
    centre = (mask * cols).sum(1, keepdims=True) / np.maximum(mask.sum(1, keepdims=True), 1)
    left, right = mask & (cols < centre - 1), mask & (cols > centre + 1)
    return gray[mask].mean(), gray[left].mean(), gray[right].mean()


def test_a_dim_side_light_darkens_the_image_and_lights_one_side():
    """The plain bar turned 45 deg about its axis shows two faces: the room's lights (the camera's
    light among them) light both, the side light from +y (the image's right) mostly the right."""
    room_color, room_mask = render(still_scenario("plain_bar", yaw=np.pi / 4))
    side_color, side_mask = render(still_scenario("plain_bar", SIDE_LIGHT, yaw=np.pi / 4))
    assert np.array_equal(room_mask, side_mask)
    assert side_color.mean() < 0.6 * room_color.mean()
    room, room_left, room_right = _halves(room_color, room_mask)
    side, side_left, side_right = _halves(side_color, side_mask)
    assert side < 0.7 * room
    assert 0.5 < room_right / room_left < 1.5
    assert side_right > 5 * side_left


def test_no_lights_given_is_the_rooms_lights(renders):
    """``lights: []`` (the default) renders as the room's two lights given explicitly."""
    color, _ = render(still_scenario("rod", ROOM_LIGHTS))
    assert np.array_equal(color, renders["rod"][0])


def test_lights_load_from_yaml():
    s = load_scenario_string("lights:\n  - {type: directional, frame: world, direction: [-0.5, -1.0, -0.5], "
                             "intensity: 0.6}\n  - {type: spot, position: [0, 1, 2], cone_angle: 30, "
                             "color: {rgba: [1.0, 0.9, 0.8, 1.0]}}\n")
    assert [light.type for light in s.lights] == ["directional", "spot"]
    assert s.lights[0].intensity == 0.6 and s.lights[0].frame == "world"
    np.testing.assert_array_equal(s.lights[1].position, [0, 1, 2])
    assert s.lights[1].color.g() == pytest.approx(0.9)
    assert Scenario().lights == []


@pytest.mark.parametrize("text, words", [
    ("lights: [{intensity: -0.5}]\n", "lights[0].intensity must be a number from 0"),
    ("lights: [{intensity: .nan}]\n", "lights[0].intensity"),
    ("lights: [{type: laser}]\n", "lights[0].type must be one of 'point', 'spot', 'directional'"),
    ("lights: [{}, {frame: head}]\n", "lights[1].frame must be one of 'world', 'camera'"),
    ("lights: [{direction: [0, 0, 0]}]\n", "lights[0].direction must not be zero"),
    ("lights: [{direction: [0, 1]}]\n", "lights[0].direction needs 3 numbers"),
    ("lights: [{type: spot, cone_angle: 0}]\n", "lights[0].cone_angle must be above 0"),
    ("lights: [{type: spot, cone_angle: 120}]\n", "lights[0].cone_angle must be a number from 0 to 90"),
    ("lights: [{type: point, attenuation_values: [0, 0, 0]}]\n", "lights[0].attenuation_values"),
    ("lights: [{position: [0, 0, 1e6]}]\n", "lights[0].position[2]"),
    ("lights: [{color: {rgba: [1, 1, 2, 1]}}]\n", "lights[0].color"),
    ("lights: [{intesity: 1}]\n", "lights[0].intesity"),
    ("lights: {type: point}\n", "lights must be a list"),
])
def test_bad_lights_are_one_line_errors(text, words):
    with pytest.raises(ScenarioError) as error:
        load_scenario_string(text)
    assert words in str(error.value) and "\n" not in str(error.value)


def test_a_sweep_crosses_tools_and_lights(tmp_path):
    """The scene matrix of issue 27 is a sweep's grid over ``tool.model`` and ``lights``."""
    from sustain_drake.sweeps.spec import load_sweep

    path = tmp_path / "scene.yaml"
    path.write_text(f"scenario: {ROOT / 'diagrams' / 'hand_eye.yaml'}\nscenario_name: hand_eye\n"
                    "grid:\n  tool.model: [rod, wood_handle, metal_bar, speckle_bar, plain_bar]\n"
                    "  lights: [[], [{type: directional, frame: world, direction: [-0.5, -1.0, -0.5], "
                    "intensity: 0.6}]]\n")
    sweep = load_sweep(path)
    assert len(sweep.cells) == 10 and len({c.id for c in sweep.cells}) == 10


def test_the_committed_tool_assets_are_the_generators(tmp_path):
    """models/generate_assets.py draws every texture from a fixed seed: rerun, it writes the
    committed meshes, textures (pixel for pixel) and SDF files again."""
    spec = importlib.util.spec_from_file_location("generate_assets", ROOT / "models" / "generate_assets.py")
    assets = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(assets)
    assets.HERE = tmp_path / "meshes"
    assets.main()
    for name in ("rod", "box", "backdrop", *WORKSHOP):
        for suffix in (".obj", ".mtl"):
            assert (assets.HERE / f"{name}{suffix}").read_text() == \
                (models_dir() / "meshes" / f"{name}{suffix}").read_text(), name + suffix
        new, committed = (cv2.imread(str(folder / f"{name}.png"))
                          for folder in (assets.HERE, models_dir() / "meshes"))
        assert np.array_equal(new, committed), name
    for name in WORKSHOP:
        assert (tmp_path / f"{name}_tool.sdf").read_text() == (models_dir() / f"{name}_tool.sdf").read_text()
