"""``sustain-drake calibrate eye-to-hand``: output, YAML for Drake, and one-line errors."""

import contextlib
import errno
import io
import os
import shutil
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from eye_to_hand_data import make_samples, make_truth
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from pydrake.common.schema import Transform
from pydrake.common.yaml import yaml_load_typed

from sustain_drake import files
from sustain_drake.recorded_data import read_points_csv, read_poses_csv, write_points_csv, write_poses_csv

DATA = Path(__file__).parent / "data" / "jin_eyetobase_rvc_single"


def run_cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "sustain_drake.cli.main", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=120,
    )


def calibrate(points, poses, *extra):
    return run_cli("calibrate", "eye-to-hand", "--points", points, "--poses", poses, *extra)


def test_real_data_end_to_end(tmp_path):
    out = tmp_path / "result.yaml"
    r = calibrate(DATA / "corner_points.csv", DATA / "poses.csv", "--out", out)
    assert r.returncode == 0, r.stderr
    assert "verdict: converged" in r.stdout
    assert "per-sample residuals [mm]" in r.stdout
    assert "gap lambda_15/lambda_16" in r.stdout
    assert (
        len([line for line in r.stdout.splitlines() if line.startswith("    ") and line.strip()[0].isdigit()])
        >= 50
    )
    # The YAML's X_WC is a Drake schema.Transform in metres and degrees.
    transform = yaml_load_typed(
        schema=Transform, filename=str(out), child_name="X_WC", retain_map_defaults=True
    )
    X = transform.GetDeterministicValue()
    assert transform.base_frame == "world"
    assert np.abs(X.translation() * 1e3 - [-144.26, -491.22, 951.02]).max() < 0.05
    text = out.read_text()
    assert "converged: true" in text and "residuals_m:" in text


