"""Finds the package's own models (offline) and makes Drake parsers that resolve them; the arms the
station can build (``ARMS``)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant

PACKAGE_NAME = "sustain_drake"
# The held tools (scenario key ``tool.model``, described in ToolConfig's comment): each one's SDF in
# models/. Every SDF has the body ``tool`` (its frame is the tool frame T, at the grasp point) and
# the frame ``tracked_point`` (the point the ground truth ``true_p_HP`` follows: the rod's and the
# bars' tip, the box's far corner). The bars are the rod's 50 mm square at the grip, so one gripper
# closing (``tool.gripper_position``) holds them all; models/generate_assets.py writes the bars. The
# ChArUco board (models/generate_charuco_board.py) is the marker-based baseline's target, on a handle
# of the same grip; its frame ``charuco`` is OpenCV's board frame (``perception.charuco``).
TOOL_FILES = {"rod": "rod_tool.sdf", "box": "box_tool.sdf", "wood_handle": "wood_handle_tool.sdf",
              "metal_bar": "metal_bar_tool.sdf", "speckle_bar": "speckle_bar_tool.sdf",
              "plain_bar": "plain_bar_tool.sdf", "charuco_board": "charuco_board_tool.sdf"}


@dataclass(frozen=True)
class ArmModel:
    """An arm the station can build (scenario key ``arm.model``): its model file and what the station
    wires to it. The model instance is named like its key in ``ARMS``; every arm carries the same
    gripper (arm.sdf's: the F/T weld ``ft_sensor``, the hand body, ``grasp``, ``gripper_joint``)."""

    file: str  # the model file in models/
    base_frame: str  # the frame welded onto the table's pedestal
    joints: tuple[str, ...]  # the babbling joints, base to hand (the encoders' order)
    hand_body: str  # the hand H: the body on the F/T sensor weld's child side
    # rad: the babbling's default [lower, upper] per joint (scenario key motion.joint_ranges)
    joint_ranges: tuple[tuple[float, float], ...]
    initial_posture: tuple[float, ...]  # rad: the default joint angles at the start


ARMS = {
    # 5 joints in the spirit of the paper's Katana (links of about 0.2 m); the paper's experiments.
    "arm": ArmModel(
        "arm.sdf", "arm_base", ("arm_joint1", "arm_joint2", "arm_joint3", "arm_joint4", "arm_joint5"),
        "gripper", ((-0.8, 0.8), (0.2, 1.0), (0.6, 1.6), (-0.4, 1.2), (-1.5, 1.5)),
        (0.0, 0.6, 1.1, 0.5, 0.0)),
    # 6 joints with UR5e-like kinematics (models/generate_ur_arm.py): the hand 0.5-0.7 m out over
    # the table, in front of the default head, the gripper pointing down (the held rod upright in
    # the camera's view).
    "ur_arm": ArmModel(
        "ur_arm.sdf", "ur_base", ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                                  "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"),
        "gripper", ((-0.3, 0.3), (0.1, 0.45), (1.3, 1.75), (1.05, 1.65), (-0.3, 0.3), (-1.2, 1.2)),
        (0.0, 0.3, 1.55, 1.25, 0.0, 0.0)),
}


def models_dir() -> Path:
    """The folder holding ``package.xml`` and the model files.

    Looked up next to the package first (``sustain_drake/models``, for a build that ships the
    models as package data), then in the source tree's ``models/`` (a checkout or an editable
    install)."""
    here = Path(__file__).resolve()
    for candidate in (here.parents[1] / "models", here.parents[2] / "models"):
        if (candidate / "package.xml").is_file():
            return candidate
    raise FileNotFoundError(
        f"cannot find the sustain_drake models (package.xml) near {here.parents[1]}")


def make_parser(plant: MultibodyPlant) -> Parser:
    """A parser whose package map knows ``package://sustain_drake/...`` (and nothing remote)."""
    parser = Parser(plant)
    parser.package_map().AddPackageXml(str(models_dir() / "package.xml"))
    return parser


def model_file(name: str) -> str:
    """The path of a model file of ours, e.g. ``model_file("arm.sdf")``."""
    path = models_dir() / name
    if not path.is_file():
        raise FileNotFoundError(f"no model file {path}")
    return str(path)
