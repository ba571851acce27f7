"""Reading recorded calibration data from CSV files and writing results as YAML (no pydrake).

CSV formats (UTF-8 text, a byte-order mark allowed, at most ``MAX_FILE_BYTES``; one header row;
blank lines and lines starting with ``#`` are ignored; coordinates within ``MAX_ABS_POSITION_M``,
angles within ``MAX_ABS_ANGLE_RAD``; anything else raises ``RecordedDataError`` with a one-line
message):

- points: ``x,y,z`` -- one point fixed on the hand, in the camera frame C, metres (camera frame as
  in Drake and OpenCV: +z forward along the optical axis, +x right, +y down in the image); row i
  goes with row i of the poses file.
- points of several points: ``sample,point,x,y,z`` -- one row per point seen at a sample: the
  0-based row index into the poses file, the point's label (text), its position in C in metres
  (``read_point_tracks_csv``).
- poses: the hand frame H in the world W, either
  ``x,y,z,qw,qx,qy,qz`` (metres; unit quaternion, scalar first) or
  ``x,y,z,roll,pitch,yaw`` (metres; radians, ``R = Rz(yaw) Ry(pitch) Rx(roll)``, Drake's
  ``RollPitchYaw``).

The YAML result holds ``X_WC`` in Drake's ``schema.Transform`` form (``translation`` in metres,
``rotation: !Rpy {deg: [...]}``), so it can be pasted into a scenario as a camera's ``X_PB`` with
``base_frame: world``, plus the point (or each point), the residuals and the verdict.
"""

from __future__ import annotations

import codecs
import csv
import io
import json
import math
import numbers
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import NamedTuple

import numpy as np
from scipy.spatial.transform import Rotation

from sustain_drake.identification.batch import (
    MAX_LABEL_CHARACTERS,
    MAX_POINTS,
    MIN_POINT_SAMPLES,
    EyeToHandPointsResult,
)

POINT_COLUMNS = ("x", "y", "z")
POINT_TRACK_COLUMNS = ("sample", "point", "x", "y", "z")
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


def _read_rows(path: Path, formats: tuple[tuple[str, ...], ...]) -> tuple[tuple[str, ...], list]:
    """The header (one of ``formats``) and ``(line number, cells)`` of every data row, each with as
    many cells as the header (blank lines and ``#`` lines skipped)."""
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
        rows.append((line_no, cells))
    if header is None:
        raise RecordedDataError(f"{path}: empty file (no header row)")
    return header, rows


def _numbers(path: Path, line_no: int, header: tuple[str, ...], cells: list[str], start: int = 0):
    """The cells from ``start`` on as finite numbers (a list) within their columns' ranges."""
    try:
        values = [float(c) for c in cells[start:]]
    except ValueError:
        raise RecordedDataError(f"{path}:{line_no}: not a number in '{_shown(cells)}'") from None
    if not all(math.isfinite(v) for v in values):
        raise RecordedDataError(f"{path}:{line_no}: NaN or inf in '{_shown(cells)}'")
    _check_ranges(path, line_no, header[start:], values)
    return values


def _read_table(path: str | Path, formats: tuple[tuple[str, ...], ...]) -> tuple[tuple[str, ...], np.ndarray]:
    path = Path(path)
    header, rows = _read_rows(path, formats)
    table = [_numbers(path, line_no, header, cells) for line_no, cells in rows]
    return header, np.array(table, dtype=float).reshape(len(table), len(header))


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


class PointTracks(NamedTuple):
    """A points file (``read_point_tracks_csv``): ``points`` maps each point's label to its samples
    (0-based indices into the poses file's rows, int array) and its positions in the camera frame
    ((m, 3), metres), in the order of the labels' first rows; ``labelled``: the file has the
    ``sample,point,x,y,z`` header (else ``x,y,z``: one point labelled ``"P"``, row i is sample i);
    ``left_out``: the points of the file in fewer than ``MIN_POINT_SAMPLES`` samples, label ->
    (their first line, their sample count), not in ``points``."""

    points: dict
    labelled: bool
    left_out: Mapping = MappingProxyType({})  # read-only: a default shared by every instance