def test_rpy_pose_format_gives_the_same_answer(tmp_path):
    truth = make_truth(3)
    p_C, X_WH = make_samples(truth, 30, noise_m=1e-4, seed=4)
    from scipy.spatial.transform import Rotation

    rpy = Rotation.from_matrix(X_WH[:, :3, :3]).as_euler("xyz")
    rows = ["x,y,z,roll,pitch,yaw"] + [
        ",".join(repr(float(v)) for v in (*X[:3, 3], *a)) for X, a in zip(X_WH, rpy, strict=True)
    ]
    (tmp_path / "rpy.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "quat.csv").write_text(write_poses_csv(X_WH))
    (tmp_path / "p.csv").write_text(write_points_csv(p_C))
    assert np.allclose(
        read_poses_csv(tmp_path / "rpy.csv"), read_poses_csv(tmp_path / "quat.csv"), atol=1e-12
    )
    assert np.array_equal(read_points_csv(tmp_path / "p.csv"), p_C)
    a = calibrate(tmp_path / "p.csv", tmp_path / "rpy.csv", "--out", tmp_path / "a.yaml")
    b = calibrate(tmp_path / "p.csv", tmp_path / "quat.csv", "--out", tmp_path / "b.yaml")
    assert a.returncode == b.returncode == 0
    assert a.stdout.split("verdict")[1].split("wrote")[0] == b.stdout.split("verdict")[1].split("wrote")[0]


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.fixture
def good_files(tmp_path):
    truth = make_truth(1)
    p_C, X_WH = make_samples(truth, 20, noise_m=1e-4, seed=2)
    return (
        _write(tmp_path / "p.csv", write_points_csv(p_C)),
        _write(tmp_path / "q.csv", write_poses_csv(X_WH)),
        p_C,
        X_WH,
    )


def one_line_error(r, code=2):
    assert r.returncode == code, (r.returncode, r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert "Traceback" not in r.stderr
    return lines[0]


def test_nan_is_one_line(tmp_path, good_files):
    points, poses, p_C, _ = good_files
    lines = points.read_text().splitlines()
    lines[3] = "0.1,nan,0.3"
    bad = _write(tmp_path / "nan.csv", "\n".join(lines) + "\n")
    assert "NaN or inf" in one_line_error(calibrate(bad, poses))
    assert "nan.csv:4" in one_line_error(calibrate(bad, poses))


def test_wrong_column_count(tmp_path, good_files):
    points, poses, _, _ = good_files
    lines = poses.read_text().splitlines()
    lines[5] = ",".join(lines[5].split(",")[:6])
    bad = _write(tmp_path / "cols.csv", "\n".join(lines) + "\n")
    assert "6 columns, expected 7" in one_line_error(calibrate(points, bad))
    bad_header = _write(tmp_path / "hdr.csv", "a,b\n1,2\n")
    assert "header is 'a,b'" in one_line_error(calibrate(bad_header, poses))


def test_mismatched_rows(tmp_path, good_files):
    points, poses, _, _ = good_files
    lines = points.read_text().splitlines()
    short = _write(tmp_path / "short.csv", "\n".join(lines[:-2]) + "\n")
    assert "rows must pair one to one" in one_line_error(calibrate(short, poses))


def test_too_few_samples(tmp_path, good_files):
    points, poses, p_C, X_WH = good_files
    p = _write(tmp_path / "few_p.csv", write_points_csv(p_C[:4]))
    q = _write(tmp_path / "few_q.csv", write_poses_csv(X_WH[:4]))
    assert "too few samples: 4 rows" in one_line_error(calibrate(p, q))


def test_missing_file_and_bad_quaternion(tmp_path, good_files):
    points, poses, _, _ = good_files
    assert "cannot read" in one_line_error(calibrate(tmp_path / "nope.csv", poses))
    lines = poses.read_text().splitlines()
    lines[2] = ",".join(lines[2].split(",")[:3] + ["2", "0", "0", "0"])
    bad = _write(tmp_path / "q2.csv", "\n".join(lines) + "\n")
    assert "quaternion norm 2 is not 1" in one_line_error(calibrate(points, bad))


def test_degenerate_motion_is_not_converged_and_keeps_old_result(tmp_path):
    truth = make_truth(5)
    p_C, X_WH = make_samples(truth, 40, noise_m=1e-4, rotate=False, seed=6)
    p = _write(tmp_path / "p.csv", write_points_csv(p_C))
    q = _write(tmp_path / "q.csv", write_poses_csv(X_WH))
    out = _write(tmp_path / "result.yaml", "previous result\n")
    r = calibrate(p, q, "--out", out)
    line = one_line_error(r, code=3)
    assert line.startswith("sustain-drake: not converged: motion not rich enough")
    assert out.read_text() == "previous result\n"  # nothing the user had is lost


def test_console_script_is_installed():
    exe = shutil.which("sustain-drake") or str(Path(sys.executable).parent / "sustain-drake")
    r = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "calibrate" in r.stdout


def test_atomic_write_gives_normal_permissions_and_keeps_existing_ones(tmp_path):
    import os
    import stat

    from sustain_drake.files import write_atomically

    new = tmp_path / "new.txt"
    write_atomically(new, "a")
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(new.stat().st_mode) == 0o666 & ~mask
    old = tmp_path / "old.txt"
    old.write_text("x")
    old.chmod(0o640)
    write_atomically(old, b"y")
    assert old.read_bytes() == b"y" and stat.S_IMODE(old.stat().st_mode) == 0o640
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left


# --- Reliability (issue #23): bad encodings, CSV parser failures and unsafe output paths -----------

LATIN = "# measured at 20 °C, café\n"  # also writable in latin-1 and cp1252
COMMENTED = "# measured at 20 °C, café — 测量\n"


def snapshot(folder: Path) -> dict:
    """Every file under ``folder`` and its bytes (a refused run must change none and add none)."""
    return {p: p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def calibrate_in_process(points, poses, *extra):
    """``calibrate`` without a new interpreter: what the process would exit with and print on stderr."""
    code, err = run_in_process(["calibrate", "eye-to-hand", "--points", str(points), "--poses", str(poses),
                                *map(str, extra)])  # fmt: skip
    return subprocess.CompletedProcess([], code, "", err)


def real_copies(tmp_path) -> tuple[Path, Path, Path]:
    """The real data set's corner points and poses, copied, and a previous result beside them."""
    points = _write(tmp_path / "points.csv", (DATA / "corner_points.csv").read_text())
    poses = _write(tmp_path / "poses.csv", (DATA / "poses.csv").read_text())
    return points, poses, _write(tmp_path / "result.yaml", "previous result\n")


BAD_POINTS = {
    "utf-16": (lambda text: (COMMENTED + text).encode("utf-16"), "binary or UTF-16"),
    "utf-16 without a byte-order mark": (lambda text: text.encode("utf-16-le"), "binary or UTF-16"),
    "latin-1": (lambda text: (LATIN + text).encode("latin-1"), "not UTF-8 text"),
    "cp1252": (lambda text: (LATIN + text).encode("cp1252"), "not UTF-8 text"),
    "binary": (lambda text: bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8)), "binary"),
    "a field over 131,072 characters": (
        lambda text: (text + "1" * 200_000 + ",0,0\n").encode(), "field larger than field limit"
    ),
    "a quoted field across lines": (lambda text: (text + '"0.1\n0.2",0,0\n').encode(), "not a number"),
    "a millimetre value": (lambda text: (text + "104.3,-86.9,1837.8\n").encode(), "over 1000 m: give metres"),
}


@pytest.mark.parametrize("case", BAD_POINTS, ids=list(BAD_POINTS))
def test_bad_points_file_is_one_line_and_changes_nothing(tmp_path, case):
    make, expected = BAD_POINTS[case]
    points, poses, out = real_copies(tmp_path)
    points.write_bytes(make(points.read_text()))
    before = snapshot(tmp_path)
    r = calibrate_in_process(points, poses, "--out", out, "--camera-config", tmp_path / "camera.yaml")
    line = one_line_error(r)
    assert expected in line and str(points) in line
    assert snapshot(tmp_path) == before


def _out_on_points(tmp_path, points, poses, out):
    return ("--out", points), "is also the --points file"


def _out_linked_to_poses(tmp_path, points, poses, out):
    (tmp_path / "link.yaml").symlink_to(poses)
    return ("--out", tmp_path / "link.yaml"), "is also the --poses file"


def _one_path_twice(tmp_path, points, poses, out):
    return ("--out", out, "--camera-config", out), "are one file"


def _one_path_spelled_twice(tmp_path, points, poses, out):
    (tmp_path / "sub").mkdir()
    return ("--out", out, "--camera-config", tmp_path / "sub" / ".." / out.name), "are one file"


def _camera_config_a_folder(tmp_path, points, poses, out):
    (tmp_path / "folder").mkdir()
    return ("--out", out, "--camera-config", tmp_path / "folder"), "is a folder"


def _camera_config_under_a_file(tmp_path, points, poses, out):
    return ("--out", out, "--camera-config", points / "camera.yaml"), "is not a folder"


BAD_OUTPUTS = {
    "--out is the points file": _out_on_points,
    "--out is a link to the poses file": _out_linked_to_poses,
    "--out and --camera-config on one path": _one_path_twice,
    "--out and --camera-config on one path spelled twice": _one_path_spelled_twice,
    "--camera-config is a folder": _camera_config_a_folder,
    "--camera-config under a file": _camera_config_under_a_file,
}


@pytest.mark.parametrize("make", BAD_OUTPUTS.values(), ids=list(BAD_OUTPUTS))
def test_unsafe_outputs_are_refused_before_anything_runs(tmp_path, make):
    points, poses, out = real_copies(tmp_path)
    args, expected = make(tmp_path, points, poses, out)
    before = snapshot(tmp_path)
    line = one_line_error(calibrate_in_process(points, poses, *args))
    assert expected in line, line
    assert snapshot(tmp_path) == before  # the inputs and the previous result are byte-identical


def test_an_out_folder_that_cannot_be_written_is_refused_before_anything_runs(tmp_path, monkeypatch):
    # The tests run as root, who writes in read-only folders: the write itself is made to fail.
    def no_write(*args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied")

    points, poses, out = real_copies(tmp_path)
    before = snapshot(tmp_path)
    monkeypatch.setattr(files.tempfile, "mkstemp", no_write)
    line = one_line_error(calibrate_in_process(points, poses, "--out", str(out)))
    assert "cannot write" in line, line
    assert snapshot(tmp_path) == before


def test_refusals_end_to_end(tmp_path):
    points, poses, out = real_copies(tmp_path)
    utf16 = _write(tmp_path / "utf16.csv", "")
    utf16.write_bytes(points.read_text().encode("utf-16"))
    before = snapshot(tmp_path)
    assert "binary or UTF-16" in one_line_error(calibrate(utf16, poses, "--out", out))
    assert "is also the --points file" in one_line_error(calibrate(points, poses, "--out", points))
    assert snapshot(tmp_path) == before


def test_both_outputs_are_written_and_a_byte_order_mark_is_read(tmp_path):
    points, poses, out = real_copies(tmp_path)
    with_bom = _write(tmp_path / "bom.csv", "\ufeff" + COMMENTED + points.read_text())
    assert np.array_equal(read_points_csv(with_bom), read_points_csv(points))
    camera = tmp_path / "new" / "camera.yaml"
    r = calibrate(with_bom, poses, "--out", out, "--camera-config", camera)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    assert "converged: true" in out.read_text() and "X_PB:" in camera.read_text()


@pytest.mark.parametrize("flag", ["--max-rms", "--min-gap", "--max-ssd"])
def test_non_finite_criteria_are_refused(tmp_path, flag):
    points, poses, _ = real_copies(tmp_path)
    line = one_line_error(calibrate_in_process(points, poses, flag, "inf"))
    assert f"{flag} must be a finite number" in line


# --- Fuzz: random bytes, random CSV text and random encodings as the points and poses files --------

FUZZ_LONG = os.environ.get("SUSTAIN_DRAKE_FUZZ") == "long"
ENCODINGS = ("utf-8", "utf-8-sig", "utf-16", "utf-16-be", "utf-32", "latin-1", "cp1252", "shift_jis",
             "koi8-r")  # fmt: skip
ODD_CELLS = ("nan", "-inf", "1e308", "1e-320", "", " ", '"1,2"', '"', "#", "1_0", "0x10", "1e3", "-999.9",
             "6.3")  # fmt: skip


@st.composite
def csv_text(draw, lines: list[str]) -> str:
    """The real data set's file with a few random edits, line endings and an optional comment."""
    lines = list(lines)
    for _ in range(draw(st.integers(0, 4))):
        i = draw(st.integers(0, len(lines) - 1)) if lines else 0
        edit = draw(st.sampled_from(("cell", "delete", "duplicate", "insert", "truncate", "column", "scale")))
        if not lines:
            lines.append(draw(st.text(max_size=40)))
        elif edit == "cell":
            cells = lines[i].split(",")
            cell = draw(st.one_of(st.sampled_from(ODD_CELLS), st.floats().map(repr), st.text(max_size=12)))
            cells[draw(st.integers(0, len(cells) - 1))] = cell
            lines[i] = ",".join(cells)
        elif edit == "delete":
            del lines[i]
        elif edit == "duplicate":
            lines.insert(i, lines[draw(st.integers(0, len(lines) - 1))])
        elif edit == "insert":
            lines.insert(i, draw(st.text(max_size=40)))
        elif edit == "truncate":
            lines = lines[: draw(st.integers(0, len(lines)))]
        elif edit == "column":
            lines[i] += "," + draw(st.sampled_from(ODD_CELLS))
        else:  # one column of every row scaled, e.g. millimetres or a constant
            j = draw(st.integers(0, 6))
            factor = draw(st.sampled_from((0.0, -1.0, 1e-9, 1e3)))
            for k in range(1, len(lines)):
                cells = lines[k].split(",")
                if j < len(cells):
                    try:
                        cells[j] = repr(float(cells[j]) * factor)
                    except ValueError:
                        pass
                lines[k] = ",".join(cells)
    newline = draw(st.sampled_from(("\n", "\r\n", "\r")))
    comment = draw(st.sampled_from(("", COMMENTED)))
    return comment + newline.join(lines) + newline


def file_bytes(lines: list[str]):
    return st.one_of(
        st.binary(max_size=2000),
        csv_text(lines).map(str.encode),
        st.tuples(csv_text(lines), st.sampled_from(ENCODINGS)).map(lambda t: t[0].encode(t[1], "replace")),
    )


POINT_LINES = (DATA / "corner_points.csv").read_text().splitlines()
POSE_LINES = (DATA / "poses.csv").read_text().splitlines()


def run_in_process(args: list[str]) -> tuple[int, str]:
    """``main(args)``: the exit code and what a process would print on stderr (warnings too)."""
    from sustain_drake.cli.main import main

    err = io.StringIO()
    with warnings.catch_warnings(record=True) as caught, contextlib.redirect_stderr(err):
        warnings.simplefilter("always")
        with contextlib.redirect_stdout(io.StringIO()):
            code = main(args)
    for w in caught:
        err.write(f"{w.category.__name__}: {w.message}\n")
    return code, err.getvalue()


@settings(max_examples=3000 if FUZZ_LONG else 250, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])  # fmt: skip
@given(points=file_bytes(POINT_LINES), poses=file_bytes(POSE_LINES))
def test_fuzz_points_and_poses_files(points, poses):
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        (folder / "p.csv").write_bytes(points)
        (folder / "q.csv").write_bytes(poses)
        _write(folder / "result.yaml", "previous result\n")
        _write(folder / "camera.yaml", "previous camera\n")
        before = snapshot(folder)
        code, err = run_in_process(["calibrate", "eye-to-hand", "--points", str(folder / "p.csv"),
                                    "--poses", str(folder / "q.csv"), "--out", str(folder / "result.yaml"),
                                    "--camera-config", str(folder / "camera.yaml")])  # fmt: skip
        event(f"exit {code}")  # shown by --hypothesis-show-statistics
        assert code in (0, 2, 3), err
        assert len(err.splitlines()) == (0 if code == 0 else 1), err
        after = snapshot(folder)
        changed = {p.name for p in before.keys() | after.keys() if before.get(p) != after.get(p)}
        assert changed == ({"result.yaml", "camera.yaml"} if code == 0 else set()), (code, changed)
