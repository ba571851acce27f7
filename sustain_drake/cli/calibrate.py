"""``sustain-drake calibrate eye-to-hand``: offline calibration from recorded CSV data.

One point (points file ``x,y,z``) or several fitted jointly (``sample,point,x,y,z``).

Exit codes: 0 converged, 2 bad input (one line on stderr), 3 not converged (the reason on stderr;
no YAML is written then, so an earlier good result is never overwritten by a bad one). The output
paths are checked (writable, distinct, none of them an input) before anything is read, and every
output is written atomically.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from sustain_drake.calibration_export import CalibrationExportError, camera_config_yaml
from sustain_drake.cli.common import EXIT_NOT_CONVERGED, EXIT_OK, CliError
from sustain_drake.files import OutputPathError, check_output_paths, write_atomically
from sustain_drake.identification import (
    ConvergenceCriteria,
    IdentificationError,
    calibrate_eye_to_hand,
    calibrate_eye_to_hand_points,
)
from sustain_drake.identification import eye_to_hand as eye_to_hand_formulation
from sustain_drake.identification.batch import MIN_POINT_SAMPLES, OUTLIER_FACTOR, EyeToHandPointsResult
from sustain_drake.recorded_data import (
    PointTracks,
    RecordedDataError,
    eye_to_hand_yaml,
    left_out_text,
    read_point_tracks_csv,
    read_poses_csv,
    rpy_degrees,
)

# The convergence criteria (paper §3.1 (a)-(c)) as options: flag, type, ConvergenceCriteria field, help.
CRITERIA_FLAGS = (
    ("--max-rms", float, "max_expected_rms", "criterion (a): largest expected RMS error, m"),
    ("--min-gap", float, "min_gap_ratio", "criterion (b): smallest lambda_15/lambda_16"),
    ("--max-ssd", float, "max_ssd", "criterion (c): largest SSD to a rotation"),
    ("--min-samples", int, "min_samples", "fewest samples"),
)


def register(subparsers) -> None:
    calibrate = subparsers.add_parser("calibrate", help="calibrate from recorded data")
    kinds = calibrate.add_subparsers(dest="kind", required=True)
    p = kinds.add_parser(
        "eye-to-hand",
        help="camera pose in the world and hand points, from tracked points (paper §3.4)",
        description="Eye-to-hand calibration from a fixed camera's 3-D measurements of one or several "
        "points fixed on the hand. CSV formats: see docs/identification.md (points: x,y,z in metres in the "
        "camera frame, row i = sample i, or sample,point,x,y,z for several points, sample = 0-based row of "
        "the poses; poses: x,y,z,qw,qx,qy,qz or x,y,z,roll,pitch,yaw of the hand in the world).",
    )
    p.add_argument("--points", required=True, type=Path,
                   help="CSV of the point(s) in the camera frame (m): x,y,z or sample,point,x,y,z")
    p.add_argument(
        "--poses", required=True, type=Path, help="CSV of the hand poses X_WH (m, quaternion or rpy)"
    )
    p.add_argument("--out", type=Path, help="write the result as YAML (Drake Transform: m, rpy in deg)")
    p.add_argument("--camera-config", type=Path,
                   help="also write X_WC as a Drake CameraConfig YAML (X_PB in the world)")
    defaults = eye_to_hand_formulation.default_criteria()
    for flag, kind, field, text in CRITERIA_FLAGS:
        p.add_argument(flag, type=kind, default=getattr(defaults, field), dest=field,
                       help=f"{text} (default %(default)s)")
    p.set_defaults(handler=_run_eye_to_hand)


def _criteria(args) -> ConvergenceCriteria:
    for flag, kind, field, _ in CRITERIA_FLAGS:
        value = getattr(args, field)
        if kind is float and value is not None and not math.isfinite(value):
            raise CliError(f"{flag} must be a finite number, got {value}")
    try:
        return ConvergenceCriteria(
            **{field: getattr(args, field) for _, _, field, _ in CRITERIA_FLAGS},
        )
    except ValueError as e:
        raise CliError(str(e)) from None


def run_eye_to_hand(
    points: Path,
    poses: Path,
    out: Path | None,
    criteria: ConvergenceCriteria,
    stream=None,
    camera_config: Path | None = None,
) -> int:
    """Reads, calibrates, prints and (if converged) writes the YAML result and, if asked, the
    camera pose as a Drake ``CameraConfig``. Returns the exit code. ``stream``: where to print
    (default: the standard output when called, not when imported)."""
    stream = sys.stdout if stream is None else stream
    try:
        check_output_paths({"--out": out, "--camera-config": camera_config},
                           {"--points": points, "--poses": poses})  # fmt: skip
    except OutputPathError as e:
        raise CliError(str(e)) from None
    try:
        X_WH = read_poses_csv(poses)
        tracks = read_point_tracks_csv(points, num_samples=len(X_WH))
    except RecordedDataError as e:
        raise CliError(str(e)) from None
    try:
        result = _calibrate(tracks, X_WH, points, poses, criteria)
    except IdentificationError as e:
        raise CliError(str(e)) from None
    if isinstance(result, EyeToHandPointsResult):
        print_eye_to_hand_points(result, points, poses, stream)
    else:
        print_eye_to_hand(result, points, poses, stream)
    if not result.converged:
        print(f"sustain-drake: {result.verdict}", file=sys.stderr)
        for path in (out, camera_config):
            if path is not None:
                print(f"{path} not written (not converged)", file=stream)
        return EXIT_NOT_CONVERGED
    # Every text is made (and every path was checked) before any file is written.
    texts = {}
    if out is not None:
        texts[out] = eye_to_hand_yaml(result, str(points), str(poses))
    if camera_config is not None:
        try:
            texts[camera_config] = camera_config_yaml(result.X_WC, name="calibrated_camera")
        except CalibrationExportError as e:
            raise CliError(f"the calibrated pose cannot be exported: {e}") from None
    for path, text in texts.items():
        try:
            write_atomically(path, text)
        except OSError as e:
            raise CliError(f"{path}: cannot write: {e.strerror or e}") from None
        print(f"wrote {path}", file=stream)
    return EXIT_OK


def _calibrate(tracks: PointTracks, X_WH: np.ndarray, points: Path, poses: Path,
               criteria: ConvergenceCriteria):  # fmt: skip
    """The calibration of the points read: one point of an ``x,y,z`` file (its rows are the poses'),
    or every point of a ``sample,point,x,y,z`` file jointly."""
    if tracks.left_out:
        print(f"sustain-drake: warning: left out (fewer than {MIN_POINT_SAMPLES} samples; "
              f"a typo in a label?): {left_out_text(tracks.left_out)}", file=sys.stderr)
    if tracks.labelled:
        seen = np.unique(np.concatenate([s for s, _ in tracks.points.values()])) if tracks.points else ()
        if len(seen) < criteria.min_samples:
            raise CliError(f"too few samples: {len(seen)} poses with a point, at least "
                           f"{criteria.min_samples} needed")  # fmt: skip
        return calibrate_eye_to_hand_points(tracks.points, X_WH, criteria=criteria)
    (_, p_C), = tracks.points.values()
    if len(p_C) != len(X_WH):
        raise CliError(
            f"{points} has {len(p_C)} samples but {poses} has {len(X_WH)}: rows must pair one to one"
        )
    if len(p_C) < criteria.min_samples:
        raise CliError(f"too few samples: {len(p_C)} rows, at least {criteria.min_samples} needed")
    return calibrate_eye_to_hand(p_C, X_WH, criteria=criteria)


def print_eye_to_hand(result, points, poses, stream) -> None:
    w = stream.write
    n = len(result.residuals)
    w(f"Eye-to-hand calibration (paper §3.4) of {n} samples\n  points: {points}\n  poses:  {poses}\n")
    w(f"verdict: {result.verdict}\n")
    if result.refined is None or not result.converged:
        return  # never a camera (nor residuals under one) from data the verdict refuses
    X = result.X_WC
    w("camera pose in the world, X_WC:\n")
    w("  translation [m]:  " + "  ".join(f"{v:+.6f}" for v in X[:3, 3]) + "\n")
    w("  rpy [deg]:        " + "  ".join(f"{v:+.4f}" for v in rpy_degrees(X[:3, :3])) + "\n")
    w("point in the hand, p_HP [m]: " + "  ".join(f"{v:+.6f}" for v in result.p_HP) + "\n")
    if result.standard_errors is not None:
        rotation, position, point = result.standard_errors
        w(f"1 sd (Gauss-Newton's covariance, RMS of the 3-D error): camera position {position * 1e3:.3f} mm, "
          f"camera rotation {math.degrees(rotation):.4f} deg, p_HP {point * 1e3:.3f} mm\n")
    proj = result.projected
    dp = np.linalg.norm(proj.p_WC - X[:3, 3]) * 1e3
    w(
        f"residual RMS: {result.rms * 1e3:.3f} mm (the identification expected "
        f"{result.expected_rms * 1e3:.3f} mm; Gauss-Newton moved the camera {dp:.2f} mm from the "
        "projected TLS estimate)\n"
    )
    lam = result.eigenvalues
    w(f"eigenvalue gap lambda_15/lambda_16: {result.gap_ratio:.4g}   SSD to a rotation: {result.ssd:.3g}\n")
    w("lambda_13..lambda_16: " + "  ".join(f"{v:.4g}" for v in lam[-4:]) + "\n")
    w("per-sample residuals [mm]:\n")
    numbers = np.arange(1, len(result.residuals) + 1)
    _write_residuals(w, numbers, result.residuals, numbers[result.residuals > OUTLIER_FACTOR * result.rms])


def _write_residuals(w, numbers, residuals, flagged) -> None:
    """One line per sample (its number, its residual in mm), the ``flagged`` numbers marked."""
    flagged = set(np.asarray(flagged).tolist())
    for i, r in zip(np.asarray(numbers).tolist(), residuals, strict=True):
        flag = "   <-- large: check this sample's pairing" if i in flagged else ""
        w(f"  {i:4d}  {r * 1e3:8.3f}{flag}\n")


def print_eye_to_hand_points(result: EyeToHandPointsResult, points, poses, stream) -> None:
    w = stream.write
    w(f"Eye-to-hand calibration (paper §3.4 per point, then jointly) of {len(result.labels)} points fixed on "
      f"the hand over {result.num_samples} samples\n  points: {points}\n  poses:  {poses}\n")
    w(f"verdict: {result.verdict}\n")
    if not result.converged:  # no camera; each point's own verdict says what it lacks alone
        for label, alone in zip(result.labels, result.single, strict=True):
            w(f"  point {label!r} alone: {alone.verdict}\n")
        return
    X = result.X_WC
    w("camera pose in the world, X_WC (every point jointly):\n")
    w("  translation [m]:  " + "  ".join(f"{v:+.6f}" for v in X[:3, 3]) + "\n")
    w("  rpy [deg]:        " + "  ".join(f"{v:+.4f}" for v in rpy_degrees(X[:3, :3])) + "\n")
    rotation, position, point_errors = result.standard_errors
    w(f"1 sd (Gauss-Newton's covariance, RMS of the 3-D error): camera position {position * 1e3:.3f} mm, "
      f"camera rotation {math.degrees(rotation):.4f} deg\n")
    w(f"started from point {result.labels[result.seed]!r} alone (its camera the best determined); each point "
      "weighted by the inverse of its residual variance\n")
    w("per point: p_HP, its 1 sd and RMS under the joint camera; 'alone': its own fit's RMS and how far its "
      "camera is from the joint one\n")
    w(f"  {'point':<12} {'samples':>7} {'RMS mm':>8} {'weight':>8}   {'p_HP [m]':<30} {'1 sd mm':>7}   "
      f"{'alone: RMS mm':>13} {'off mm':>9} {'off deg':>7}\n")
    offsets = result.single_offsets()
    for k, label in enumerate(result.labels):
        p = "  ".join(f"{v:+.6f}" for v in result.p_HP[k])
        w(f"  {str(label):<12} {len(result.samples[k]):>7} {result.rms[k] * 1e3:>8.3f} "
          f"{result.weights[k]:>8.3g}   {p:<30} {point_errors[k] * 1e3:>7.3f}   "
          f"{result.single[k].rms * 1e3:>13.3f} {offsets[k, 0] * 1e3:>9.2f} "
          f"{math.degrees(offsets[k, 1]):>7.3f}\n")
    for k, (label, flagged) in enumerate(zip(result.labels, result.outliers(), strict=True)):
        w(f"per-sample residuals [mm] of point {label!r} (sample: the poses' row, from 0):\n")
        _write_residuals(w, result.samples[k], result.residuals[k], flagged)


def _run_eye_to_hand(args: argparse.Namespace) -> int:
    return run_eye_to_hand(args.points, args.poses, args.out, _criteria(args),
                           camera_config=args.camera_config)
