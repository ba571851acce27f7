"""Sweeps: a sweep file expands into validated cells; cells run on Dask into one table that a
re-run resumes without running a cell twice; a failed cell is a row, not the end of the sweep."""

from __future__ import annotations

from pathlib import Path

import dask
import pandas as pd
import pytest
from distributed import Client

from sustain_drake.cli.main import main
from sustain_drake.experiments import run as run_module
from sustain_drake.experiments.targets import TARGETS, check_targets
from sustain_drake.station import load_scenario
from sustain_drake.station.scenario_files import load_scenario_string, with_seed
from sustain_drake.sweeps import SweepError, SweepRunError, load_sweep, read_table, run_sweep, write_summary
from sustain_drake.sweeps.engine import flatten

ROOT = Path(__file__).resolve().parents[1]
KINESTHETIC = ROOT / "diagrams" / "inertia_touch.yaml"
SWEEPS = ROOT / "diagrams" / "sweeps"


def in_process_client() -> Client:
    """One worker thread in this process: cells can be patched, and no process start-up."""
    return Client(processes=False, n_workers=1, threads_per_worker=1, dashboard_address="127.0.0.1:0")


def sweep_file(tmp_path, body: str, name: str = "s.yaml") -> Path:
    path = tmp_path / name
    path.write_text(f"scenario: {KINESTHETIC}\n" + body)
    return path


def test_grid_times_zip_makes_every_cell_with_its_overrides(tmp_path):
    sweep = load_sweep(sweep_file(tmp_path, """
duration: 2
grid:
  seed: [~, 5]
  motion.max_speed: [0.3, 0.5, 0.7]
zip:
  wrench_sensor.force_noise: [0.05, 0.2]
  head.X_WP: [{translation: [1.5, 0, 0]}, {translation: [1.6, 0.1, 0]}]
"""))
    assert len(sweep.cells) == 2 * 3 * 2
    assert sweep.axes == ("seed", "motion.max_speed", "wrench_sensor.force_noise", "head.X_WP")
    base = load_scenario(KINESTHETIC)
    for cell in sweep.cells:
        values = dict(cell.overrides)
        s = load_scenario_string(cell.scenario_text)
        assert cell.duration == 2.0
        assert s.motion.max_speed == float(values["motion.max_speed"])
        assert s.wrench_sensor.force_noise == float(values["wrench_sensor.force_noise"])
        # a mapping sets only the keys it names: X_WP's rotation is the base's
        x = 1.5 if values["wrench_sensor.force_noise"] == "0.05" else 1.6
        assert list(s.head.X_WP.translation) == pytest.approx([x, 0.1 * (x == 1.6), 0.0])
        assert repr(s.head.X_WP.rotation) == repr(base.head.X_WP.rotation)
        if values["seed"] == "5":
            assert s.motion.seed == 5 and s.depth_noise.seed == with_seed(base, 5).depth_noise.seed
        else:
            assert s.motion.seed == base.motion.seed
        assert s.touch_motion == base.touch_motion  # untouched sections are the base's
    assert len({c.id for c in sweep.cells}) == len(sweep.cells)


def test_a_tagged_list_replaces_the_whole_list(tmp_path):
    sweep = load_sweep(sweep_file(tmp_path, """
grid:
  disturbances: [[], [!HeadMove {time: 1.0, pan: 0.05}, !HeadMove {time: 2.0, tilt: 0.2}]]
"""))
    empty, two = (load_scenario_string(c.scenario_text) for c in sweep.cells)
    assert empty.disturbances == []
    assert [(type(d).__name__, d.time) for d in two.disturbances] == [("HeadMove", 1.0), ("HeadMove", 2.0)]
    assert dict(sweep.cells[1].overrides)["disturbances"].startswith("[!HeadMove {")


@pytest.mark.parametrize("body, words", [
    ("grid:\n  motion.sed: [1]\n", "motion has no key 'sed'"),
    ("grid:\n  camera.width.x: [1]\n", "camera.width has no keys below it"),
    ("grid:\n  camera: [{}]\n  camera.width: [1]\n", "overlap"),
    ("zip:\n  motion.seed: [1, 2]\n  motion.max_speed: [0.3]\n", "one length"),
    ("grid:\n  motion.seed: []\n", "non-empty list"),
    ("grid:\n  motion.seed: 3\n", "non-empty list"),
    ("gird:\n  motion.seed: [1]\n", "unknown key(s) gird"),
    ("grid:\n  disturbances: [[!HeadMov {time: 1}]]\n", "unknown tag !HeadMov"),
    ("grid:\n  motion.max_speed: [-1]\n", "cell 0 (motion.max_speed=-1)"),
    ("grid:\n  seed: [-3]\n", "seed must be an integer >= 0"),
    ("grid:\n  motion.seed: [1, 1]\n", "cells 0 and 1 run the same scenario"),
    ("duration: -2\n", "duration must be a positive number"),
    ("grid:\n  motion.seed: [1]\nzip:\n  motion.seed: [2]\n", "both in grid and in zip"),
])
def test_bad_sweep_files_are_one_line_errors_before_anything_runs(tmp_path, body, words):
    with pytest.raises(SweepError) as e:
        load_sweep(sweep_file(tmp_path, body))
    assert words in str(e.value) and "\n" not in str(e.value)


