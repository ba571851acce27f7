"""Reading recorded calibration data from CSV files and writing results as YAML (no pydrake).

CSV formats (UTF-8 text, a byte-order mark allowed, at most ``MAX_FILE_BYTES``; one header row;
blank lines and lines starting with ``#`` are ignored; row i of the points file goes with row i of
the poses file; coordinates within ``MAX_ABS_POSITION_M``, angles within ``MAX_ABS_ANGLE_RAD``;
anything else raises ``RecordedDataError`` with a one-line message):

- points: ``x,y,z`` -- the tracked point in the camera frame C, metres (camera frame as in Drake
  and OpenCV: +z forward along the optical axis, +x right, +y down in the image).
- poses: the hand frame H in the world W, either
  ``x,y,z,qw,qx,qy,qz`` (metres; unit quaternion, scalar first) or
  ``x,y,z,roll,pitch,yaw`` (metres; radians, ``R = Rz(yaw) Ry(pitch) Rx(roll)``, Drake's
  ``RollPitchYaw``).

The YAML result holds ``X_WC`` in Drake's ``schema.Transform`` form (``translation`` in metres,
``rotation: !Rpy {deg: [...]}``), so it can be pasted into a scenario as a camera's ``X_PB`` with
``base_frame: world``, plus the point, the residuals and the verdict.
"""

from __future__ import annotations

import codecs
import csv
import io
import math
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

POINT_COLUMNS = ("x", "y", "z")
POSE_COLUMNS_QUATERNION = ("x", "y", "z", "qw", "qx", "qy", "qz")
POSE_COLUMNS_RPY = ("x", "y", "z", "roll", "pitch", "yaw")
QUATERNION_NORM_TOLERANCE = 1e-3


class RecordedDataError(ValueError):
    """A file that cannot be used; the message is one line naming the file (and row)."""


# Limits that keep a read bounded and catch unit mistakes (both stated in docs/identification.md).
MAX_FILE_BYTES = 100_000_000
MAX_ABS_POSITION_M = 1000.0  # a larger coordinate is surely millimetres, not metres
MAX_ABS_ANGLE_RAD = 2 * math.pi  # a larger roll, pitch or yaw is surely degrees, not radians


def _shown(cells) -> str:
    """Cells as the user wrote them, on one line and at most 60 characters."""
    text = ",".join(cells)
    text = text if text.isprintable() else repr(text)[1:-1]
    return text if len(text) <= 60 else text[:57] + "..."


def _read_text(path: Path) -> str:
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_FILE_BYTES + 1)
    except OSError as e:
        raise RecordedDataError(f"{path}: cannot read: {e.strerror or e}") from None
    if len(data) > MAX_FILE_BYTES:
        raise RecordedDataError(f"{path}: larger than {MAX_FILE_BYTES // 1_000_000} MB: not a recorded CSV")
    if data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)) or b"\x00" in data:
        raise RecordedDataError(f"{path}: a binary or UTF-16 file, not a text CSV: save it as UTF-8")
    body = data.removeprefix(codecs.BOM_UTF8)  # a leading byte-order mark (as Excel writes) is dropped
    try:
        return body.decode("utf-8")
    except UnicodeDecodeError as e:
        at = e.start + len(data) - len(body)
        raise RecordedDataError(
            f"{path}: not UTF-8 text (byte {at + 1} is {data[at]:#04x}): save it as UTF-8"
        ) from None


def _read_table(path: str | Path, formats: tuple[tuple[str, ...], ...]) -> tuple[tuple[str, ...], np.ndarray]:
    path = Path(path)
    reader = csv.reader(io.StringIO(_read_text(path), newline=""))
    rows = []
    header = None
    while True:
        try:
            row = next(reader)
        except StopIteration:
            break
        except csv.Error as e:
            raise RecordedDataError(f"{path}:{reader.line_num}: not a CSV row ({e})") from None
        line_no = reader.line_num
        cells = [c.strip() for c in row]
        if not cells or all(c == "" for c in cells) or cells[0].startswith("#"):
            continue
        if header is None:
            header = tuple(c.lower() for c in cells)
            if header not in formats:
                wanted = " or ".join(",".join(f) for f in formats)
                raise RecordedDataError(f"{path}:{line_no}: header is '{_shown(cells)}', expected {wanted}")
            continue
        if len(cells) != len(header):
            raise RecordedDataError(
                f"{path}:{line_no}: {len(cells)} columns, expected {len(header)} ({','.join(header)})"
            )
        try:
            values = [float(c) for c in cells]
        except ValueError:
            raise RecordedDataError(f"{path}:{line_no}: not a number in '{_shown(cells)}'") from None
        if not all(math.isfinite(v) for v in values):
            raise RecordedDataError(f"{path}:{line_no}: NaN or inf in '{_shown(cells)}'")
        _check_ranges(path, line_no, header, values)
        rows.append(values)
    if header is None:
        raise RecordedDataError(f"{path}: empty file (no header row)")
    return header, np.array(rows, dtype=float).reshape(len(rows), len(header))


