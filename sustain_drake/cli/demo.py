"""``sustain-drake demo``: what ``make demo`` runs.

Step 1 calibrates a real fixed 3-D camera against a chessboard corner on a robot's flange (the
Jin et al. data set bundled as a test fixture) with the offline eye-to-hand calibration, and writes
the YAML result.

Step 2 simulates a few seconds of the hand-eye world (``diagrams/hand_eye.yaml``, headless) and
says where its Meshcat replay is.
"""

from __future__ import annotations

from pathlib import Path

from sustain_drake.cli.calibrate import run_eye_to_hand
from sustain_drake.cli.common import CliError
from sustain_drake.experiments.run import RunError, simulate_file
from sustain_drake.identification import eye_to_hand
from sustain_drake.station import ScenarioError

REPO = Path(__file__).resolve().parents[2]
REAL_DATA = REPO / "tests" / "data" / "jin_eyetobase_rvc_single"
SIMULATED_SECONDS = 5.0


def register(subparsers) -> None:
    p = subparsers.add_parser("demo", help="run the demo (offline calibration on bundled real data)")
    p.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder (default %(default)s)")
    p.set_defaults(handler=run)


def run(args) -> int:
    if not REAL_DATA.is_dir():
        raise CliError(f"demo data not found at {REAL_DATA}: run the demo from a source checkout")
    print("== 1. Offline eye-to-hand calibration on real data (Jin et al., RVC-X camera, Jaka Zu7 arm)")
    code = run_eye_to_hand(
        REAL_DATA / "corner_points.csv",
        REAL_DATA / "poses.csv",
        args.out / "calibration.yaml",
        eye_to_hand.default_criteria(),
    )
    print(f"== 2. {SIMULATED_SECONDS:g} simulated seconds of the hand-eye world "
          "(diagrams/hand_eye.yaml, headless)")
    try:
        result = simulate_file(REPO / "diagrams" / "hand_eye.yaml", out=args.out / "simulation",
                               duration=SIMULATED_SECONDS)
    except (ScenarioError, RunError) as e:
        raise CliError(str(e)) from None
    print(f"simulated in {result.wall:.1f} s ({result.realtime_factor:.1f}x real time); "
          f"logs: {result.log}")
    print(f"open the replay in a browser: {result.replay}")
    return code
