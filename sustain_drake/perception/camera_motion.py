"""The camera notices its own motion from the static scene (beyond the paper). Pure numpy + OpenCV.

The paper's observation rule (Eq. (2) errors of the observed tool point against the allowable
error) sees a moved camera only through a point it is observing; a loop that lost its observed
point when the camera moved is blind to the move. But a moving camera moves the whole static
scene in the image coherently (one global image motion), whereas the robot moves only its own
body's features and a walking person a minority of them. So, per frame:

- the *background*: the *anchors*, tracked features that have not moved against the scene
  (within ``feature_still_px`` of where they became still, so that a slow drift adds up; while the
  scene moves, their flow within ``inlier_px`` of the frame's global motion: a static corner stays
  an anchor while the camera turns) through ``anchor_time`` s of arm motion (``static_features``)
  and are not the robot's (neither a body feature nor in a body cell: ``robot`` below); while the
  arm has been at rest for ``anchor_time``, every feature still for that long (a body at rest is
  static scene). A feature that became still only while the arm rested is no anchor once it moves
  again, whatever the body detector says: from a near camera the arm fills most of the image, and
  its unflagged features, all moving off together as the arm starts, would be "the scene". A
  walking person's features keep moving and never become anchors; a feature seeded in this frame
  has no flow yet;
- the *global motion*: a similarity (rotation, uniform scale, translation; 4 degrees of freedom)
  fitted by RANSAC (``cv2.estimateAffinePartial2D``) from the anchors' previous pixels
  (``p_px - flow_px``) to their current ones;
- the frame *moves* when at least ``min_background`` anchors exist, at least
  ``min_inlier_fraction`` of them are inliers of that motion (within ``inlier_px``), its
  displacement (below) exceeds ``still_px``, and fewer than ``min_background`` anchors are
  explained better by staying put than by that motion (a camera move moves every anchor). The arm
  or a person starting to move over a still background leaves the still anchors as the consensus
  (displacement 0); a person who stood long enough for their features to be anchors and
  outnumbers the scene's, walking on, leaves the scene's anchors still; fewer anchors than
  ``min_background`` say nothing (the frame is not judged moving).
  A slow move (a head's ramp, a fraction of a pixel per frame at first, or a creep) is seen by
  its sum: when the anchors, fitted from their still pixels (where each came to rest, or where the
  last moving frame left it) to where they are now, moved together by more than ``still_px``, the
  frame moves by that motion (else every anchor would restart once ``feature_still_px`` away, all
  in the same frame, and no frame of the move be judged).

**It needs a textured static scene.** In the plain room (wall, floor and table; the station
without ``backdrop``) the tracker holds 0-7 static corners outside the body cells (2 when the
head turns at 113 s in ``diagrams/hand_eye.yaml``: the table's right corners), too few for a
robust fit: the detector then judges a frame only when the arm has rested for ``anchor_time``
(its features are anchors). With the station's ``backdrop`` (posters on the back wall), about
100 anchors.

An *episode* runs from the first moving frame to ``rest_frames`` consecutive frames that do not
move. Its frames' motions are composed; the episode is a **camera move** (the count ``moves``
goes up, once per episode) as soon as it has ``min_frames`` moving frames (one frame's jump is a
tracking glitch, a camera moves over frames) and the composed motion's displacement reaches
``move_px``.

**A move the tracks missed** (``scene_reference``; with the frame's grey image). The anchors must
live through a move for its frames to be judged: a person passing in front of the camera ends them,
and a turn thins them below ``min_background`` (its perspective takes the image's edges off the
similarity). After such a *gap* (a frame not judged, or an episode that ended before it reached
``move_px``) the new anchors are born in the moved image and see no motion. So a still frame with
its anchors is kept as a reference (refreshed every ``REFERENCE_INTERVAL`` s while still) and, once
the scene is still again after a gap (a view of ``turn_frames`` frames), its anchors are followed
from its image into the current one: a displacement of ``move_px`` or more is a camera move,
declared then, the followed anchors its turn.

**Static scene is no hand candidate** (``static_features``, ``exclude_static``). A feature that
stayed still against the scene through ``anchor_time`` s of arm motion is not on the hand (every
joint moves the hand, the last link), whatever cell it lies in. The hand-eye candidates skip such
features: with a textured wall, static corners in body cells would take candidate slots, and
after a camera move the body cells (fixed in the image) lie on the static scene.

Displacement of an image motion ``M``: the mean of ``||M p - p||`` over a 3 x 3 grid of image
points (corners, edge midpoints, centre): a pan or tilt's image translation, a roll's mean arc.

**Why ``move_px`` is a few pixels.** A camera rotation of ``d`` rad (pan or tilt) moves the image
by about ``f d`` px (``f`` the focal length in px) and a point at depth ``z`` relative to the
camera by about ``z d``; a camera translation ``t`` moves a point at depth ``z`` by ``f t / z``
px. Either way a move of ``D`` px displaces the points at depth ``z`` by about ``z D / f`` in the
camera frame. The observation rule tolerates a per-sample residual of ``sqrt(sigma)`` (the
allowable error), so a move matters for a calibration used at depths up to ``z_max`` when
``z_max D / f >= sqrt(sigma)``, i.e. ``D >= f sqrt(sigma) / z_max``. The defaults are for
320 x 240 (``f`` = 290 px, 45 deg vertical field of view), ``sqrt(sigma)`` = 13 mm (100 (1.3 mm)^2)
and the tool at 0.6-0.9 m: 4.2 px at 0.9 m, so ``move_px`` = 3 px counts every move the rule could
see. Every threshold here is in pixels: at another image size scale them with the focal length
(``diagrams/hand_eye.yaml``, 640 x 480: ``f`` = 580 px, each doubled).

**The turn of the camera** (``SceneTurn``; given the intrinsics and the features' 3-D points).
While the scene is still (the state not in an episode, the frame's displacement at most
``view_still_px``), each anchor's pixel and 3-D point are averaged into the *view* of the still
scene (a running mean over its last ``VIEW_FRAMES`` frames). At an episode's onset the view becomes
the *view before* (if it has ``turn_frames`` frames: the scene was at rest before the move), and a
new view starts once the scene rests again. When a declared move's view after has ``turn_frames``
frames, the anchors seen in both views (each in at least half of either's frames) give the turn's
correspondences: per anchor its bearing before and after (unit vectors in C0 and C1) and its point
before and after (in C0 and C1, NaN without depth). The camera's rotation and translation are
estimated from them downstream (``identification.camera_turn.camera_after_turn``, with the tool
points for the translation): a far scene pins the rotation to a few hundredths of a degree; its
bearings hardly show the position, its depth on both sides does (to the depth noise over the
anchors), enough to match the tool's points again.
The anchors' tracks through the move are used as they are (re-registering the view before against
the image after moved them by 0.07 px median in ``diagrams/hand_eye.yaml``'s head turn).
"""

