"""The README is a front door: short, and every command in it runs as written (with a short
duration and a temporary output folder)."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import pytest

from sustain_drake.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
REAL_DATA = ROOT / "tests" / "data" / "jin_eyetobase_rvc_single"


def readme_commands() -> list[list[str]]:
    """The command lines of the README's bash blocks, comments dropped."""
    text = README.read_text(encoding="utf-8")
    lines = [line.split("#")[0].strip() for block in re.findall(r"```bash\n(.*?)```", text, re.DOTALL)
             for line in block.splitlines()]
    return [shlex.split(line) for line in lines if line]


def test_the_readme_is_a_front_door():
    assert len(README.read_text(encoding="utf-8").splitlines()) <= 250


def test_every_document_the_readme_links_exists():
    links = re.findall(r"\]\(((?:docs|tests|bench)/[^)#]+)", README.read_text(encoding="utf-8"))
    assert len(links) >= 8
    assert [link for link in links if not (ROOT / link).exists()] == []


def test_the_readme_commands_are_known():
    """Every command is `make demo`, `make test` (CI runs it) or a `sustain-drake` call run below."""
    commands = readme_commands()
    assert ["make", "demo"] in commands and ["make", "test"] in commands
    others = [c for c in commands if c[0] != "make"]
    assert others and all(c[0] == ".venv/bin/sustain-drake" for c in others)


SIMULATE = [c[1:] for c in readme_commands() if c[1:2] == ["simulate"]]


@pytest.mark.parametrize("args", SIMULATE, ids=lambda a: Path(a[1]).stem)
def test_each_simulate_command_of_the_readme_runs(args, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(ROOT)
    out = tmp_path / "out"
    args = [a if a != args[args.index("--out") + 1] else str(out) for a in args]
    assert main(args + ["--duration", "0.3", "--no-replay"]) == 0
    assert (out / "log.npz").is_file()
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["duration_s"] == 0.3


def test_the_readme_calibration_command_runs_on_the_real_data(tmp_path, monkeypatch, capsys):
    (command,) = [c[1:] for c in readme_commands() if c[1:2] == ["calibrate"]]
    files = {"points.csv": REAL_DATA / "corner_points.csv", "poses.csv": REAL_DATA / "poses.csv",
             "result.yaml": tmp_path / "result.yaml"}
    assert main([str(files.get(a, a)) for a in command]) == 0
    assert "X_WC" in (tmp_path / "result.yaml").read_text()


def test_the_readme_sweep_command_lists_its_cells(monkeypatch, capsys):
    """The sweep runs for minutes (tests/test_sweep.py runs short ones); here its file is read and
    every cell built and checked."""
    (command,) = [c[1:] for c in readme_commands() if c[1:2] == ["sweep"]]
    monkeypatch.chdir(ROOT)
    assert main(command + ["--list"]) == 0
    assert len(capsys.readouterr().out.strip().splitlines()) >= 64
