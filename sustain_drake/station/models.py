"""Finds the package's own models (offline) and makes Drake parsers that resolve them."""

from __future__ import annotations

from pathlib import Path

from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant

PACKAGE_NAME = "sustain_drake"
# The held tools (scenario key ``tool.model``, described in ToolConfig's comment): each one's SDF in
# models/. Every SDF has the body ``tool`` (its frame is the tool frame T, at the grasp point) and
# the frame ``tracked_point`` (the point the ground truth ``true_p_HP`` follows: the rod's and the
# bars' tip, the box's far corner). The bars are the rod's 50 mm square at the grip, so one gripper
# closing (``tool.gripper_position``) holds them all; models/generate_assets.py writes the bars.
TOOL_FILES = {"rod": "rod_tool.sdf", "box": "box_tool.sdf", "wood_handle": "wood_handle_tool.sdf",
              "metal_bar": "metal_bar_tool.sdf", "speckle_bar": "speckle_bar_tool.sdf",
              "plain_bar": "plain_bar_tool.sdf"}


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
