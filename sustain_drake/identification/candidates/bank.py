"""What the candidates carry from frame to frame: ``Candidate``, ``Adoption``, ``CandidateBank`` (immutable,
held by a Drake system in an abstract state), the short history of hand poses, and a summary."""

import math
from dataclasses import dataclass, field, replace

import numpy as np

from sustain_drake.identification.coordination import NO_RESET
from sustain_drake.identification.eye_to_hand import (
    EyeToHandEstimate,
    EyeToHandIdentifier,
    EyeToHandSolution,
    pack_x,
)
from sustain_drake.identification.sustainable_identifier import ConvergenceCriteria, Verdict


@dataclass(frozen=True)
class Candidate:
    """One candidate tracked point: its feature id, its identifier's statistic and solution."""

    feature_id: int
    statistic: np.ndarray
    solution: EyeToHandSolution
    admitted: float  # s
    last_sample: float  # s, the last sample fed or held view seen again (admission time before any)
    last_p_CP: np.ndarray | None = None  # the last measured point (accepted or not), for the gate
    last_X_WH: np.ndarray | None = None
    verified_samples: int = 0  # its samples taken up to the last frame the adopted model was verified
    sampled_p_CP: np.ndarray | None = None  # the point of its last sample (``min_view_change``)
    frames: int = 1  # frames it was fed (a new view or a held one): the observation's counts
    # its samples' distinct views (``view_angle``; V x 12, ``admission.view_of``) and each view's
    # sums (V x 16, ``view_correlation.view_row``): a point's error repeats within a view, so the
    # cameras' 95 % regions count its samples as ``view_correlation.independent_samples``
    view_list: np.ndarray = field(default_factory=lambda: np.zeros((0, 12)))
    view_sums: np.ndarray = field(default_factory=lambda: np.zeros((0, 16)))
    # its point was centrally symmetric when admitted; False: anchored on its patch (a
    # second choice, ``fitting.FIRST_CHOICE_POINTS``) or not known
    symmetric: bool = False
    # the same samples' statistic with the pose of the hand's parent link (``FrameInput.X_WL``) in
    # place of the hand's: a point fixed on that link fits it better (``fitting.on_parent_link``);
    # None: that pose is not known
    parent_statistic: np.ndarray | None = None
    # whether its samples fit the hand better than the parent link when it first converged (None:
    # not judged)
    on_hand: bool | None = None


@dataclass(frozen=True)
class Adoption:
    """A leader chosen (what the state machine adopts): when, which feature, its statistic, the
    estimate, and how it was identified (``"identified"``: all 16 unknowns, the paper's verdict;
    ``"previous camera"``: the camera of the model abandoned at the last reset explains the
    candidate's samples, only its ``p_HP`` is new; after a camera move ``"scene turn, tool points
    kept"``, ``"tool points found by the scene turn"``, ``"previous tool points"``, ``"scene turn,
    points since the move"`` and ``"points since the move, near the scene turn"``, see
    ``camera_move_recovery``; ``track_consensus.KIND`` where tracks ended before any converged)."""

    time: float
    feature_id: int
    statistic: np.ndarray
    admitted: float  # s, when this candidate was admitted
    round_start: float  # s, when the first candidate of this identification round was admitted
    estimate: EyeToHandEstimate | None = None
    kind: str = "identified"
    rotation_lever: float = math.nan  # m, the smallest (``smallest_rotation_lever``) when identified
    # (m, rad): the adopted camera's 1 sd (``fitting.camera_sd`` of the fit that gave it), where
    # that fit has a covariance (identified, and the consensus of the tracks); None elsewhere
    camera_sd: tuple | None = None


