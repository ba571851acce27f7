"""The paper's identification math (§3.1, §3.2, §3.4, §4.4) in pure numpy/scipy: no pydrake here.

- ``sustainable_identifier``: the constant-memory statistic, its eigen-solution and the verdict.
- ``rotation``: the §3.2 projection onto SO(3).
- ``eye_to_hand``: the one-point eye-to-hand formulation (N = 16), conditioning, refinement.
- ``eye_to_hand_points``: several points sharing one camera (joint refinement, the camera from
  known points, the camera after a turn).
- ``payload``: the static payload formulation (N = 5) and the wrench sign convention.
- ``payload_dynamic``: the dynamic payload formulation (N = 17: the ten inertial parameters and the
  wrench sensor's bias, from the Newton-Euler regressor); ``dynamic_observability`` its verdict's
  checks; ``rls`` the recursive least-squares baseline; ``differentiation`` the Savitzky-Golay
  filter that differentiates joint encoders.
- ``batch``: ``calibrate_eye_to_hand`` (one point), ``calibrate_eye_to_hand_points`` (several points
  at once) and ``identify_payload`` for recorded data.
- ``opencv_hand_eye``: OpenCV's hand-eye solvers fed for a fixed camera (the marker-based baseline).
- ``observability``: the checks that make a verdict honest on degenerate or mis-scaled data (what
  the motion determines, units and frames, agreement, uncertainty), their reasons, and covariances.
- ``errors``: ``IdentificationError`` (a ``ValueError``), the only exception the API raises for a
  bad argument (wrong type, shape or value; one-line message naming it), and its checks.
"""

from sustain_drake.identification.batch import (
    EyeToHandPointsResult,
    EyeToHandResult,
    PayloadResult,
    calibrate_eye_to_hand,
    calibrate_eye_to_hand_points,
    identify_payload,
)
from sustain_drake.identification.eye_to_hand import EyeToHandIdentifier
from sustain_drake.identification.payload import PayloadIdentifier
from sustain_drake.identification.sustainable_identifier import (
    ConvergenceCriteria,
    IdentificationError,
    SustainableIdentifier,
    Verdict,
)

__all__ = [
    "ConvergenceCriteria",
    "EyeToHandIdentifier",
    "EyeToHandPointsResult",
    "EyeToHandResult",
    "IdentificationError",
    "PayloadIdentifier",
    "PayloadResult",
    "SustainableIdentifier",
    "Verdict",
    "calibrate_eye_to_hand",
    "calibrate_eye_to_hand_points",
    "identify_payload",
]
