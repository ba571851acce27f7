"""Several points in one points file (``sample,point,x,y,z``): reading, refusals, and
``sustain-drake calibrate eye-to-hand`` end to end with them (issue 26 item 5)."""

from __future__ import annotations

import io
import tempfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from eye_to_hand_data import make_points, make_truth
from hypothesis import HealthCheck, event, given, settings
from pydrake.common.schema import Transform
from pydrake.common.yaml import yaml_load_typed
from test_cli_calibrate import (
    DATA,
    FUZZ_LONG,
    POSE_LINES,
    _write,
    calibrate,
    calibrate_in_process,
    file_bytes,
    one_line_error,
    run_in_process,
    snapshot,
)

from sustain_drake.cli.calibrate import run_eye_to_hand
from sustain_drake.identification import calibrate_eye_to_hand_points, eye_to_hand
from sustain_drake.recorded_data import (
    RecordedDataError,
    read_point_tracks_csv,
    read_points_csv,
    read_poses_csv,
    write_point_tracks_csv,
    write_points_csv,
    write_poses_csv,
)

P_HP = np.array([[0.05, 0.02, 0.12], [-0.08, 0.04, 0.10], [0.0, -0.09, 0.15]])
HEADER = "sample,point,x,y,z"


class _Loader(yaml.SafeLoader):
    """Reads the result YAML with its Drake ``!Rpy`` tag as a plain mapping."""


_Loader.add_constructor("!Rpy", lambda loader, node: loader.construct_mapping(node))


@pytest.fixture
def files(tmp_path):
    """Three points over 30 poses, each missing from a fifth of them, 1 mm noise; labels as text."""
    data, X_WH = make_points(make_truth(5), P_HP, 30, noise_m=1e-3, missing=0.2, seed=3)
    data = {label: value for label, value in zip(("tip", "10", "mark b"), data.values(), strict=True)}
    points = _write(tmp_path / "points.csv", write_point_tracks_csv(data))
    return points, _write(tmp_path / "poses.csv", write_poses_csv(X_WH)), data, X_WH


def test_the_file_is_read_as_written(files):
    points, poses, data, X_WH = files
    tracks = read_point_tracks_csv(points, num_samples=30)
    assert tracks.labelled and set(tracks.points) == {"tip", "10", "mark b"}
    first = [line.split(",")[1] for line in points.read_text().splitlines()[1:]]
    assert list(tracks.points) == sorted(set(first), key=first.index)  # in the order of first rows
    for label, (samples, p_C) in data.items():
        assert np.array_equal(tracks.points[label][0], samples)
        assert np.array_equal(tracks.points[label][1], p_C)  # repr of floats: exact
    lines = points.read_text().splitlines()
    assert lines[0] == HEADER and [int(line.split(",")[0]) for line in lines[1:]] == sorted(
        int(line.split(",")[0]) for line in lines[1:])  # ordered by sample
    # The one-point format is one point, row i = sample i.
    old = read_point_tracks_csv(DATA / "corner_points.csv")
    assert not old.labelled and list(old.points) == ["P"]
    assert np.array_equal(old.points["P"][0], np.arange(50))
    assert np.array_equal(old.points["P"][1], read_points_csv(DATA / "corner_points.csv"))


def _edit(points: Path, line: int, text: str | None) -> Path:
    """The points file with its line ``line`` (1-based, the header is 1) replaced by ``text`` (or
    ``text`` appended when ``line`` is 0)."""
    lines = points.read_text().splitlines()
    if line == 0:
        lines.append(text)
    else:
        lines[line - 1] = text
    return _write(points.parent / "edited.csv", "\n".join(lines) + "\n")


def _first_row_of(points: Path, label: str) -> tuple[int, list[str]]:
    for number, line in enumerate(points.read_text().splitlines(), start=1):
        if line.split(",")[1:2] == [label]:
            return number, line.split(",")
    raise AssertionError(label)


def _typo(points):
    number, cells = _first_row_of(points, "tip")
    cells[1] = "tpi"  # an unknown point, in one sample only
    return _edit(points, number, ",".join(cells)), f"edited.csv:{number}: point 'tpi' is in 1 sample only"


