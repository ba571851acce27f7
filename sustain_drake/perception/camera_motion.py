"""The camera notices its own motion from the static scene (beyond the paper). Pure numpy + OpenCV.

The paper's observation rule (Eq. (2) errors of the observed tool point against the allowable
error) sees a moved camera only through a point it is observing; a loop that lost its observed
point when the camera moved is blind to the move. But a moving camera moves the whole static
scene in the image coherently (one global image motion), whereas the robot moves only its own
body's features and a walking person a minority of them. So, per frame:

- the *background*: the tracked features that were tracked in the previous frame too (a flow
  from a real track, not a feature seeded now) and are not the robot's (neither a body feature
  nor in a body cell: ``robot`` below);
- the *global motion*: a similarity (rotation, uniform scale, translation; 4 degrees of freedom)
  fitted by RANSAC (``cv2.estimateAffinePartial2D``) from the background's previous pixels
  (``p_px - flow_px``) to its current ones;
- the frame *moves* when at least ``min_background`` background features exist, at least
  ``min_inlier_fraction`` of them are inliers of that motion (within ``inlier_px``) and its
  displacement (below) exceeds ``still_px``. A person or the arm moving over a still background
  leaves the still background as the consensus (displacement 0); fewer features than
  ``min_background`` say nothing (the frame is not judged moving).

An *episode* runs from the first moving frame to ``rest_frames`` consecutive frames that do not
move. Its frames' motions are composed; the episode is a **camera move** (the count ``moves``
goes up, once per episode) as soon as the composed motion's displacement reaches ``move_px``.

Displacement of an image motion ``M``: the mean of ``||M p - p||`` over a 3 x 3 grid of image
points (corners, edge midpoints, centre): a pan or tilt's image translation, a roll's mean arc.

**Why ``move_px`` is a few pixels.** A camera rotation of ``d`` rad (pan or tilt) moves the image
by about ``f d`` px (``f`` the focal length in px) and a point at depth ``z`` relative to the
camera by about ``z d``; a camera translation ``t`` moves a point at depth ``z`` by ``f t / z``
px. Either way a move of ``D`` px displaces the points at depth ``z`` by about ``z D / f`` in the
camera frame. The observation rule tolerates a per-sample residual of ``sqrt(sigma)`` (the
allowable error), so a move matters for a calibration used at depths up to ``z_max`` when
``z_max D / f >= sqrt(sigma)``, i.e. ``D >= f sqrt(sigma) / z_max``. ``diagrams/hand_eye.yaml``:
``f`` = 290 px (320 x 240, 45 deg vertical field of view), ``sqrt(sigma)`` = 13 mm (100 (1.3 mm)^2),
tool at 0.6-0.9 m: 4.2 px at 0.9 m, so ``move_px`` = 3 px counts every move the rule could see.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import cv2
import numpy as np


@dataclass(frozen=True)
class CameraMotionParams:
    """Thresholds of the camera-motion detector (px, frames, counts)."""

    min_background: int = 20          # background features with a flow needed to judge a frame
    inlier_px: float = 1.0            # RANSAC: a feature within this of the fitted motion is an inlier
    min_inlier_fraction: float = 0.6  # of the background: the consensus that is "the scene"
    still_px: float = 0.5             # per-frame displacement at or below this: not moving
    rest_frames: int = 3              # consecutive frames not moving that end an episode
    move_px: float = 3.0              # composed displacement of an episode that is a camera move

    def __post_init__(self):
        if not (self.min_background >= 3 and self.inlier_px > 0 and 0 < self.min_inlier_fraction <= 1
                and self.still_px >= 0 and self.rest_frames >= 1 and self.move_px > self.still_px
                and all(map(math.isfinite, (self.inlier_px, self.still_px, self.move_px)))):
            raise ValueError(f"invalid camera motion parameters (min_background >= 3, inlier_px > 0, "
                             f"0 < min_inlier_fraction <= 1, rest_frames >= 1, move_px > still_px >= 0): "
                             f"{self}")


@dataclass(frozen=True)
class FrameMotion:
    """One frame's verdict: ``judged`` (enough background), ``moving``, the fitted motion ``M``
    (2 x 3, previous -> current pixels; identity when not judged), the background count, the
    inlier fraction and the displacement (px)."""

    judged: bool
    moving: bool
    M: np.ndarray
    num_background: int
    inlier_fraction: float
    displacement_px: float


@dataclass(frozen=True)
class CameraMotionState:
    """Everything carried from frame to frame (immutable: ``step`` returns a new one).

    ``moving``: in an episode; ``moves``: camera moves so far; ``accumulated_px``: the displacement
    of the current (or last) episode's composed motion; ``M_episode``: that motion (3 x 3
    homogeneous); ``declared``: the current episode was counted; ``rest``: frames not moving since
    the last moving one; ``prev_ids``: the ids tracked in the last frame (sorted);
    ``last_time``: that frame's time (a frame not newer is ignored)."""

    moving: bool = False
    moves: int = 0
    accumulated_px: float = 0.0
    M_episode: np.ndarray = field(default_factory=lambda: np.eye(3))
    declared: bool = False
    rest: int = 0
    prev_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    last_time: float = -math.inf
    last: FrameMotion | None = None

    def output(self) -> np.ndarray:
        """``[moving (0/1), moves, accumulated displacement (px)]``."""
        return np.array([float(self.moving), float(self.moves), self.accumulated_px])


