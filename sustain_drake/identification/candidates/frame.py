"""One tick's input to ``step`` (``FrameInput``) and the new frame's features made ready for use
(``SeenFrame``)."""

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sustain_drake.identification.candidates.params import CandidateParams
from sustain_drake.identification.coordination import NO_RESET


@dataclass(frozen=True)
class FrameInput:
    """What ``step`` takes each tick besides the bank, the settings and the convergence criteria."""

    time: float  # s, now
    # the reset input; a value different from the last one seen drops every candidate
    reset: float
    X_WH: np.ndarray  # the hand pose now (4 x 4)
    frame_time: float  # s, the capture time of the features below
    ids: np.ndarray  # per tracked feature (the same order below): its id
    p_CP: np.ndarray  # per tracked feature: its point in the camera frame, m
    valid: np.ndarray  # per tracked feature: whether the point is measured
    on_body: np.ndarray  # per tracked feature: whether the feature is body
    # the adopted estimate (Eq. (36)); zeros or None while there is none. ``s_t`` of the observed
    # feature is computed under it (under the leader's own estimate if unset)
    reference_x: np.ndarray | None = None
    forgetting_factor: float = 1.0  # the identifiers' forgetting factor
    # per tracked feature, whether it lies in a body cell (None: no such candidates)
    in_body_cell: np.ndarray | None = None
    # m^2: the state machine's sigma, to tell a tracking failure of the observed point from a
    # change of the body (inf: never)
    allowable_error: float = math.inf
    # this frame's depth check (``free_space_radius``): for a point in the camera frame, how far
    # behind it the camera sees a surface, m (NaN: cannot tell). None: no depth image for this frame
    depth_gap: Callable[[np.ndarray], float] | None = None
    # the static scene's correspondences across the last camera move (a
    # ``perception.camera_motion.SceneTurn``: ``move``, ``start``, ``time``, ``b0``, ``q0``, ``b1``),
    # or None. Used with ``keep_tool_points`` when the move it belongs to (its episode began before
    # the reset that cleared the model and ended after) cleared the model: the camera is then the
    # old one turned, its position from the tool points
    scene_turn: object | None = None
    # s since when the static scene has been judged still (a ``CameraMotionDetector``'s; inf: not
    # known): if since before the last reset, the camera did not move and the kept camera leads
    # with ``keep_camera_min_samples``
    scene_still_since: float = math.inf
    # why that reset (``coordination.OBSERVATION_FAILED`` or ``CAMERA_MOVED``; ``NO_RESET`` when not
    # known): after a camera move the model's camera is dropped and, with ``keep_tool_points``, its
    # tool points are kept; after any other reset the model (``reference_x``) is kept as the
    # previous camera that a slipped tool leaves in place
    reset_reason: int = NO_RESET
    # per tracked feature, whether its point is centrally symmetric (``TrackedFeatures.symmetric``):
    # such points are preferred to those anchored on their patch (None, or a length other
    # than ids': not known, no point is)
    symmetric: np.ndarray | None = None
    # the pose now (4 x 4) of the hand's parent link L: the body the hand's last moving joint turns
    # it on (``fitting.on_parent_link``: a point fixed on L near that joint's axis moves almost
    # like the hand). None: not known
    X_WL: np.ndarray | None = None


@dataclass(frozen=True)
class SeenFrame:
    """A new frame's features as arrays, with the hand pose at its capture time."""

    given: FrameInput
    X_WH: np.ndarray  # the hand pose at the frame's capture time (4 x 4), not ``given.X_WH``
    ids: np.ndarray  # int64
    p_CP: np.ndarray  # N x 3, m
    usable: np.ndarray  # measured, finite points
    on_body: np.ndarray
    in_body_cell: np.ndarray  # all False without ``use_body_cells``
    body: np.ndarray  # on_body | in_body_cell
    row: dict  # feature id -> its row
    symmetric: np.ndarray  # usable and centrally symmetric (all False when not known)
    X_WL: np.ndarray | None = None  # the parent link's pose at the capture time (None: not known)

    @property
    def time(self) -> float:
        """The frame's capture time, s."""
        return self.given.frame_time

    @classmethod
    def of(cls, given: FrameInput, X_WH: np.ndarray, params: CandidateParams,
           X_WL: np.ndarray | None = None) -> "SeenFrame":
        ids = np.asarray(given.ids, np.int64).ravel()
        p_CP = np.asarray(given.p_CP, dtype=float).reshape(-1, 3)
        usable = np.asarray(given.valid, bool).ravel() & np.all(np.isfinite(p_CP), axis=1)
        on_body = np.asarray(given.on_body, bool).ravel()
        in_body_cell = (np.zeros_like(on_body) if given.in_body_cell is None or not params.use_body_cells
                        else np.asarray(given.in_body_cell, bool).ravel())
        row = {int(i): k for k, i in enumerate(ids)}
        symmetric = (np.zeros_like(usable) if given.symmetric is None or len(given.symmetric) != len(ids)
                     else np.asarray(given.symmetric, bool).ravel() & usable)
        return cls(given, X_WH, ids, p_CP, usable, on_body, in_body_cell, on_body | in_body_cell, row,
                   symmetric, X_WL)


@dataclass(frozen=True)
class Pool:
    """The candidates as a new frame leaves them while ``step`` works on it (not kept in the bank)."""

    kept: list  # the tracked candidates (and the leader), in admission order
    archive: list  # ended tracks kept for the joint refinement
    rejected: frozenset  # ids rejected since the last reset (only ids still tracked)
    fed: bool  # a candidate was admitted or its identifier gained a sample
    round_start: float  # s, as ``CandidateBank.round_start``
    leader: int  # feature id of the leader (-1: none)
    adoptions: tuple  # every leader chosen, in order
    adopted_mse: float  # m^2, as ``CandidateBank.adopted_mse``