# No "from __future__ import annotations": yaml_load_typed reads CameraMotionParams' real field types.

import math
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from sustain_drake.perception.optical_flow import PinholeIntrinsics, TrackedFeatures, pinhole_points
from sustain_drake.perception.scene_reference import MIN_MATCHES, SceneReference, match

# The view of the still scene is a running mean over at most this many frames (1 s at 30 Hz): a
# slow drift of the camera below ``still_px`` does not smear it.
VIEW_FRAMES = 30
# s between refreshes of the still scene's reference (a still camera's image changes only slowly:
# lights, a person's shadow; a refresh keeps a reference to the frame's grey image, no copy).
REFERENCE_INTERVAL = 1.0
# s a reference that no view after a gap matched is kept before a new one replaces it: a move
# older than this was found by the observation rule, if it mattered.
MAX_REFERENCE_AGE = 10.0


@dataclass
class CameraMotionParams:
    """Thresholds of the camera-motion detector (px, frames, counts)."""

    min_background: int = 20          # count: anchors needed to judge a frame
    anchor_time: float = 0.5          # s a feature must have been still against the scene to be an anchor
    inlier_px: float = 1.0            # px: RANSAC: a feature within this of the fitted motion is an inlier
    min_inlier_fraction: float = 0.6  # fraction of the background: the consensus that is "the scene"
    still_px: float = 0.5             # px: per-frame displacement at or below this is not moving
    feature_still_px: float = 0.5     # px: a feature this far from where it became still has moved
    arm_speed: float = 0.01           # rad/s: a joint faster than this moves the arm (Eq. (27)'s threshold)
    rest_frames: int = 3              # count: consecutive frames not moving that end an episode
    min_frames: int = 2               # count: moving frames of an episode before it can be a camera move
    move_px: float = 3.0              # px: composed displacement of an episode that is a camera move
    exclude_static: bool = True       # static scene features are no body candidates (static_features)
    view_still_px: float = 0.1        # px: a frame moving at most this adds to the view of the still scene
    turn_frames: int = 5              # count: still frames around a move that give its turn; 0: none

    def __post_init__(self):
        times = (self.anchor_time, self.arm_speed, self.feature_still_px)
        if not (self.min_background >= 3 and self.inlier_px > 0 and 0 < self.min_inlier_fraction <= 1
                and self.still_px >= 0 and self.rest_frames >= 1 and self.min_frames >= 1
                and self.move_px > self.still_px and all(x >= 0 for x in times)
                and 0 <= self.view_still_px <= self.still_px and self.turn_frames >= 0
                and all(map(math.isfinite, (*times, self.inlier_px, self.still_px, self.move_px)))):
            raise ValueError("invalid camera motion parameters (min_background >= 3, inlier_px > 0, "
                             "0 < min_inlier_fraction <= 1, rest_frames and min_frames >= 1, "
                             "move_px > still_px >= view_still_px >= 0, turn_frames >= 0, "
                             f"finite times and speeds >= 0): {self}")


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
class SceneView:
    """The still scene's anchors over the last ``VIEW_FRAMES`` of ``frames`` still frames: per
    anchor (sorted ``ids``) its mean pixel ``px`` (K x 2), its mean 3-D point ``p_CP`` (K x 3, m,
    camera frame; NaN where it never had depth), in how many of those frames it was seen
    (``seen``, at most ``VIEW_FRAMES``) and had depth (``with_depth``), and the frame it was last
    seen in (``last``, counting from 1). An anchor not seen for ``VIEW_FRAMES`` frames is dropped."""

    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    p_CP: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    seen: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    with_depth: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    last: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    frames: int = 0