def reference_points(width: int, height: int) -> np.ndarray:
    """The 3 x 3 grid of image points (corners, edge midpoints, centre) a displacement is measured on."""
    u, v = np.meshgrid([0.0, width / 2.0, float(width)], [0.0, height / 2.0, float(height)])
    return np.column_stack([u.ravel(), v.ravel()])


def displacement(M: np.ndarray, points: np.ndarray) -> float:
    """Mean ``||M p - p||`` over ``points`` (K x 2), px; ``M`` is 2 x 3 or 3 x 3."""
    M = np.asarray(M, float)[:2]
    moved = points @ M[:, :2].T + M[:, 2]
    return float(np.mean(np.linalg.norm(moved - points, axis=1)))


def background_mask(ids: np.ndarray, prev_ids: np.ndarray, robot: np.ndarray) -> np.ndarray:
    """Features tracked in the previous frame too (``prev_ids``, sorted) and not the robot's."""
    ids = np.asarray(ids, np.int64).ravel()
    return np.isin(ids, prev_ids, assume_unique=False) & ~np.asarray(robot, bool).ravel()


def frame_motion(prev_px: np.ndarray, cur_px: np.ndarray, params: CameraMotionParams,
                 points: np.ndarray) -> FrameMotion:
    """The global image motion of the background (``prev_px`` -> ``cur_px``, K x 2 each) and
    whether it is a moving scene (module docstring)."""
    prev_px = np.asarray(prev_px, np.float64).reshape(-1, 2)
    cur_px = np.asarray(cur_px, np.float64).reshape(-1, 2)
    n = prev_px.shape[0]
    still = np.hstack([np.eye(2), np.zeros((2, 1))])
    if n < params.min_background:
        return FrameMotion(False, False, still, n, 0.0, 0.0)
    # Deterministic: OpenCV's RANSAC draws from a fixed-seed generator on each call.
    M, inliers = cv2.estimateAffinePartial2D(prev_px, cur_px, method=cv2.RANSAC,
                                             ransacReprojThreshold=params.inlier_px, maxIters=2000,
                                             confidence=0.995)  # fmt: skip
    if M is None or inliers is None or not np.all(np.isfinite(M)):
        return FrameMotion(True, False, still, n, 0.0, 0.0)
    fraction = float(np.count_nonzero(inliers)) / n
    moved = displacement(M, points)
    moving = fraction >= params.min_inlier_fraction and moved > params.still_px
    return FrameMotion(True, moving, M, n, fraction, moved)


def step(state: CameraMotionState, time: float, ids: np.ndarray, p_px: np.ndarray, flow_px: np.ndarray,
         robot: np.ndarray, params: CameraMotionParams, image_size: tuple[int, int]) -> CameraMotionState:
    """One frame of tracked features at ``time`` (``ids``, ``p_px``, ``flow_px`` as in
    ``optical_flow.TrackedFeatures``; ``robot``: per feature, a body feature or in a body cell).
    ``image_size`` is (width, height). Returns the new state (``state`` itself for a frame not
    newer than the last one)."""
    if not time > state.last_time:
        return state
    ids = np.asarray(ids, np.int64).ravel()
    p_px = np.asarray(p_px, float).reshape(-1, 2)
    flow_px = np.asarray(flow_px, float).reshape(-1, 2)
    robot = np.asarray(robot, bool).ravel()
    if not (p_px.shape[0] == flow_px.shape[0] == robot.shape[0] == ids.shape[0]):
        raise ValueError(f"camera motion: {ids.shape[0]} ids, {p_px.shape[0]} pixels, {flow_px.shape[0]} flows, "
                         f"{robot.shape[0]} robot flags: one per feature expected")  # fmt: skip
    points = reference_points(*image_size)
    usable = background_mask(ids, state.prev_ids, robot) & np.all(np.isfinite(p_px) & np.isfinite(flow_px), axis=1)
    frame = frame_motion(p_px[usable] - flow_px[usable], p_px[usable], params, points)
    new = replace(state, prev_ids=np.sort(ids), last_time=float(time), last=frame)
    if frame.moving:
        M = np.vstack([frame.M, [0.0, 0.0, 1.0]])
        if not state.moving:  # onset: a new episode
            new = replace(new, moving=True, declared=False, M_episode=np.eye(3))
        M_episode = M @ new.M_episode
        accumulated = displacement(M_episode, points)
        new = replace(new, M_episode=M_episode, accumulated_px=accumulated, rest=0)
        if not new.declared and accumulated >= params.move_px:
            new = replace(new, declared=True, moves=state.moves + 1)
        return new
    if state.moving:
        rest = state.rest + 1
        new = replace(new, rest=rest, moving=rest < params.rest_frames)
    return new