def _out_of_range(points):
    number, cells = _first_row_of(points, "10")
    cells[0] = "30"  # the poses have rows 0 to 29
    return (_edit(points, number, ",".join(cells)),
            f"edited.csv:{number}: sample 30 is out of range: the poses have 30 rows (0 to 29)")  # fmt: skip


def _duplicate(points):
    number, cells = _first_row_of(points, "mark b")
    last = len(points.read_text().splitlines()) + 1
    return (_edit(points, 0, ",".join(cells)),
            f"edited.csv:{last}: sample {cells[0]} of point 'mark b' again (first at line "
            f"{number})")  # fmt: skip


def _not_an_index(points, cell):
    number, cells = _first_row_of(points, "tip")
    cells[0] = cell
    return _edit(points, number, ",".join(cells)), f"edited.csv:{number}: sample '{cell}' is not a 0-based"


def _empty_label(points):
    number, cells = _first_row_of(points, "tip")
    cells[1] = ""
    return _edit(points, number, ",".join(cells)), f"edited.csv:{number}: the point label is empty"


def _too_many_points(points):
    rows = [f"{i % 30},p{i // 4},0.1,0.2,0.9" for i in range(4 * 101)]  # 101 points of 4 samples
    return (_write(points.parent / "edited.csv", "\n".join([HEADER, *rows]) + "\n"),
            "edited.csv:402: point 'p100' is one point too many (at most 100)")  # fmt: skip


def _millimetres(points):
    number, cells = _first_row_of(points, "10")
    cells[4] = "1837.8"
    return _edit(points, number, ",".join(cells)), f"edited.csv:{number}: z = 1837.8 m is over 1000 m"


def _nan(points):
    number, cells = _first_row_of(points, "10")
    cells[2] = "nan"
    return _edit(points, number, ",".join(cells)), f"edited.csv:{number}: NaN or inf"


def _columns(points):
    number, cells = _first_row_of(points, "10")
    return _edit(points, number, ",".join(cells[:4])), f"edited.csv:{number}: 4 columns, expected 5"


def _utf16(points):
    path = points.parent / "edited.csv"
    path.write_bytes(points.read_text().encode("utf-16"))
    return path, "binary or UTF-16"


def _few_poses(points):
    rows = [f"{i},{label},0.1,{0.01 * i},0.9" for label, n in (("tip", 4), ("tail", 5)) for i in range(n)]
    return (_write(points.parent / "edited.csv", "\n".join([HEADER, *rows]) + "\n"),
            "too few samples: 5 poses with a point, at least 10 needed")  # fmt: skip


BAD_FILES = {
    "a sample out of range": _out_of_range,
    "a (sample, point) twice": _duplicate,
    "a negative sample": lambda p: _not_an_index(p, "-1"),
    "a fractional sample": lambda p: _not_an_index(p, "3.0"),
    "a sample in words": lambda p: _not_an_index(p, "three"),
    "an empty label": _empty_label,
    "101 points": _too_many_points,
    "millimetres": _millimetres,
    "NaN": _nan,
    "a row of 4 columns": _columns,
    "UTF-16": _utf16,
    "too few poses with a point": _few_poses,
}


@pytest.mark.parametrize("make", BAD_FILES.values(), ids=list(BAD_FILES))
def test_bad_points_files_are_one_line_and_change_nothing(files, make):
    points, poses, _, _ = files
    bad, expected = make(points)
    out = _write(points.parent / "result.yaml", "previous result\n")
    before = snapshot(points.parent)
    line = one_line_error(calibrate_in_process(bad, poses, "--out", out, "--camera-config",
                                               points.parent / "camera.yaml"))  # fmt: skip
    assert expected in line, line
    assert snapshot(points.parent) == before


def test_the_reader_alone_refuses_them_too(files):
    points, _, _, _ = files
    bad, expected = _out_of_range(points)
    read_point_tracks_csv(bad)  # without the poses' row count the index is not checked
    with pytest.raises(RecordedDataError, match="out of range"):
        read_point_tracks_csv(bad, num_samples=30)
    tracks = read_point_tracks_csv(_typo(points)[0])
    assert list(tracks.left_out) == ["tpi"] and tracks.left_out["tpi"][1] == 1 and "tpi" not in tracks.points
    few = _write(points.parent / "few.csv", f"{HEADER}\n0,a,0.1,0.0,0.9\n1,a,0.1,0.01,0.9\n0,b,0.1,0.0,0.8\n")
    with pytest.raises(RecordedDataError, match="no point is in 4 samples or more"):
        read_point_tracks_csv(few)