@dataclass(frozen=True)
class SceneTurn:
    """The correspondences of the static scene across camera move number ``move`` (0: none yet),
    formed at ``time`` (s) from the move's episode starting at ``start`` (s): per anchor seen at rest
    before and after the move, its unit bearing before ``b0`` (K x 3, in the camera frame C0 before),
    its point before ``q0`` (K x 3, m, in C0; NaN rows without depth), its unit bearing after
    ``b1`` (K x 3, in the camera frame C1 after) and its point after ``q1`` (K x 3, m, in C1; NaN
    rows without depth). A point of the static scene satisfies ``q0 = R_C0C1 q1 + p_C0C1`` (``q1``
    along ``b1``)."""

    move: int = 0
    time: float = -math.inf
    start: float = -math.inf
    b0: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    q0: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    b1: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    q1: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def __len__(self) -> int:
        return int(self.b0.shape[0])


@dataclass(frozen=True)
class CameraMotionState:
    """Everything carried from frame to frame (immutable: ``step`` returns a new one).

    ``moving``: in an episode; ``moves``: camera moves so far; ``accumulated_px``: the displacement
    of the current (or last) episode's composed motion; ``M_episode``: that motion (3 x 3
    homogeneous); ``declared``: the current episode was counted; ``frames``: its moving frames;
    ``rest``: frames not moving since
    the last moving one; ``ids`` and ``still_since``: the features tracked in the last frame (sorted
    ids) and since when each has been still against the scene (s); ``last_time``: that frame's time
    (a frame not newer is ignored); ``last``: that frame's verdict; ``arm_moving``,
    ``arm_clock``, ``arm_still_since``: whether a joint moved at the last frame, for how long the
    arm has moved in all (s, between frames where it moved) and since when it has been at rest (s);
    ``still_clock``, ``still_px``: per feature, ``arm_clock`` when it became still and its pixel
    then (moved along with the scene's motion since). ``view``: the still scene now (``SceneView``;
    empty while moving); ``view_before``: the one before the current or last move (None once its
    turn is formed, or when the scene had not been at rest before); ``episode_start``: the current
    or last episode's first moving frame (s); ``turn``: the last move's ``SceneTurn``;
    ``unmoved_since``: since when the still scene shows the camera has not moved (s): the frames
    judged still, outside an episode, joined across a gap that the reference, matched after it,
    showed no move in (``scene_still_since``); inf after a declared move until a frame is judged
    still, and where a frame is not judged with no reference to check it against later or the
    reference aged before any view matched it;
    ``move_start``: when the last declared camera move began (s; -inf before any: its episode's first
    moving frame, or the time of the reference a move the tracks missed was found against, so at
    most when the camera began to move);
    ``reference``: a still frame of the scene (``scene_reference.SceneReference``; kept only when
    ``step`` is given the grey image), ``gap``: since it was taken a frame was not judged or an
    episode ended undeclared, so the tracks may have missed a move (checked against it when the
    scene is still again); ``before_move``: the reference when the tracks declared the current or
    last move, until its turn is formed (the turn from it where too few anchors were tracked
    across the move)."""

    moving: bool = False
    moves: int = 0
    accumulated_px: float = 0.0
    M_episode: np.ndarray = field(default_factory=lambda: np.eye(3))
    declared: bool = False
    frames: int = 0
    rest: int = 0
    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    still_since: np.ndarray = field(default_factory=lambda: np.zeros(0))
    last_time: float = -math.inf
    last: FrameMotion | None = None
    still_clock: np.ndarray = field(default_factory=lambda: np.zeros(0))
    still_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    arm_moving: bool = False
    arm_clock: float = 0.0
    arm_still_since: float = -math.inf
    view: SceneView = field(default_factory=SceneView)
    view_before: SceneView | None = None
    episode_start: float = -math.inf
    turn: SceneTurn = field(default_factory=SceneTurn)
    unmoved_since: float = math.inf
    move_start: float = -math.inf
    reference: SceneReference | None = None
    gap: bool = False
    before_move: SceneReference | None = None

    def scene_still_since(self) -> float:
        """Since when the camera has not moved as the still scene shows (s; ``unmoved_since``): inf
        while moving, in an episode, or while a gap is not yet checked against the reference."""
        return math.inf if self.moving or self.gap else self.unmoved_since

    def output(self) -> np.ndarray:
        """``[moving (0/1), moves, accumulated displacement (px)]``."""
        return np.array([float(self.moving), float(self.moves), self.accumulated_px])