def read_point_tracks_csv(path: str | Path, num_samples: int | None = None) -> PointTracks:
    """Reads a points file of either format. With the ``sample,point,x,y,z`` header each row is one
    point seen at one sample: ``sample`` the 0-based row index into the poses file (below
    ``num_samples`` when given), ``point`` a label compared as text (non-empty, printable, at most
    ``MAX_LABEL_CHARACTERS``); a (sample, point) pair appears once; at most ``MAX_POINTS`` points.
    A point in fewer than ``MIN_POINT_SAMPLES`` samples (a board's corner seen in two images; or a
    typo in a label) is left out (``PointTracks.left_out``: its own fit needs 4); when every point is,
    and anything else, raises RecordedDataError naming the file and line."""
    path = Path(path)
    header, rows = _read_rows(path, (POINT_COLUMNS, POINT_TRACK_COLUMNS))
    if header == POINT_COLUMNS:
        table = np.array([_numbers(path, line_no, header, cells) for line_no, cells in rows]).reshape(-1, 3)
        return PointTracks({"P": (np.arange(len(table)), table)}, labelled=False)
    seen: dict[tuple[str, int], int] = {}  # (point, sample) -> its line
    first: dict[str, int] = {}  # point -> its first line
    tracks: dict[str, tuple[list, list]] = {}
    for line_no, cells in rows:
        sample, label = _sample_index(path, line_no, cells[0], num_samples), _label(path, line_no, cells[1])
        if (label, sample) in seen:
            raise RecordedDataError(f"{path}:{line_no}: sample {sample} of point '{label}' again (first at "
                                    f"line {seen[label, sample]}): one row per sample and point")  # fmt: skip
        if label not in tracks and len(tracks) == MAX_POINTS:
            raise RecordedDataError(f"{path}:{line_no}: point '{label}' is one point too many (at most "
                                    f"{MAX_POINTS})")  # fmt: skip
        seen[label, sample] = line_no
        first.setdefault(label, line_no)
        samples, positions = tracks.setdefault(label, ([], []))
        samples.append(sample)
        positions.append(_numbers(path, line_no, header, cells, start=2))
    left_out = {label: (first[label], len(samples)) for label, (samples, _) in tracks.items()
                if len(samples) < MIN_POINT_SAMPLES}
    if tracks and len(left_out) == len(tracks):
        raise RecordedDataError(f"{path}: no point is in {MIN_POINT_SAMPLES} samples or more (each point's "
                                f"own fit needs {MIN_POINT_SAMPLES}): {left_out_text(left_out)}")
    return PointTracks({label: (np.array(samples, dtype=np.int64), np.array(positions, dtype=float))
                        for label, (samples, positions) in tracks.items() if label not in left_out},
                       labelled=True, left_out=left_out)  # fmt: skip


def left_out_text(left_out: dict, shown: int = 5) -> str:
    """One line naming the points left out (``PointTracks.left_out``): label, samples, first line;
    the first ``shown`` of them, then how many more."""
    items = [f"point '{label}' in {count} sample{'s' if count != 1 else ''} only (line {line})"
             for label, (line, count) in left_out.items()]
    more = f"; and {len(items) - shown} more" if len(items) > shown else ""
    return "; ".join(items[:shown]) + more


def _sample_index(path: Path, line_no: int, cell: str, num_samples: int | None) -> int:
    if not (cell.isascii() and cell.isdigit() and len(cell) <= 9):
        raise RecordedDataError(f"{path}:{line_no}: sample '{_shown([cell])}' is not a 0-based row index of "
                                "the poses (0, 1, 2, ...)")  # fmt: skip
    sample = int(cell)
    if num_samples is not None and sample >= num_samples:
        rows = f"0 to {num_samples - 1}" if num_samples else "none"
        raise RecordedDataError(f"{path}:{line_no}: sample {sample} is out of range: the poses have "
                                f"{num_samples} rows ({rows})")  # fmt: skip
    return sample


def _label(path: Path, line_no: int, cell: str) -> str:
    if not cell:
        raise RecordedDataError(f"{path}:{line_no}: the point label is empty")
    if not cell.isprintable() or len(cell) > MAX_LABEL_CHARACTERS:
        raise RecordedDataError(f"{path}:{line_no}: the point label '{_shown([cell])}' is not printable text "
                                f"of at most {MAX_LABEL_CHARACTERS} characters")  # fmt: skip
    return cell


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


def write_point_tracks_csv(points) -> str:
    """The text of a points file in the ``sample,point,x,y,z`` format from a mapping of labels to
    ``(samples, p_C)`` (``batch.calibrate_eye_to_hand_points``'s ``points``), ordered by sample and
    then by label order."""
    rows = [(int(i), order, str(label), p) for order, (label, (samples, p_C)) in enumerate(points.items())
            for i, p in zip(samples, np.asarray(p_C), strict=True)]  # fmt: skip
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(POINT_TRACK_COLUMNS)
    for i, _, label, p in sorted(rows, key=lambda row: row[:2]):
        writer.writerow([i, label, *(repr(float(v)) for v in p)])
    return text.getvalue()