def test_a_point_in_fewer_than_four_samples_is_left_out_and_named(files):
    # A board corner seen in a few images, or a typo in a label: named on stderr, the others fitted.
    points, poses, _, _ = files
    bad, _ = _typo(points)
    r = calibrate(bad, poses)
    assert r.returncode == 0, r.stderr
    assert "left out" in r.stderr and "point 'tpi' in 1 sample only" in r.stderr
    assert "of 3 points fixed on the hand" in r.stdout


def test_end_to_end(files):
    points, poses, data, X_WH = files
    out, camera = points.parent / "result.yaml", points.parent / "camera.yaml"
    r = calibrate(points, poses, "--out", out, "--camera-config", camera)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    expected = calibrate_eye_to_hand_points(read_point_tracks_csv(points).points, X_WH)
    assert expected.converged
    assert "of 3 points fixed on the hand over 30 samples" in r.stdout and "verdict: converged" in r.stdout
    for k, label in enumerate(expected.labels):
        row = next(line for line in r.stdout.splitlines() if line.startswith(f"  {label} "))
        assert f"{expected.rms[k] * 1e3:.3f}" in row
        assert "  ".join(f"{v:+.6f}" for v in expected.p_HP[k]) in row
        assert f"per-sample residuals [mm] of point '{label}'" in r.stdout
    # The YAML: a Drake Transform, and every point's figures as computed.
    X = yaml_load_typed(schema=Transform, filename=str(out), child_name="X_WC",
                        retain_map_defaults=True).GetDeterministicValue()  # fmt: skip
    np.testing.assert_allclose(X.GetAsMatrix4(), expected.X_WC, atol=1e-12)
    result = yaml.load(out.read_text(), Loader=_Loader)  # a SafeLoader that reads !Rpy
    assert result["converged"] is True and result["num_samples"] == 30
    assert result["start_point"] == expected.labels[expected.seed]
    close = {"rtol": 1e-9, "atol": 1e-15}  # another process: the last digits of a solve may differ
    np.testing.assert_allclose(result["camera_position_sd_m"], expected.standard_errors[1], **close)
    assert [p["label"] for p in result["points"]] == list(expected.labels)
    assert set(expected.labels) == {"tip", "10", "mark b"}  # "10" stays text
    for k, point in enumerate(result["points"]):
        np.testing.assert_allclose(point["p_HP"], expected.p_HP[k], **close)
        np.testing.assert_allclose([point["rms_m"], point["weight"], point["alone"]["camera_offset_m"]],
                                   [expected.rms[k], expected.weights[k], expected.single_offsets()[k, 0]],
                                   **close)  # fmt: skip
        np.testing.assert_allclose(point["residuals_m"], expected.residuals[k], **close)
        assert point["samples"] == expected.samples[k].tolist() == data[point["label"]][0].tolist()
        assert point["outliers"] == [] and point["alone"]["verdict"] == "converged"
    assert "X_PB:" in camera.read_text()


def test_not_converged_exits_3_names_each_point_and_keeps_the_old_result(files):
    points, poses, data, X_WH = files
    X_WH = X_WH.copy()
    X_WH[:, :3, :3] = X_WH[0, :3, :3]  # the points as recorded, under poses that do not turn
    still = _write(points.parent / "still.csv", write_poses_csv(X_WH))
    out = _write(points.parent / "result.yaml", "previous result\n")
    r = calibrate(points, still, "--out", out)
    line = one_line_error(r, code=3)
    assert line.startswith("sustain-drake: not converged: motion not rich enough: the hand did not rotate")
    assert "point 'tip' alone: not converged" in r.stdout and "X_WC" not in r.stdout
    assert out.read_text() == "previous result\n"