def reference_points(width: int, height: int) -> np.ndarray:
    """The 3 x 3 grid of image points (corners, edge midpoints, centre) a displacement is measured on."""
    u, v = np.meshgrid([0.0, width / 2.0, float(width)], [0.0, height / 2.0, float(height)])
    return np.column_stack([u.ravel(), v.ravel()])


def displacement(M: np.ndarray, points: np.ndarray) -> float:
    """Mean ``||M p - p||`` over ``points`` (K x 2), px; ``M`` is 2 x 3 or 3 x 3 (affine)."""
    M = np.asarray(M, float)[:2]
    moved = points @ M[:, :2].T + M[:, 2]
    return float(np.mean(np.linalg.norm(moved - points, axis=1)))


def still_since(state: CameraMotionState, ids: np.ndarray) -> np.ndarray:
    """Per feature in ``ids``: since when it has been still against the scene (s), from the last
    frame's memory; NaN for a feature not tracked in the last frame (no flow yet)."""
    return _remembered(state, ids, state.still_since)


def _remembered(state: CameraMotionState, ids: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The last frame's per-feature ``values`` (aligned with ``state.ids``) for ``ids``; NaN for
    a feature not tracked in the last frame."""
    out = np.full((ids.shape[0],) + np.shape(values)[1:], np.nan)
    if state.ids.size:
        pos = np.minimum(np.searchsorted(state.ids, ids), state.ids.size - 1)
        known = state.ids[pos] == ids
        out[known] = values[pos[known]]
    return out


def static_features(state: CameraMotionState, ids: np.ndarray, params: CameraMotionParams) -> np.ndarray:
    """Per feature in ``ids`` (the last frame's): it stayed still against the scene for
    ``anchor_time`` s of arm motion (``arm_clock``) and more. Every joint moves the hand (the last link), so
    such a feature is not on the hand, whatever cell it lies in: it is no candidate for the
    hand-eye identifiers (after a camera move the body cells, fixed in the image, lie on the
    static scene)."""
    clock = _remembered(state, np.asarray(ids, np.int64).ravel(), state.still_clock)
    return ~np.isnan(clock) & (state.arm_clock - np.nan_to_num(clock, nan=np.inf) >= params.anchor_time)


def add_to_view(view: SceneView, ids: np.ndarray, px: np.ndarray, p_CP: np.ndarray,
                valid: np.ndarray) -> SceneView:
    """``view`` with one more still frame of anchors (``ids``, pixels ``px``, points ``p_CP`` with
    ``valid`` depth): each anchor's running mean over its last ``VIEW_FRAMES`` sightings at most."""
    ids = np.asarray(ids, np.int64).ravel()
    order = np.argsort(ids)
    ids, px = ids[order], np.asarray(px, float).reshape(-1, 2)[order]
    p_CP = np.asarray(p_CP, float).reshape(-1, 3)[order]
    valid = np.asarray(valid, bool).ravel()[order] & np.all(np.isfinite(p_CP), axis=1)
    frame = view.frames + 1
    recent = frame - view.last < VIEW_FRAMES  # the others are gone from the scene's view
    all_ids = np.union1d(view.ids[recent], ids)
    old = np.searchsorted(all_ids, view.ids[recent])
    n = all_ids.size
    mean_px, mean_p = np.zeros((n, 2)), np.full((n, 3), np.nan)
    seen, with_depth, last = np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n, np.int64)
    mean_px[old], mean_p[old] = view.px[recent], view.p_CP[recent]
    seen[old], with_depth[old], last[old] = view.seen[recent], view.with_depth[recent], view.last[recent]
    new = np.searchsorted(all_ids, ids)
    seen[new] = np.minimum(seen[new] + 1, VIEW_FRAMES)
    last[new] = frame
    mean_px[new] += (px - mean_px[new]) / seen[new][:, None]
    d = new[valid]
    with_depth[d] = np.minimum(with_depth[d] + 1, VIEW_FRAMES)
    first = with_depth[d, None] == 1  # the mean so far is NaN
    mean_p[d] = np.where(first, p_CP[valid], mean_p[d] + (p_CP[valid] - mean_p[d]) / with_depth[d][:, None])
    return SceneView(all_ids, mean_px, mean_p, seen, with_depth, last, frame)


def bearings(px: np.ndarray, intrinsics: PinholeIntrinsics) -> np.ndarray:
    """Unit vectors in the camera frame towards pixels ``px`` (K x 2): the pinhole model at depth 1,
    normalised."""
    b = pinhole_points(px, np.ones(np.asarray(px).reshape(-1, 2).shape[0]), intrinsics)
    return b / np.linalg.norm(b, axis=1, keepdims=True)


def scene_turn(before: SceneView, after: SceneView, intrinsics: PinholeIntrinsics, move: int, time: float,
               start: float) -> SceneTurn:
    """The ``SceneTurn`` of the anchors in both views, each seen in at least half of either
    view's last ``VIEW_FRAMES`` frames (a track that came and went is left out)."""
    common, i0, i1 = np.intersect1d(before.ids, after.ids, return_indices=True)
    keep = ((2 * before.seen[i0] >= min(before.frames, VIEW_FRAMES))
            & (2 * after.seen[i1] >= min(after.frames, VIEW_FRAMES)))
    i0, i1 = i0[keep], i1[keep]
    return SceneTurn(move, float(time), float(start), bearings(before.px[i0], intrinsics),
                     before.p_CP[i0].copy(), bearings(after.px[i1], intrinsics), after.p_CP[i1].copy())


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
    if moving:
        # A camera move moves every anchor as the fitted motion does: anchors enough to judge a frame
        # by themselves that staying put explains better than the motion (by more than the still
        # scene's own per-frame motion, view_still_px) are the scene, and the motion is of a body in
        # front of it (a person or the robot's unflagged features moving off: a similarity fits a
        # compact group's shift and the still anchors around it within inlier_px).
        stayed = (np.linalg.norm(cur_px - (prev_px @ M[:, :2].T + M[:, 2]), axis=1)
                  - np.linalg.norm(cur_px - prev_px, axis=1)) > params.view_still_px
        moving = int(np.count_nonzero(stayed)) < params.min_background
    return FrameMotion(True, moving, M, n, fraction, moved)


def step(state: CameraMotionState, features: TrackedFeatures, robot: np.ndarray, joints_moving: np.ndarray,
         params: CameraMotionParams, image_size: tuple[int, int],
         intrinsics: PinholeIntrinsics | None = None,
         gray: np.ndarray | None = None) -> CameraMotionState:  # fmt: skip
    """One frame of tracked ``features`` (``optical_flow.TrackedFeatures``: its ``time``, ``ids``,
    ``p_px``, ``flow_px``, and for the turn ``p_CP`` and ``valid``); ``robot``: per feature, a body
    feature or in a body cell; ``joints_moving``: per actuator, it moves now. ``image_size`` is
    (width, height). With ``intrinsics`` (and ``params.turn_frames`` > 0) the views of the still
    scene and the turn of each move are kept too (module docstring); with the frame's grey image
    ``gray`` (H x W uint8) as well, the still scene's reference, checked after a gap
    (``_checked_against_reference``). Returns the new state (``state`` itself for a frame not
    newer than the last one)."""
    time = features.time
    if not time > state.last_time:
        return state
    ids = np.asarray(features.ids, np.int64).ravel()
    p_px = np.asarray(features.p_px, float).reshape(-1, 2)
    flow_px = np.asarray(features.flow_px, float).reshape(-1, 2)
    robot = np.asarray(robot, bool).ravel()
    if not (p_px.shape[0] == flow_px.shape[0] == robot.shape[0] == ids.shape[0]):
        raise ValueError(f"camera motion: {ids.shape[0]} ids, {p_px.shape[0]} pixels, "
                         f"{flow_px.shape[0]} flows, {robot.shape[0]} robot flags: one per feature expected")
    p_CP = valid = None
    if intrinsics is not None:  # the turn needs the features' 3-D points
        p_CP = np.asarray(features.p_CP, float).reshape(-1, 3)
        valid = np.asarray(features.valid, bool).ravel()
        if not (p_CP.shape[0] == valid.shape[0] == ids.shape[0]):
            raise ValueError(f"camera motion: {ids.shape[0]} ids, {p_CP.shape[0]} points, {valid.shape[0]} "
                             "valid flags: one per feature expected")
    points = reference_points(*image_size)
    arm_moving = bool(np.any(joints_moving))
    if arm_moving:
        arm_still_since = math.inf
    elif state.arm_moving or state.arm_still_since == math.inf:
        arm_still_since = time  # it just stopped
    else:
        arm_still_since = state.arm_still_since
    arm_at_rest = not arm_moving and time - arm_still_since >= params.anchor_time
    since = still_since(state, ids)
    p_prev = p_px - flow_px
    finite = np.all(np.isfinite(p_px) & np.isfinite(flow_px), axis=1)
    tracked = ~np.isnan(since)
    if arm_at_rest:
        still_enough = time - np.where(tracked, since, time) >= params.anchor_time
    else:
        still_enough = static_features(state, ids, params)
    anchors = finite & tracked & still_enough & (arm_at_rest | ~robot)
    frame = frame_motion(p_prev[anchors], p_px[anchors], params, points)
    drift = None  # the anchors' motion since their still pixels, when it makes this frame move
    if frame.judged and not frame.moving:
        # A slow move (a head's ramp, a creep): each frame at most still_px, but the anchors drifted
        # together from their still pixels (where each came to rest, or the last moving frame left
        # it) by more; each would restart once feature_still_px away, all in one frame, and no frame
        # of the move be judged. The frame moves by that drift (frames not composed yet).
        since_still = frame_motion(_remembered(state, ids, state.still_px)[anchors], p_px[anchors],
                                   params, points)  # fmt: skip
        if since_still.moving:
            frame, drift = replace(frame, moving=True), since_still.M
    # Memory: a feature moving against the scene restarts its still time; so does a feature seeded
    # now. While the scene moves: its flow off the frame's motion (and its still pixel follows);
    # else: its distance from where it became still (a slow drift adds up over frames).
    if frame.moving:
        moved = np.linalg.norm(p_px - (p_prev @ frame.M[:, :2].T + frame.M[:, 2]), axis=1) > params.inlier_px
        anchor_px = p_px
    else:
        anchor_px = _remembered(state, ids, state.still_px)
        moved = ~(np.linalg.norm(p_px - anchor_px, axis=1) <= params.feature_still_px)
    restart = np.isnan(since) | ~finite | moved
    anchor_px = np.where(restart[:, None], p_px, anchor_px)
    arm_clock = state.arm_clock + (time - state.last_time if arm_moving and state.arm_moving else 0.0)
    since = np.where(restart, time, since)
    clock = np.where(restart, arm_clock, _remembered(state, ids, state.still_clock))
    order = np.argsort(ids)
    if frame.judged and not frame.moving and not state.moving:
        unmoved = min(state.unmoved_since, float(time))
    else:  # a gap or an episode: it holds while a reference can check it (a gap's, once still)
        unmoved = state.unmoved_since if state.reference is not None else math.inf
    new = replace(state, ids=ids[order], still_since=since[order], still_clock=clock[order],
                  still_px=anchor_px[order],
                  last_time=float(time), last=frame, arm_moving=arm_moving, arm_clock=arm_clock,
                  arm_still_since=arm_still_since, unmoved_since=unmoved)
    if frame.moving:
        M = np.vstack([frame.M if drift is None else drift, [0.0, 0.0, 1.0]])
        if not state.moving:  # onset: a new episode; the still view so far is the view before
            before = state.view if 0 < params.turn_frames <= state.view.frames else None
            new = replace(new, moving=True, declared=False, M_episode=np.eye(3), frames=0, view=SceneView(),
                          view_before=before, episode_start=float(time))
        M_episode = M @ new.M_episode
        accumulated = displacement(M_episode, points)
        new = replace(new, M_episode=M_episode, accumulated_px=accumulated, rest=0, frames=new.frames + 1)
        if not new.declared and new.frames >= params.min_frames and accumulated >= params.move_px:
            # A move the tracks followed: the reference is of the camera before it.
            new = replace(new, declared=True, moves=state.moves + 1, reference=None, gap=False,
                          before_move=state.reference, move_start=new.episode_start,
                          unmoved_since=math.inf)
        return new
    if not frame.judged and new.reference is not None:
        # The tracks may miss a move now: the view after starts anew (a view across a move is none).
        new = replace(new, gap=True, view=SceneView())
    if state.moving:
        rest = state.rest + 1
        new = replace(new, rest=rest, moving=rest < params.rest_frames)
        if not new.moving and not new.declared and new.reference is not None:
            new = replace(new, gap=True)  # an episode the tracks lost before it added up
    if (intrinsics is not None and params.turn_frames > 0 and not new.moving and frame.judged
            and frame.displacement_px <= params.view_still_px):
        # After a move, the anchors of the view before that are still tracked count at once: a
        # turn's perspective takes the image's edges off the similarity fit, so many anchors
        # restart their still time during it (the turn's fit leaves out those that did move).
        members = anchors
        if new.view_before is not None:
            members = anchors | (np.isin(ids, new.view_before.ids) & finite & ~robot)
        new = replace(new, view=add_to_view(new.view, ids[members], p_px[members], p_CP[members],
                                            valid[members]))
        formed = new.view.frames >= params.turn_frames
        if formed and (new.view_before is not None or new.before_move is not None):
            if new.declared:  # a camera move (not a glitch): its turn
                new = replace(new, turn=_turn_of_move(new, gray, ids, anchors & ~robot, params, intrinsics))
            new = replace(new, view_before=None, before_move=None)
        if gray is not None and new.view.frames >= params.turn_frames:
            new = _checked_against_reference(new, gray, ids, anchors & ~robot, params, intrinsics)
    return new


def _turn_of_move(state: CameraMotionState, gray, ids: np.ndarray, scene: np.ndarray,
                  params: CameraMotionParams, intrinsics: PinholeIntrinsics) -> SceneTurn:  # fmt: skip
    """The turn of the declared move once the view after it is formed: the anchors tracked across
    it (``scene_turn``), or, where fewer than ``MIN_MATCHES`` were (a near camera: the arm and a
    person fill the view; a turn that ends every track), the still frame before it
    (``before_move``) matched into this one (``scene_reference.match``); the last turn if neither
    gives one."""
    tracked = (None if state.view_before is None else
               scene_turn(state.view_before, state.view, intrinsics, state.moves, state.last_time,
                          state.episode_start))
    if (tracked is None or len(tracked) < MIN_MATCHES) and gray is not None and state.before_move is not None:
        px, p_CP = _scene_points(state, ids, scene, params)
        found = (None if px.shape[0] < MIN_MATCHES else
                 match(state.before_move, gray, px, p_CP, params.move_px, params.min_inlier_fraction))
        if found is not None:
            return _matched_turn(found, state.moves, state.last_time, state.episode_start, intrinsics)
    return state.turn if tracked is None else tracked


def _matched_turn(found, move: int, time: float, start: float, intrinsics: PinholeIntrinsics) -> SceneTurn:
    """The ``SceneTurn`` of a reference matched into a frame (``scene_reference.ReferenceMatch``)."""
    return SceneTurn(move, float(time), float(start), bearings(found.px0, intrinsics), found.q0,
                     bearings(found.px1, intrinsics), found.q1)


def _scene_points(state: CameraMotionState, ids: np.ndarray, scene: np.ndarray, params: CameraMotionParams):
    """The view's mean pixels and points of the anchors (``scene``: per feature, an anchor not of the
    robot) still through arm motion (``static_features``): an unflagged arm feature that rested
    with the arm would move with it (the anchors while the arm rests include such features)."""
    return _view_points(state.view, ids[scene & static_features(state, ids, params)])


def _view_points(view: SceneView, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mean pixels and 3-D points of the view's anchors among ``ids`` that were seen in the
    view's last frame and in at least half of its last ``VIEW_FRAMES`` frames."""
    keep = (np.isin(view.ids, ids) & (view.last == view.frames)
            & (2 * view.seen >= min(view.frames, VIEW_FRAMES)))
    return view.px[keep], view.p_CP[keep]


def _checked_against_reference(state: CameraMotionState, gray: np.ndarray, ids: np.ndarray, scene: np.ndarray,
                               params: CameraMotionParams,
                               intrinsics: PinholeIntrinsics) -> CameraMotionState:  # fmt: skip
    """On a still frame with a still view of ``turn_frames`` frames (``ids``: this frame's
    features, ``scene``: per feature, an anchor that is not the robot's): after a gap, the reference's anchors
    followed into this frame and this frame's anchors back into the reference
    (``scene_reference.match``); a motion of ``move_px`` or more that both agree on is a camera
    move the tracks missed, declared now with its turn (its episode starts at the reference's
    time). An inconclusive match is tried again every ``turn_frames`` frames until the reference
    is ``MAX_REFERENCE_AGE`` old. Without a gap, the reference is this frame's every
    ``REFERENCE_INTERVAL`` s."""
    time, reference = state.last_time, state.reference
    if not state.gap and reference is not None and time - reference.time < REFERENCE_INTERVAL:
        return state
    if state.gap and reference is not None and state.view.frames % max(params.turn_frames, 1):
        return state
    px, p_CP = _scene_points(state, ids, scene, params)
    if px.shape[0] < MIN_MATCHES:
        return state  # too few anchors to describe the scene (or to follow into it)
    current = SceneReference(float(time), gray, px, p_CP)
    if not state.gap or reference is None:
        return replace(state, reference=current)
    found = match(reference, gray, px, p_CP, params.move_px, params.min_inlier_fraction)
    if found is None:  # not agreed (yet): tried again later, until the reference is too old
        too_old = time - reference.time > MAX_REFERENCE_AGE
        return replace(state, reference=current, gap=False, unmoved_since=math.inf) if too_old else state
    state = replace(state, reference=current, gap=False)
    if found.moved_px < params.move_px:
        return state
    turn = _matched_turn(found, state.moves + 1, float(time), reference.time, intrinsics)
    return replace(state, moves=state.moves + 1, declared=True, accumulated_px=found.moved_px,
                   M_episode=found.H, episode_start=reference.time, move_start=reference.time, turn=turn,
                   view_before=None, unmoved_since=math.inf)