@dataclass(frozen=True)
class CandidateBank:
    """Everything the candidates carry from frame to frame (immutable: ``step`` returns a new one,
    so a Drake context holding it clones safely).

    Attributes:
        candidates: in admission order.
        leader: feature id of the first candidate to converge since the last reset (-1: none).
        observed: feature id feeding the observation (the leader's, or a re-acquired one; -1).
        rejected: ids rejected since the last reset (only ids still tracked are kept).
        sample_count: samples since construction (never reset): frames that fed an identifier
            while there is no leader, then observations of the observed feature.
        sample_error: ``s_t`` of the newest observation sample, m^2.
        last_reset: the last reset value seen.
        last_frame: capture time of the last frame used, s.
        poses: recent hand poses ``(time, X_WH, X_WL)`` (``X_WL`` None when not known).
        adoptions: every leader chosen, in order.
        round_start: when the first candidate since the last reset was admitted (NaN: none yet).
        first_found: when the first candidate of the run was admitted (never reset; NaN: none yet).
    """

    candidates: tuple = ()
    leader: int = -1
    observed: int = -1
    rejected: frozenset = frozenset()
    sample_count: int = 0
    sample_error: float = math.inf
    last_reset: float = 0.0
    last_frame: float = -math.inf
    poses: tuple = ()
    adoptions: tuple = ()
    round_start: float = math.nan
    first_found: float = math.nan
    observed_last: tuple | None = None  # (p_CP, X_WH) of the observed feature's last frame
    observed_p_HP: np.ndarray | None = None  # the observed point in H when not the leader's own
    witness: int = -1  # a second observed feature (see ``observation.observe_primary``), -1: none
    witness_p_HP: np.ndarray | None = None
    witness_last: tuple | None = None
    primary_failures: int = 0  # consecutive samples the observed point alone violated
    adopted_mse: float = math.inf  # a^2 lambda_N of the leader when it was chosen, m^2
    previous_x: np.ndarray | None = None  # the model abandoned at the last reset (Eq. (36))
    archive: tuple = ()  # candidates whose track ended, kept for the joint refinement
    observers: tuple = ()  # extra observed points: (feature_id, p_HP, (p_CP, X_WH) of the last frame)
    refined_solution: EyeToHandSolution | None = None  # the latest refinement of the adopted model
    refinement: int = 0  # refinements offered since construction (never reset)
    sample_errors: tuple = ()  # this frame's s_t of the observed point and its witness (m^2)
    last_refinement: float = -math.inf  # s
    tool_observed: bool = False  # a tool point gave this frame's observation sample
    model_x: np.ndarray | None = None  # the adopted estimate while there is a leader (Eq. (36))
    known_points: tuple = ()  # after a camera move: (feature_id, p_HP) the abandoned model observed
    # the ids of those that are centrally symmetric corners: a new track is matched to a known point
    # by where it lies only if both are (a corner is the same mark of the pattern whichever track
    # finds it; an anchored point is wherever its track began)
    known_corners: frozenset = frozenset()
    moved_from_x: np.ndarray | None = None  # the model a camera move cleared (keep_tool_points)
    moved_at: float = math.nan  # s, when that reset came
    # s: the reset before the one that cleared that model; a scene turn that starts after it (and by
    # ``moved_at``) is the turn of that model's camera
    moved_since: float = -math.inf
    known_at: float = math.nan  # s: the reset that cleared the model the known points are from
    # the model the last reset that was not a camera move cleared, should a camera move be declared
    # before another leader (the tracks lost the move and the observation found it first)
    cleared: "ClearedModel | None" = None
    turn: object | None = None  # the static scene's turn across that move (``FrameInput.scene_turn``)
    turned_R_WC: np.ndarray | None = None  # that camera turned as the scene shows (None: too few anchors)
    # rad: the turn's 1 sd (``CameraAfterTurn.rotation_sd``); over ``MAX_TURN_ROTATION_SD`` the turned
    # camera only finds the known points again, and they give the camera's rotation themselves
    turn_rotation_sd: float = math.inf
    turned_p_WC: np.ndarray | None = None  # and where the scene's depth puts it (None: not known)
    reset_time: float = -math.inf  # s, when the last reset came
    last_reason: int = NO_RESET  # why that reset (``FrameInput.reset_reason``), as last seen
    more_motion: bool = False  # a leader was held back (lever or spread), none leads, one converged
    held_back: int = -1  # the feature id of the candidate held back (as above), -1: none

    def motion_wanted(self) -> float:
        """``CandidateIdentifiers``' ``more_motion``: 0 (none), 1 (more views of the candidates'
        points) or 2 (a converged candidate held back, ``held_back``: more points wanted too, from
        the detector's trials)."""
        if not self.more_motion:
            return 0.0
        return 2.0 if self.held_back >= 0 else 1.0

    def find(self, feature_id: int) -> Candidate | None:
        for c in self.candidates:
            if c.feature_id == feature_id:
                return c
        return None

    @property
    def shown(self) -> Candidate | None:
        """The candidate to report: the leader, else the one with the most samples."""
        if not self.candidates:
            return None
        leader = self.find(self.leader)
        if leader is not None:
            return leader
        return max(self.candidates, key=lambda c: c.solution.num_samples)


