"""The hand-eye scene matrix (issue 27): the committed sweep files are what bench/make_scene_matrix.py
writes, every axis value is in both splits, the two splits share no cell, and every cell loads."""

import collections
import sys
from pathlib import Path

import pytest

from sustain_drake.sweeps import load_sweep

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
import make_scene_matrix  # noqa: E402

AXES = {"placement": make_scene_matrix.PLACEMENTS, "camera": make_scene_matrix.CAMERAS,
        "tool": make_scene_matrix.TOOLS, "lights": make_scene_matrix.LIGHTS,
        "person": make_scene_matrix.PERSONS, "disturbances": make_scene_matrix.DISTURBANCES}


@pytest.mark.parametrize("split", ["tuning", "held_out"])
def test_the_committed_split_is_the_generators(split):
    """The split was drawn once from a fixed seed: the files must not drift from it (nor the
    generator from the files)."""
    cells = make_scene_matrix.design()[split]
    path = make_scene_matrix.SWEEPS / f"scene_matrix_{split}.yaml"
    assert path.read_text() == make_scene_matrix.sweep_text(split, cells)


def test_every_axis_value_is_in_both_splits_and_four_cells():
    splits = make_scene_matrix.design()
    assert sum(len(c) for c in splits.values()) >= 40
    for axis, values in AXES.items():
        for split, cells in splits.items():
            counts = collections.Counter(c[axis] for c in cells)
            assert set(counts) == set(values), (axis, split)
            assert min(counts.values()) >= 2, (axis, split, counts)
    seeds = [c["seed"] for cells in splits.values() for c in cells]
    assert len(set(seeds)) == len(seeds)


def test_the_sweep_files_load_and_the_splits_share_no_cell():
    tuning = load_sweep(make_scene_matrix.SWEEPS / "scene_matrix_tuning.yaml")
    held_out = load_sweep(make_scene_matrix.SWEEPS / "scene_matrix_held_out.yaml")
    assert len(tuning.cells) == len(held_out.cells) == make_scene_matrix.CELLS_PER_SPLIT
    assert not {c.id for c in tuning.cells} & {c.id for c in held_out.cells}
    assert all(c.duration == make_scene_matrix.DURATION for c in tuning.cells + held_out.cells)


def test_the_heads_aim_at_the_workspace():
    """Each placement's optical axis (post yaw, tilt) passes within 1 cm of TARGET (the front is
    the scenario's own head)."""
    import numpy as np

    for name, p in make_scene_matrix.PLACEMENTS.items():
        if name == "front":
            continue
        eye = p["foot"] + [0.0, 0.0, make_scene_matrix.EYE_HEIGHT]
        axis = np.array([np.cos(p["tilt"]) * np.cos(p["yaw"]), np.cos(p["tilt"]) * np.sin(p["yaw"]),
                         -np.sin(p["tilt"])])
        d = make_scene_matrix.TARGET - eye
        assert np.linalg.norm(d - (d @ axis) * axis) < 0.01, name


@pytest.mark.parametrize("split", ["tuning", "held_out"])
def test_the_second_arms_cells_are_the_generators_and_load(split):
    cells = make_scene_matrix.second_arm_design()[split]
    path = make_scene_matrix.SWEEPS / f"scene_matrix_second_arm_{split}.yaml"
    assert path.read_text() == make_scene_matrix.second_arm_sweep_text(split, cells)
    sweep = load_sweep(path)
    assert len(sweep.cells) == make_scene_matrix.SECOND_ARM_CELLS_PER_SPLIT
    assert "model: ur_arm" in sweep.cells[0].scenario_text