def test_a_missing_base_scenario_is_named(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("scenario: nowhere.yaml\n")
    with pytest.raises(SweepError, match="the base scenario: .*nowhere.yaml"):
        load_sweep(path)


def test_targets_read_lists_and_missing_figures():
    hand_eye = {t.name: t for t in TARGETS["hand_eye"]}
    section = {"adopted": [{"camera_position_error_mm": 0.5}, {"camera_position_error_mm": 2.5}],
               "disturbances": [{"detection_latency_s": 0.2}, {"detection_latency_s": None}],
               "num_false_alarms": 0, "first_convergence_after_found_s": None}
    position = hand_eye["camera_position_mm"]
    assert not position.met(section) and position.worst(section) == 2.5
    assert not hand_eye["detection_latency_s"].met(section)  # a change never detected
    assert hand_eye["detection_latency_s"].worst(section) is None
    assert not hand_eye["first_convergence_after_found_s"].met(section)  # never converged
    assert hand_eye["false_alarms"].met(section)
    assert not position.met({"adopted": []})  # nothing adopted is not a pass
    verdicts = check_targets({"hand_eye": section, "scenario": "x"})
    assert set(verdicts) == {f"hand_eye.{t.name}" for t in TARGETS["hand_eye"]}


def test_flatten_keeps_every_figure():
    assert flatten({"a": {"b": 1, "c": [1, 2]}, "d": None}) == {"a.b": 1, "a.c": "[1, 2]", "d": None}


def test_cells_run_into_one_table_resume_and_a_failed_cell_is_a_row(tmp_path, monkeypatch):
    # Three short cells of the kinesthetic scenario on an in-process worker; the third fails
    # inside the run.
    sweep = load_sweep(sweep_file(tmp_path, "duration: 0.3\ngrid:\n  seed: [1, 2, 3]\n"))
    simulate = run_module.simulate_scenario

    def fail_on_seed_3(scenario, *args, **kwargs):
        if scenario.motion.seed == 3:
            raise RuntimeError("the world could not be built (nonsense)")
        return simulate(scenario, *args, **kwargs)
    monkeypatch.setattr(run_module, "simulate_scenario", fail_on_seed_3)
    out = tmp_path / "out"
    seen = []

    def stop_after_first(row):
        seen.append(row["cell_id"])
        raise KeyboardInterrupt  # as a user's Ctrl-C after the first cell

    with in_process_client() as client:
        with pytest.raises(KeyboardInterrupt):
            run_sweep(sweep, out, client, progress=False, on_row=stop_after_first)
        first = read_table(out)
        assert list(first["cell_id"]) == seen  # the finished cell is kept
        ran = []
        table = run_sweep(sweep, out, client, progress=False, on_row=lambda r: ran.append(r["cell_id"]))
        assert seen[0] not in ran and sorted(ran + seen) == sorted(c.id for c in sweep.cells)
        again = []
        run_sweep(sweep, out, client, progress=False, on_row=lambda r: again.append(r))
        assert again == []  # nothing is run twice
    assert len(table) == 3 and list(table["cell"]) == [0, 1, 2]
    failed = table[table["error"].notna()]
    assert list(failed["cell"]) == [2] and "nonsense" in failed["error"].iloc[0]
    ok = table[table["error"].isna()]
    assert (ok["metric.duration_s"] == 0.3).all()
    assert ok["target.kinesthetic.false_touch_samples.met"].all()
    assert (out / "cells" / failed["cell_id"].iloc[0] / "error.txt").exists()
    assert all((out / "cells" / i / "metrics.json").exists() for i in ok["cell_id"])
    assert pd.read_parquet(out / "results.parquet").shape == table.shape
    summary = write_summary(table, sweep, out).read_text()
    assert "3 of 3 cells in the table, 1 failed" in summary and "## seed" in summary
    assert (out / "summary_seed.png").stat().st_size > 1000


def test_the_command_runs_a_sweep_on_a_local_cluster(tmp_path, capsys):
    path = sweep_file(tmp_path, "duration: 0.2\ngrid:\n  seed: [1, 2]\n")
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--out", str(out), "--workers", "2"]) == 0
    assert "2 of 2 cells" in capsys.readouterr().out
    table = read_table(out)
    assert set(table["axis.seed"]) == {"1", "2"} and table["error"].isna().all()
    assert len(set(table["host"])) == 1 and (out / "summary.md").exists()


@pytest.mark.parametrize("args, words", [
    (["--workers", "0"], "--workers must be >= 1"),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "leave it out"),
    (["--scheduler", "tcp://127.0.0.1:1"], "no Dask scheduler at tcp://127.0.0.1:1"),
])
def test_bad_arguments_are_one_line_errors(tmp_path, capsys, args, words):
    path = sweep_file(tmp_path, "duration: 0.2\n")
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        assert main(["sweep", str(path), "--out", str(tmp_path / "o"), *args]) == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1


def test_an_output_under_a_file_is_refused_before_running(tmp_path, capsys):
    path = sweep_file(tmp_path, "duration: 0.2\n")
    (tmp_path / "file").write_text("x")
    with in_process_client() as client:
        with pytest.raises(SweepRunError, match="cannot create it, .*file is a file"):
            run_sweep(load_sweep(path), tmp_path / "file", client, progress=False)


@pytest.mark.parametrize("name", sorted(p.name for p in SWEEPS.glob("*.yaml")))
def test_shipped_sweep_files_load(name):
    sweep = load_sweep(SWEEPS / name)
    assert len(sweep.cells) >= 2


def test_a_closed_output_pipe_ends_the_command_quietly(capfd, monkeypatch):
    """``sustain-drake sweep FILE --list | head -1``: the reader closes the pipe, and the command
    stops with the shell's SIGPIPE status and no traceback."""
    from sustain_drake.cli import sweep as sweep_cli

    def closed(*args, **kwargs):
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(sweep_cli, "print", closed, raising=False)
    sweep_file = Path(__file__).resolve().parents[1] / "diagrams" / "sweeps" / "kinesthetic_seeds.yaml"
    assert main(["sweep", str(sweep_file), "--list"]) == 141
    assert capfd.readouterr().err == ""
