"""``sustain-drake calibrate eye-to-hand``: output, YAML for Drake, and one-line errors."""

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from eye_to_hand_data import make_samples, make_truth
from pydrake.common.schema import Transform
from pydrake.common.yaml import yaml_load_typed

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
