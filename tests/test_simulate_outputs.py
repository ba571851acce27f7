"""``sustain-drake simulate`` and ``graph`` outputs (issue #23): ``--out`` is checked before the run
(exit 2, one line, nothing written), a refused run leaves an earlier run's files as they were, and a
new run leaves no stale output of an earlier one beside its own."""

from __future__ import annotations

import errno
from pathlib import Path

import pytest

from sustain_drake import files
from sustain_drake.cli.main import main

# A quick world: no camera, no person; 0.1 s.
QUICK = "duration: 0.1\ncamera: {rgb: false, depth: false, label: false}\ndistractor: {enabled: false}\n"


@pytest.fixture
def quick(tmp_path) -> Path:
    path = tmp_path / "quick.yaml"
    path.write_text(QUICK)
    return path


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else b"<dir>"
            for p in sorted(folder.rglob("*"))}


def refused(args, capsys, words: str) -> str:
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err and "Traceback" not in err, err
    return err


def earlier_run(folder: Path) -> dict[str, bytes]:
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in (("replay.html", "<html>earlier</html>"), ("log.npz", "earlier log"),
                       ("metrics.json", "{}"), ("notes.txt", "the user's own file")):
        (folder / name).write_text(text)
    return snapshot(folder)


def test_out_under_a_file_is_refused_before_the_run(tmp_path, quick, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("keep me")
    before = snapshot(tmp_path)
    refused(["simulate", str(quick), "--out", str(blocker / "run")], capsys, "a_file is a file")
    refused(["simulate", str(quick), "--out", str(blocker)], capsys, "is a file, not a folder")
    assert snapshot(tmp_path) == before


def test_an_unwritable_out_is_refused_before_the_run(tmp_path, quick, capsys, monkeypatch):
    def no_write(*args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(files.tempfile, "mkstemp", no_write)
    out = tmp_path / "new" / "run"
    refused(["simulate", str(quick), "--out", str(out)], capsys, "cannot write there (Permission denied)")
    assert not (tmp_path / "new").exists()  # the folders it made for the check are gone again


def test_a_refused_run_leaves_the_earlier_runs_files(tmp_path, capsys):
    out = tmp_path / "run"
    before = earlier_run(out)
    bad = tmp_path / "bad.yaml"
    bad.write_text(QUICK + "wrench_sensor: {rate: 1e9}\n")
    refused(["simulate", str(bad), "--out", str(out)], capsys, "wrench_sensor.rate")
    assert snapshot(out) == before
    # A world that cannot be built: refused after the folder check, before anything is written.
    bad.write_text(QUICK.replace("label: false}", "label: false, X_PB: {base_frame: 'head::camera_mnt'}}"))
    refused(["simulate", str(bad), "--out", str(out)], capsys, "camera_mnt")
    assert snapshot(out) == before
    refused(["simulate", str(bad), "--out", str(tmp_path / "fresh")], capsys, "camera_mnt")
    assert not (tmp_path / "fresh").exists()


def test_an_output_name_taken_by_a_folder_is_refused_before_the_run(tmp_path, quick, capsys):
    out = tmp_path / "run"
    (out / "log.npz").mkdir(parents=True)
    refused(["simulate", str(quick), "--out", str(out)], capsys, "log.npz is a folder")


def test_a_new_run_removes_the_earlier_runs_outputs_it_does_not_write(tmp_path, quick, capsys):
    out = tmp_path / "run"
    earlier_run(out)
    assert main(["simulate", str(quick), "--out", str(out), "--no-replay"]) == 0
    printed = capsys.readouterr().out
    assert "removed an earlier run's metrics.json, replay.html" in printed
    assert not (out / "replay.html").exists() and not (out / "metrics.json").exists()
    assert (out / "log.npz").read_bytes()[:2] == b"PK"  # the new log (an npz is a zip)
    assert (out / "notes.txt").read_text() == "the user's own file"  # not an output: kept


def test_graph_refuses_a_folder_for_its_dot_file(tmp_path, quick, capsys):
    (tmp_path / "g.dot").mkdir()
    blocker = tmp_path / "a_file"
    blocker.write_text("keep me")
    before = snapshot(tmp_path)
    refused(["graph", str(quick), "--out", str(tmp_path / "g.dot")], capsys, "is a folder")
    refused(["graph", str(quick), "--out", str(blocker / "g.dot")], capsys, "a_file is not a folder")
    (tmp_path / "h.svg").mkdir()
    refused(["graph", str(quick), "--out", str(tmp_path / "h.dot")], capsys, "h.svg is a folder")
    assert snapshot(tmp_path) == {**before, "h.svg": b"<dir>"}


def test_graph_without_graphviz_leaves_no_older_svg(tmp_path, quick, capsys, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path / "empty_bin"))
    out = tmp_path / "g.dot"
    out.with_suffix(".svg").write_text("<svg>an older graph</svg>")
    assert main(["graph", str(quick), "--out", str(out)]) == 0
    assert out.read_text().startswith("digraph") and not out.with_suffix(".svg").exists()