def _check_ranges(path: Path, line_no: int, header: tuple[str, ...], values: list[float]) -> None:
    for name, value in zip(header, values, strict=True):
        if name in POINT_COLUMNS and abs(value) > MAX_ABS_POSITION_M:
            raise RecordedDataError(
                f"{path}:{line_no}: {name} = {value:g} m is over {MAX_ABS_POSITION_M:g} m: give metres"
            )
        if name in ("roll", "pitch", "yaw") and abs(value) > MAX_ABS_ANGLE_RAD:
            raise RecordedDataError(
                f"{path}:{line_no}: {name} = {value:g} rad is outside +-2 pi: give radians"
            )


def read_points_csv(path: str | Path) -> np.ndarray:
    """Reads a points file: (n, 3) positions in the camera frame, metres."""
    _, table = _read_table(path, (POINT_COLUMNS,))
    return table


def read_poses_csv(path: str | Path) -> np.ndarray:
    """Reads a poses file: (n, 4, 4) homogeneous transforms ``X_WH``."""
    header, table = _read_table(path, (POSE_COLUMNS_QUATERNION, POSE_COLUMNS_RPY))
    n = len(table)
    X = np.tile(np.eye(4), (n, 1, 1))
    X[:, :3, 3] = table[:, 0:3]
    if n == 0:
        return X
    if header == POSE_COLUMNS_QUATERNION:
        q = table[:, 3:7]
        with np.errstate(over="ignore"):  # a huge component gives an inf norm, refused below
            norms = np.linalg.norm(q, axis=1)
        bad = np.flatnonzero(np.abs(norms - 1.0) > QUATERNION_NORM_TOLERANCE)
        if bad.size:
            raise RecordedDataError(
                f"{path}: data row {bad[0] + 1}: quaternion norm {norms[bad[0]]:.6g} is not 1"
            )
        q = q / norms[:, None]
        X[:, :3, :3] = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()  # scipy is scalar-last
    else:
        X[:, :3, :3] = Rotation.from_euler("xyz", table[:, 3:6]).as_matrix()
    return X


def write_points_csv(p_C: np.ndarray) -> str:
    """The text of a points file (returned; the caller writes it atomically)."""
    lines = [",".join(POINT_COLUMNS)]
    lines += [",".join(repr(float(v)) for v in row) for row in np.asarray(p_C)]
    return "\n".join(lines) + "\n"


def write_poses_csv(X_WH: np.ndarray) -> str:
    """The text of a poses file in the quaternion format."""
    X_WH = np.asarray(X_WH)
    q = Rotation.from_matrix(X_WH[:, :3, :3]).as_quat()[:, [3, 0, 1, 2]]  # scalar first
    q[q[:, 0] < 0] *= -1.0  # canonical sign, w >= 0
    lines = [",".join(POSE_COLUMNS_QUATERNION)]
    for X, qi in zip(X_WH, q, strict=True):
        lines.append(",".join(repr(float(v)) for v in (*X[:3, 3], *qi)))
    return "\n".join(lines) + "\n"


def rpy_degrees(R: np.ndarray) -> np.ndarray:
    """Drake ``RollPitchYaw`` angles of ``R`` in degrees (``R = Rz(yaw) Ry(pitch) Rx(roll)``)."""
    return Rotation.from_matrix(R).as_euler("xyz", degrees=True)


def _yaml_list(values) -> str:
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def eye_to_hand_yaml(result, points_file: str = "", poses_file: str = "") -> str:
    """The YAML text of an eye-to-hand result (``batch.EyeToHandResult``).

    ``X_WC`` is a Drake ``schema.Transform``: load it with
    ``yaml_load_typed(schema=Transform, data=text, child_name="X_WC")`` or paste it as a camera's
    ``X_PB`` (the camera body frame B of a ``CameraConfig`` is the optical frame C).
    """
    X_WC = result.X_WC
    lines = [
        "# Eye-to-hand calibration by sustain-drake (paper §3.4; TLS, SO(3) projection, Gauss-Newton).",
        f"# points: {points_file}" if points_file else None,
        f"# poses: {poses_file}" if poses_file else None,
        f"# verdict: {result.verdict}",
        "X_WC:",
        "  base_frame: world",
        f"  translation: {_yaml_list(X_WC[:3, 3])}",
        "  rotation: !Rpy",
        f"    deg: {_yaml_list(rpy_degrees(X_WC[:3, :3]))}",
        f"p_HP: {_yaml_list(result.p_HP)}",
        f"converged: {'true' if result.converged else 'false'}",
        f"rms_m: {float(result.rms)!r}",
        f"expected_rms_m: {float(result.expected_rms)!r}",
        f"gap_ratio: {float(result.gap_ratio)!r}" if math.isfinite(result.gap_ratio) else "gap_ratio: .inf",
        f"ssd: {float(result.ssd)!r}",
        f"num_samples: {len(result.residuals)}",
        f"residuals_m: {_yaml_list(result.residuals)}",
        f"eigenvalues: {_yaml_list(result.eigenvalues)}",
    ]
    return "\n".join(line for line in lines if line is not None) + "\n"
