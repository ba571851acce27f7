"""``sustain-drake calibrate eye-to-hand``: offline calibration from recorded CSV data.

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
from sustain_drake.identification import ConvergenceCriteria, IdentificationError, calibrate_eye_to_hand
from sustain_drake.identification import eye_to_hand as eye_to_hand_formulation
from sustain_drake.recorded_data import (
    RecordedDataError,
    eye_to_hand_yaml,
    read_points_csv,
    read_poses_csv,
    rpy_degrees,
)

# A residual this many times the RMS is flagged (a mis-paired image and pose stands out so).
OUTLIER_FACTOR = 3.0


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
        help="camera pose in the world and a hand point, from one tracked point (paper §3.4)",
        description="Eye-to-hand calibration from a fixed camera's 3-D measurements of one point on the "
        "hand. CSV formats: see docs/identification.md (points: x,y,z in metres in the camera frame; poses: "
        "x,y,z,qw,qx,qy,qz or x,y,z,roll,pitch,yaw of the hand in the world).",
    )
    p.add_argument("--points", required=True, type=Path, help="CSV of the point in the camera frame (m)")
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
        p_C = read_points_csv(points)
        X_WH = read_poses_csv(poses)
    except RecordedDataError as e:
        raise CliError(str(e)) from None
    if len(p_C) != len(X_WH):
        raise CliError(
            f"{points} has {len(p_C)} samples but {poses} has {len(X_WH)}: rows must pair one to one"
        )
    if len(p_C) < criteria.min_samples:
        raise CliError(f"too few samples: {len(p_C)} rows, at least {criteria.min_samples} needed")
    try:
        result = calibrate_eye_to_hand(p_C, X_WH, criteria=criteria)
    except IdentificationError as e:
        raise CliError(str(e)) from None
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
    limit = OUTLIER_FACTOR * result.rms
    for i, r in enumerate(result.residuals, start=1):
        flag = "   <-- large: check this sample's pairing" if r > limit else ""
        w(f"  {i:4d}  {r * 1e3:8.3f}{flag}\n")


def _run_eye_to_hand(args: argparse.Namespace) -> int:
    return run_eye_to_hand(args.points, args.poses, args.out, _criteria(args),
                           camera_config=args.camera_config)
