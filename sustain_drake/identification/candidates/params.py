"""The candidate identifiers' settings: ``CandidateParams``, the ``hand_eye.candidates`` scenario section."""

# No "from __future__ import annotations": yaml_load_typed reads CandidateParams' real field types.

import math
from dataclasses import dataclass


@dataclass
class CandidateParams:
    """Bookkeeping thresholds of the candidate identifiers (SI units).

    ``p_HP`` is a candidate's tracked point in the hand frame H. A candidate *fits* a camera when
    its samples, under that camera and its own best ``p_HP``, have an RMS error at most
    ``observe_consistency`` times the adopted model's. Counts are samples (frames a point is tracked;
    with ``min_view_change``, those that fit a camera count views); a 0, False or inf turns off a
    rule that goes beyond the paper.
    """

    max_candidates: int = 8  # count: identifiers run at a time, one per candidate tracked point
    # m: farthest a tracked point on the hand or its tool lies from the hand origin (motion gate)
    max_hand_radius: float = 0.6
    gate_margin: float = 0.01  # m added to the motion gate's bound: the depth noise of two frames
    max_lost_time: float = 2.0  # s without a sample before a candidate's slot is freed
    # s after admission before a candidate that has not converged is rejected (until a reset)
    max_unconverged_time: float = 30.0
    # m: a body feature this near the adopted prediction takes over a lost observed feature
    reacquire_radius: float = 0.01
    # s: the most the nearest hand pose's time may differ from a frame's capture time
    pose_tolerance: float = 0.01
    # m: a candidate with min_samples whose expected RMS error exceeds this is rejected (not on the hand)
    reject_rms: float = 0.02
    # also admit features in body cells, after body features (the fit rejects the background among them)
    use_body_cells: bool = True
    # m over the motion gate: an observed point jumping more in a frame is a lost track (re-acquired)
    observation_jump: float = 0.15
    # count: samples a candidate needs to take over a lost observation, witness or observe
    observe_min_samples: int = 100
    # ratio: a candidate fits a camera when its RMS error is within this times the adopted one's
    observe_consistency: float = 3.0
    # count: samples the observed point alone violates the allowable error before its witness replaces it
    primary_failures: int = 10
    # after a reset, a candidate that fits the old camera leads at once with it (a slip moves only p_HP)
    keep_camera: bool = True
    # count: samples to lead with the kept camera when the static scene shows the camera unmoved
    # since before the reset; only p_HP (3 unknowns) is new then. Else observe_min_samples, and the
    # points since the reset must pin the camera to camera_accuracy (``slip_recovery``)
    keep_camera_min_samples: int = 100
    # a converged candidate leads only if another one fits its camera (one track can fit a wrong camera)
    confirm_with_witness: bool = True
    # rad the hand turns over a candidate's samples before it can fit a camera (a translation fits any)
    min_rotation_spread: float = 0.15
    # refine the leader's camera jointly with all candidates that fit it (the paper uses one point)
    joint: bool = False
    joint_min_samples: int = 30  # count: samples a candidate needs to join the joint refinement
    # ratio: a candidate joins the joint refinement if its RMS error is within this times the leader's
    joint_consistency: float = 3.0
    # weight each point's samples by its inverse mean squared error (maximum likelihood); False: equal
    joint_weighted: bool = False
    # count: ended tracks kept for the joint refinement (still valid constraints), most samples first
    max_archived: int = 16
    max_observers: int = 0  # count: fitting points observed besides the observed point and its witness
    # s between joint refinements of the adopted camera while observing; 0: the paper's fixed model
    refine_interval: float = 0.0
    # m: a witness, observer or hand-over lies within this of the adopted tool point in H (on the
    # tool: a gripper point does not move when the tool slips); inf: anywhere on the hand
    observe_radius: float = math.inf
    # count: samples a candidate needs to be checked on frames with no observed point; 0: off, the paper's
    blind_min_samples: int = 0
    # m: joint-refinement tracks whose p_HP lie this close are one point (summed); 0: one point per track
    stitch_radius: float = 0.0
    # count: samples, taken while the adopted model is verified, that a candidate needs to witness,
    # observe or take over: a point learned blind would re-learn the tool point and hide a slip; 0: off
    verified_overlap: int = 0
    # on a blind frame, a tool candidate that fits but lacks verified_overlap is a sample over the
    # allowable error: the held tool point can no longer be checked; False: no sample
    unverified_evidence: bool = False
    # a kept-camera model's expected error is capped at that of the identification that found
    # the camera, so a worse fit does not widen the allowable error; False: its own error
    keep_allowable_error: bool = False
    # m: radius of the depth check of the adopted tool point (the camera must see no surface behind
    # it; the gap squared joins the frame's sample): a slip shows even with no point tracked; 0: off
    free_space_radius: float = 0.0
    # after a camera-move reset, the abandoned model's points keep their p_HP (a moved camera leaves
    # the held tool unchanged) and give the new camera in closed form (6 unknowns, not 15)
    keep_tool_points: bool = False
    # m: RMS distance from a line the known points' camera-frame samples need (keep_tool_points):
    # a p_HP error e turns the new camera by about e over this spread
    min_point_spread: float = 0.06
    # m: after the scene's turn, a new track matches the known point within this of its p_HP; the
    # rod's marks lie 15-20 mm apart, so only one mark lies within twice this
    turn_radius: float = 0.004
    # m: largest camera shift searched when matching new tracks to known points after a turn
    turn_max_shift: float = 0.03
    # count: samples each known point needs before the camera after a turn is solved
    turn_min_samples: int = 15
    # m: window around the scene's camera shift where the common offset is sought (below a mark spacing)
    turn_scene_shift: float = 0.01
    # after a turn, also admit tracks near where the turned camera sees a known point, body or not:
    # after a camera move the detector's body cells hold the static scene
    turn_admit_known: bool = False
    # rad (the hand's turn plus the ray's) between a point's distinct views: the cameras' 95 % regions
    # count its samples by how much of its error repeats within a view; 0: every sample independent
    view_angle: float = 0.0
    # m a point must move in the camera frame before its next sample; 0: every frame, the paper's.
    # Measurement errors repeat with the view, so held views would otherwise outweigh the others
    min_view_change: float = 0.0
    # m: least rotation lever of a converged leader's points before adoption (it waits for motion); 0: off
    min_rotation_lever: float = 0.0
    # rad the hand must turn over a converged leader's samples for adoption (the camera's
    # rotation shows only as the hand turns); it waits for motion while its point is seen; 0: off
    min_adopt_rotation_spread: float = 0.0
    # count: samples of a candidate after which more motion is asked for until the first
    # identification: the rotation is pinned only as the hand moves; 0: off
    motion_min_samples: int = 0
    # m and rad: the accuracy the robot needs of the camera; a leader is adopted only when its
    # camera's 95 % region (the joint fit's own covariance, ``fitting.within_accuracy``) lies
    # within both, else it waits for views (a count of samples does not know the views); inf: off
    camera_accuracy: float = math.inf
    camera_rotation_accuracy: float = math.inf

    def __post_init__(self):
        counts = (self.observe_min_samples, self.keep_camera_min_samples, self.primary_failures,
                  self.joint_min_samples, self.turn_min_samples)
        if not (min(counts) >= 1 and self.max_archived >= 0 and self.max_observers >= 0
                and self.blind_min_samples >= 0 and self.verified_overlap >= 0
                and self.motion_min_samples >= 0):
            raise ValueError("observe_min_samples, keep_camera_min_samples, primary_failures, "
                             "joint_min_samples and turn_min_samples must be >= 1; max_archived, "
                             "max_observers, blind_min_samples, verified_overlap and motion_min_samples "
                             f">= 0 ({self})")
        if not self.max_candidates >= 1:
            raise ValueError(f"max_candidates must be >= 1, got {self.max_candidates}")
        if not self.observe_radius > 0:
            raise ValueError(f"observe_radius must be positive, got {self.observe_radius}")
        if not (self.stitch_radius >= 0 and math.isfinite(self.stitch_radius)):
            raise ValueError(f"stitch_radius must be >= 0, got {self.stitch_radius}")
        for name in ("refine_interval", "free_space_radius", "min_view_change", "min_rotation_lever",
                     "min_adopt_rotation_spread", "view_angle"):
            value = getattr(self, name)
            if not (value >= 0 and math.isfinite(value)):
                raise ValueError(f"{name} must be >= 0, got {value}")
        for name in ("max_hand_radius", "gate_margin", "max_lost_time", "max_unconverged_time",
                     "reacquire_radius", "pose_tolerance", "reject_rms", "observation_jump",
                     "joint_consistency", "min_rotation_spread", "min_point_spread", "turn_radius",
                     "turn_max_shift", "turn_scene_shift"):
            value = getattr(self, name)
            if not (value > 0 and math.isfinite(value)):
                raise ValueError(f"{name} must be a positive number, got {value}")
        for name in ("camera_accuracy", "camera_rotation_accuracy"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive (inf: off), got {getattr(self, name)}")