def test_an_output_on_an_input_is_refused(files):
    points, poses, _, _ = files
    before = snapshot(points.parent)
    assert "is also the --points file" in one_line_error(calibrate_in_process(points, poses, "--out", points))
    assert snapshot(points.parent) == before


def test_one_labelled_point_is_the_one_point_calibration(files):
    points, poses, data, X_WH = files
    one = _write(points.parent / "one.csv", write_point_tracks_csv({"tip": data["tip"]}))
    stream = io.StringIO()
    assert run_eye_to_hand(one, poses, None, eye_to_hand.default_criteria(), stream) == 0
    samples, p_C = data["tip"]
    from sustain_drake.identification import calibrate_eye_to_hand

    alone = calibrate_eye_to_hand(p_C, X_WH[samples])
    assert "  ".join(f"{v:+.6f}" for v in alone.X_WC[:3, 3]) in stream.getvalue()


def test_the_real_data_set_file_is_the_three_point_files():
    """``all_points.csv`` (``convert.py``) holds the corner and the two codes, each at every pose."""
    poses = read_poses_csv(DATA / "poses.csv")
    tracks = read_point_tracks_csv(DATA / "all_points.csv", num_samples=len(poses))
    assert tracks.labelled and list(tracks.points) == ["corner", "aruco10", "aruco14"]
    for label, (samples, p_C) in tracks.points.items():
        assert np.array_equal(samples, np.arange(50))
        assert np.array_equal(p_C, read_points_csv(DATA / f"{label}_points.csv"))


MULTI_LINES = (DATA / "all_points.csv").read_text().splitlines()


@settings(max_examples=1500 if FUZZ_LONG else 120, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])  # fmt: skip
@given(points=file_bytes(MULTI_LINES), poses=file_bytes(POSE_LINES))
def test_fuzz_labelled_points_and_poses_files(points, poses):
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        (folder / "p.csv").write_bytes(points)
        (folder / "q.csv").write_bytes(poses)
        _write(folder / "result.yaml", "previous result\n")
        before = snapshot(folder)
        code, err = run_in_process(["calibrate", "eye-to-hand", "--points", str(folder / "p.csv"),
                                    "--poses", str(folder / "q.csv"), "--out", str(folder / "result.yaml")])
        event(f"exit {code}")
        assert code in (0, 2, 3), err
        # Warnings (points left out) may precede the result; at most one error line follows them.
        errors = [line for line in err.splitlines() if not line.startswith("sustain-drake: warning:")]
        assert len(errors) == (0 if code == 0 else 1), err
        after = snapshot(folder)
        changed = {p.name for p in before.keys() | after.keys() if before.get(p) != after.get(p)}
        assert changed == ({"result.yaml"} if code == 0 else set()), (code, changed)


def _flagged(text: str) -> list[tuple[str, int]]:
    """(the residual block's title, sample number) of every line flagged large."""
    found, block = [], ""
    for line in text.splitlines():
        if line.startswith("per-sample residuals"):
            block = line
        elif "<-- large" in line:
            found.append((block, int(line.split()[0])))
    return found


def test_a_mispaired_sample_is_flagged_in_the_printout(files):
    points, poses, data, X_WH = files
    number, cells = _first_row_of(points, "10")
    cells[2] = repr(float(cells[2]) + 0.02)  # 2 cm off: another moment's position
    stream = io.StringIO()
    criteria = eye_to_hand.default_criteria()
    assert run_eye_to_hand(_edit(points, number, ",".join(cells)), poses, None, criteria, stream) == 0
    assert _flagged(stream.getvalue()) == [
        ("per-sample residuals [mm] of point '10' (sample: the poses' row, from 0):", int(cells[0]))]
    # One point (x,y,z): the real data set's corner with its sixth position 1 cm off, numbered from 1.
    corner = read_points_csv(DATA / "corner_points.csv")
    corner[5] += [0.01, 0.0, 0.0]
    stream = io.StringIO()
    moved = _write(points.parent / "moved.csv", write_points_csv(corner))
    assert run_eye_to_hand(moved, DATA / "poses.csv", None, criteria, stream) == 0
    assert _flagged(stream.getvalue()) == [("per-sample residuals [mm]:", 6)]