POSE_HISTORY = 8  # frames of hand poses kept (the image lags the encoders by one or two)


def empty_solution(criteria: ConvergenceCriteria | None = None) -> EyeToHandSolution:
    return EyeToHandIdentifier(criteria=criteria).solve(refine_estimate=False)


def record_pose(bank: CandidateBank, time: float, X_WH: np.ndarray,
                X_WL: np.ndarray | None = None) -> CandidateBank:  # fmt: skip
    """Adds the hand pose (and its parent link's, ``X_WL``; None: not known) at ``time`` to the
    short history."""
    X_WL = None if X_WL is None else np.array(X_WL, dtype=float)
    poses = (bank.poses + ((float(time), np.array(X_WH, dtype=float), X_WL),))[-POSE_HISTORY:]
    return replace(bank, poses=poses)


def poses_at(bank: CandidateBank, time: float, tolerance: float) -> tuple | None:
    """The recorded ``(X_WH, X_WL)`` nearest ``time`` if within ``tolerance`` s, else None."""
    best, best_dt = None, tolerance
    for t, X_WH, X_WL in bank.poses:
        dt = abs(t - time)
        if dt <= best_dt:
            best, best_dt = (X_WH, X_WL), dt
    return best


def pose_at(bank: CandidateBank, time: float, tolerance: float) -> np.ndarray | None:
    """The recorded hand pose nearest ``time`` if within ``tolerance`` s, else None."""
    found = poses_at(bank, time, tolerance)
    return None if found is None else found[0]


@dataclass(frozen=True)
class ClearedModel:
    """A model a reset cleared: its estimate ``x`` (``pack_x``), its points ``(feature_id, p_HP)``
    with the ``corners`` among them (``camera_move_recovery.model_points``), the reset before the
    one that cleared it (``since``, s) and that reset's time (``at``, s)."""

    x: np.ndarray
    points: tuple
    corners: frozenset
    since: float
    at: float


@dataclass(frozen=True)
class BankSummary:
    """A small view of the bank for outputs and logs."""

    num_candidates: int
    leader: int
    observed: int
    feature_ids: tuple = field(default_factory=tuple)


def summary(bank: CandidateBank) -> BankSummary:
    return BankSummary(len(bank.candidates), bank.leader, bank.observed,
                       tuple(c.feature_id for c in bank.candidates))


def with_camera(c: Candidate, x_previous: np.ndarray, p_HP: np.ndarray, mse: float,
                 verdict: str = "converged: the previous camera explains the samples, p_HP re-identified",
                 ) -> Candidate:  # fmt: skip
    """The candidate with the converged solution "the camera of ``x_previous`` and this p_HP"."""
    R_WC, p_WC = x_previous[0:9].reshape(3, 3, order="F"), x_previous[9:12]
    estimate = EyeToHandEstimate(R_WC, p_WC.copy(), p_HP, pack_x(R_WC, p_WC, p_HP), mse)
    verdict = Verdict(True, verdict)
    solution = replace(c.solution, projected=estimate, refined=estimate, expected_mse=mse, verdict=verdict)
    return replace(c, solution=solution)


def mark_verified(bank: CandidateBank) -> CandidateBank:
    """Every candidate's samples so far were taken while the model was verified (``verified_overlap``)."""
    return replace(bank, candidates=tuple(c if c.verified_samples == c.frames
                                          else replace(c, verified_samples=c.frames)
                                          for c in bank.candidates))
