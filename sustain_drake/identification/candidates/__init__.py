"""Candidate tracked points for eye-to-hand identification (paper Fig. 7, §4.3), pure numpy.

The paper runs one sustainable identifier per candidate corner that the coincidence detector
marks as body, and adopts the first one to converge. A corner on another link than the hand
does not satisfy Eq. (30) (its point is not fixed in H), so its residual stays large and its
verdict never says converged: the hand formulation is itself a filter.

This package is the bookkeeping, as a pure function of a ``CandidateBank`` (held by a Drake
system in an abstract state): ``step(bank, params, criteria, frame)`` once per tick, ``frame`` a
``FrameInput``. Its modules:

- ``params``: ``CandidateParams``, the settings (the ``hand_eye.candidates`` scenario section);
- ``bank``: ``Candidate``, ``Adoption``, ``CandidateBank`` and the short history of hand poses
  (``PoseHistory``: the image is older than the encoders by a frame or two, and at 0.4 m/s a frame
  is 1.3 cm, so each candidate is fed the hand pose ``X_WH`` at the frame's capture time);
- ``frame``: ``FrameInput`` (the step's input) and the new frame's features ready for use;
- ``fitting``: a candidate's statistic against a camera (its own best ``p_HP``, its error, how much
  the hand turned), the joint refinement of one camera with several points;
- ``admission``: admission (body features with a valid 3-D point, oldest track first, at most
  ``max_candidates`` at a time), feeding, the motion gate, loss and rejection;
- ``leader``: the first candidate whose verdict says converged (the smallest expected error if
  several converge on the same frame) is the leader until the next reset; its solution is refined
  (Gauss-Newton) and it is what a ``CoordinationStateMachine`` adopts;
- ``observation``: once there is a leader, its feature (the *observed* feature) gives one ``s_t``
  per frame under the reference (adopted) estimate. When the observed feature is lost, the body
  feature nearest to where the adopted estimate puts the tracked point (within
  ``reacquire_radius``) takes its place, so a re-seeded track of the same point keeps the
  observation going; beyond the paper, the depth image checks the adopted tool point every frame
  (``free_space_radius``): a surface seen behind where the model puts it is a violation, tracked
  points or not (and never evidence for the model);
- reset (``step``): a new reset value (a change was detected: the tool slipped or the camera moved)
  drops every candidate; identification starts again from the body features seen then, unless the
  abandoned model's camera explains a new point (``slip_recovery``, ``keep_camera``: a slip) or,
  after a camera move, the points it observed still fit one new camera with their ``p_HP``
  (``camera_move_recovery``, ``keep_tool_points``); where tracks end before any converges (a person
  walking between), the points since the reset give the camera together (``track_consensus``).
"""

from sustain_drake.identification.candidates import (
    admission,
    bank,
    camera_move_recovery,
    fitting,
    frame,
    leader,
    observation,
    params,
    slip_recovery,
    track_consensus,
)
from sustain_drake.identification.candidates.admission import within_motion_gate
from sustain_drake.identification.candidates.bank import (
    POSE_HISTORY,
    Adoption,
    BankSummary,
    Candidate,
    CandidateBank,
    empty_solution,
    pose_at,
    record_pose,
    summary,
)
from sustain_drake.identification.candidates.fitting import (
    STITCH_MAX_INCREASE,
    best_p_HP_given_camera,
    mean_squared_error_of,
    own_fit,
    points_in_camera,
    predicted_p_CP,
    rotation_spread,
    smallest_rotation_lever,
    stitch,
    x_is_set,
)
from sustain_drake.identification.candidates.frame import FrameInput
from sustain_drake.identification.candidates.params import CandidateParams
from sustain_drake.identification.candidates.step import step

__all__ = [
    "POSE_HISTORY",
    "STITCH_MAX_INCREASE",
    "Adoption",
    "BankSummary",
    "Candidate",
    "CandidateBank",
    "CandidateParams",
    "FrameInput",
    "admission",
    "bank",
    "best_p_HP_given_camera",
    "camera_move_recovery",
    "empty_solution",
    "fitting",
    "frame",
    "leader",
    "mean_squared_error_of",
    "observation",
    "own_fit",
    "params",
    "points_in_camera",
    "pose_at",
    "predicted_p_CP",
    "record_pose",
    "rotation_spread",
    "slip_recovery",
    "smallest_rotation_lever",
    "stitch",
    "step",
    "summary",
    "track_consensus",
    "within_motion_gate",
    "x_is_set",
]