def rpy_degrees(R: np.ndarray) -> np.ndarray:
    """Drake ``RollPitchYaw`` angles of ``R`` in degrees (``R = Rz(yaw) Ry(pitch) Rx(roll)``)."""
    return Rotation.from_matrix(R).as_euler("xyz", degrees=True)


def _yaml_float(value) -> str:
    """A float as YAML writes it (``.inf``, ``-.inf``, ``.nan`` for the non-finite)."""
    value = float(value)
    if math.isfinite(value):
        return repr(value)
    return ".nan" if math.isnan(value) else ("-.inf" if value < 0 else ".inf")


def _yaml_list(values) -> str:
    return "[" + ", ".join(_yaml_float(v) for v in values) + "]"


def _yaml_label(label) -> str:
    """A point's label as a YAML scalar: an integer as it is, text double-quoted (JSON's escapes)."""
    return str(int(label)) if isinstance(label, numbers.Integral) else json.dumps(str(label))


def _transform_lines(X_WC: np.ndarray) -> list[str]:
    """``X_WC`` as a Drake ``schema.Transform`` in the world (metres, rpy in degrees)."""
    return ["X_WC:", "  base_frame: world", f"  translation: {_yaml_list(X_WC[:3, 3])}", "  rotation: !Rpy",
            f"    deg: {_yaml_list(rpy_degrees(X_WC[:3, :3]))}"]  # fmt: skip


def eye_to_hand_yaml(result, points_file: str = "", poses_file: str = "") -> str:
    """The YAML text of an eye-to-hand result (``batch.EyeToHandResult``, or
    ``batch.EyeToHandPointsResult`` for several points: a ``points`` list with each point's label,
    ``p_HP``, its 1 sd, RMS, weight, samples, residuals, outliers and its own fit ``alone``).

    ``X_WC`` is a Drake ``schema.Transform``: load it with
    ``yaml_load_typed(schema=Transform, data=text, child_name="X_WC")`` or paste it as a camera's
    ``X_PB`` (the camera body frame B of a ``CameraConfig`` is the optical frame C).
    """
    files = [f"# points: {points_file}" if points_file else None,
             f"# poses: {poses_file}" if poses_file else None, f"# verdict: {result.verdict}"]  # fmt: skip
    if isinstance(result, EyeToHandPointsResult):
        return _points_yaml(result, files)
    lines = [
        "# Eye-to-hand calibration by sustain-drake (paper §3.4; TLS, SO(3) projection, Gauss-Newton).",
        *files,
        *_transform_lines(result.X_WC),
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


def _points_yaml(result: EyeToHandPointsResult, files: list) -> str:
    errors, offsets, outliers = result.standard_errors, result.single_offsets(), result.outliers()
    lines = [
        f"# Eye-to-hand calibration by sustain-drake of {len(result.labels)} points fixed on the hand, "
        "jointly (paper §3.4 per point; weighted joint Gauss-Newton).",
        *files,
        *_transform_lines(result.X_WC),
        f"converged: {'true' if result.converged else 'false'}",
        f"num_samples: {result.num_samples}",
        f"camera_rotation_sd_deg: {_yaml_float(math.degrees(errors[0]))}" if errors else None,
        f"camera_position_sd_m: {_yaml_float(errors[1])}" if errors else None,
        f"start_point: {_yaml_label(result.labels[result.seed])}" if result.seed is not None else None,
        "points:",
    ]
    for k, (label, alone) in enumerate(zip(result.labels, result.single, strict=True)):
        lines += [
            f"  - label: {_yaml_label(label)}",
            f"    p_HP: {_yaml_list(result.p_HP[k])}",
            f"    p_HP_sd_m: {_yaml_float(errors[2][k])}" if errors else None,
            f"    rms_m: {_yaml_float(result.rms[k])}",
            f"    weight: {_yaml_float(result.weights[k])}",
            f"    num_samples: {len(result.samples[k])}",
            "    samples: [" + ", ".join(str(int(i)) for i in result.samples[k]) + "]",
            f"    residuals_m: {_yaml_list(result.residuals[k])}",
            "    outliers: [" + ", ".join(str(int(i)) for i in outliers[k]) + "]",
            "    alone:",
            f"      verdict: {json.dumps(str(alone.verdict))}",
            f"      rms_m: {_yaml_float(alone.rms)}",
            f"      camera_offset_m: {_yaml_float(offsets[k, 0])}",
            f"      camera_offset_deg: {_yaml_float(math.degrees(offsets[k, 1]))}",
        ]
    return "\n".join(line for line in lines if line is not None) + "\n"
