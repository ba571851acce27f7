"""Optical-flow tracker core (paper §4.2): Shi–Tomasi corners tracked by pyramidal Lucas–Kanade.

Pure numpy + OpenCV, no pydrake import; ``sustain_drake.systems.optical_flow_tracker`` wraps it.

Per frame, :func:`track_frame` turns the previous :class:`TrackerState` and a new image into

- the per-cell visual change ``ṡ_j`` of Eq. (27): the sum of the flow norms of the features in
  grid cell ``j``, in pixels per second (the paper sums ``cvCalcOpticalFlowPyrLK`` flow norms);
- the tracked features (:class:`TrackedFeatures`): stable id, pixel, flow, and the 3-D point
  ``p_CP`` in the camera frame C (Drake's convention: +X right, +Y down, +Z forward) from the
  depth image.

Frames that carry no information (empty 0x0, black, or not newer than the last one) are skipped:
the state, and so every track's history, is returned unchanged.

**Track identity.** A track must stay on one physical point: body detection carries a confirmed
feature's evidence wherever its track goes, and the hand-eye identifier takes its 3-D points as
one point on the hand. Lucas–Kanade with the forward–backward check still lets a track slide
onto another surface when something passes it (a person walking past an arm corner pulls the
window along). Two cheap tests end such a track (:func:`identity_kept`):

- *appearance*: the normalised cross-correlation (NCC) of the ``ncc_patch_px`` square patch
  around the feature in the previous frame and around its new position (bilinear, one
  ``cv2.remap`` for all features) must be at least ``ncc_min``; a patch that became another
  texture correlates poorly, whereas the same surface seen one frame later (a small rotation,
  shading) keeps NCC near 1. Patches with no texture in both frames (std below ``ncc_flat``
  gray levels) pass: NCC says nothing there.
- *depth*: where the depth is valid in both frames, the feature's depth must not jump by more
  than ``depth_jump_m`` between frames (the arm moves a few cm per frame; another surface
  behind or in front of it is usually tens of cm away).

The depth test is on by default, the appearance test off (``ncc_min`` = 0). Measured on 12 s of
``diagrams/body_detection.yaml`` (the person passing the arm; 400 corners): without
either test 5 tracks went from the arm onto the person; the depth test alone ended all 5
and shortened the tracks that stay on the arm by ~2 % (median life 65 frames against 66);
adding NCC >= 0.8 caught nothing more there but shortened them to a median of 41-48 frames
(it also ends tracks on the arm's silhouette, whose background changes as the arm moves). A
camera without depth should turn NCC on (0.8 ends ~85 % of the tracks that LK and the
forward-backward check keep on a replaced texture).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import cv2
import numpy as np


@dataclass(frozen=True)
class PinholeIntrinsics:
    """Pinhole intrinsics in pixels (the subset of Drake's ``CameraInfo`` the tracker needs)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self):
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")
        if not (np.isfinite([self.fx, self.fy, self.cx, self.cy]).all()
                and self.fx > 0 and self.fy > 0):
            raise ValueError(f"focal lengths must be finite and positive, got {self.fx}, {self.fy}")


@dataclass(frozen=True)
class CellGrid:
    """A ``rows`` x ``cols`` grid of equal cells over a ``width`` x ``height`` image.

    Cell ``j = row * cols + col`` (row-major), the index used for ``ṡ_j`` and ``ε_ij``.
    """

    width: int
    height: int
    rows: int = 12
    cols: int = 16

    def __post_init__(self):
        if min(self.width, self.height, self.rows, self.cols) <= 0:
            raise ValueError(f"grid and image sizes must be positive, got {self}")
        if self.rows > self.height or self.cols > self.width:
            raise ValueError(f"grid {self.rows}x{self.cols} finer than image "
                             f"{self.width}x{self.height}")

    @property
    def num_cells(self) -> int:
        return self.rows * self.cols

    def cell_of(self, p_px: np.ndarray) -> np.ndarray:
        """Cell index of each pixel position ``p_px`` (K x 2, columns u, v); -1 if outside."""
        p = np.asarray(p_px, dtype=float).reshape(-1, 2)
        col = np.floor(p[:, 0] * self.cols / self.width).astype(np.int64)
        row = np.floor(p[:, 1] * self.rows / self.height).astype(np.int64)
        inside = (col >= 0) & (col < self.cols) & (row >= 0) & (row < self.rows)
        return np.where(inside, row * self.cols + col, -1)

    def cell_bounds(self, j: int) -> tuple[int, int, int, int]:
        """Pixel bounds ``(u0, v0, u1, v1)`` of cell ``j`` (u1, v1 exclusive)."""
        row, col = divmod(int(j), self.cols)
        u0 = col * self.width // self.cols
        u1 = (col + 1) * self.width // self.cols
        v0 = row * self.height // self.rows
        v1 = (row + 1) * self.height // self.rows
        return u0, v0, u1, v1


@dataclass(frozen=True)
class TrackerParams:
    """Tracker settings; defaults suit a 640x480 camera at 30 Hz."""

    max_corners: int = 300          # Shi–Tomasi: at most this many tracked features
    quality_level: float = 0.01     # Shi–Tomasi: corner quality relative to the best corner
    min_distance_px: float = 8.0    # Shi–Tomasi: minimum spacing of features
    block_size: int = 7
    reseed_fraction: float = 0.7    # re-seed when fewer than this fraction of max_corners remain
    lk_window_px: int = 15          # Lucas–Kanade window (square)
    lk_max_level: int = 2           # pyramid levels above the base image
    fb_threshold_px: float = 1.0    # forward–backward error above this drops the feature
    min_flow_px: float = 0.2        # per-frame flow below this counts as 0 (LK noise on still
    #                                 texture would otherwise keep ṡ_j from ever "rising from 0")
    black_level: int = 8            # a frame whose brightest gray pixel is below this is skipped
    # Track identity (module docstring): a track that changed surface ends.
    ncc_min: float = 0.0            # frame-to-frame NCC of the feature's patch at least this;
    #                                 0 or less: no appearance test (off by default, see above)
    ncc_patch_px: int = 9           # side of the square patch (odd)
    ncc_flat: float = 2.0           # gray-level std below which a patch has no texture
    depth_jump_m: float = 0.1       # depth change per frame above this ends the track; inf: no test
    # Lucas-Kanade starts each feature at its previous frame's flow added (constant image velocity)
    # instead of at rest: on a periodic texture (a checker) a frame-to-frame motion of more than
    # half the period lets the coarse pyramid level lock onto the next period, and the track jumps
    # by whole periods (25 mm rows on the rod, seen in hand-eye runs); with the prediction only the
    # change of motion must stay below that. False: start at rest (OpenCV's default).
    predict_flow: bool = False

    def __post_init__(self):
        if self.max_corners <= 0 or not 0.0 < self.reseed_fraction <= 1.0:
            raise ValueError(f"invalid max_corners/reseed_fraction in {self}")
        if self.lk_window_px < 3 or self.lk_max_level < 0 or self.fb_threshold_px <= 0:
            raise ValueError(f"invalid Lucas–Kanade settings in {self}")
        if self.min_flow_px < 0:
            raise ValueError(f"min_flow_px must be >= 0, got {self.min_flow_px}")
        if not (self.ncc_min <= 1.0 and self.ncc_patch_px >= 3 and self.ncc_patch_px % 2 == 1
                and self.ncc_flat >= 0 and self.depth_jump_m > 0):
            raise ValueError(f"invalid track identity settings (ncc_min <= 1, odd ncc_patch_px "
                             f">= 3, ncc_flat >= 0, depth_jump_m > 0) in {self}")


@dataclass
class TrackedFeatures:
    """The features tracked in the latest frame (K of them; all arrays have K rows).

    - ``ids``: stable track id (int64); a re-seeded feature gets a new id, never a reused one.
    - ``p_px``: pixel position (u, v) in the latest frame.
    - ``flow_px``: displacement (du, dv) in pixels since the previous processed frame (0 for a
      feature seeded in this frame).
    - ``p_CP``: 3-D point P in camera frame C, metres; rows with ``valid`` False are zero and
      must not be used (depth hole: 0, inf or NaN, or outside the depth image).
    - ``valid``: True where ``p_CP`` is a measured point.
    - ``cell``: grid cell index of ``p_px``.
    - ``symmetric``: True where a ``FeatureRefiner`` found the image centrally symmetric about the
      point (a checker saddle, a mark's centre): the strongest sign of a point fixed on its surface;
      all False from the tracker.
    - ``time``: time of the frame, seconds.
    """

    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    p_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    flow_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    p_CP: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    valid: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    cell: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    symmetric: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    time: float = 0.0

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    def copy(self) -> TrackedFeatures:
        return dataclasses.replace(
            self, **{f.name: np.array(getattr(self, f.name), copy=True)
                     for f in dataclasses.fields(self) if f.name != "time"})

    def __deepcopy__(self, memo):
        return self.copy()


@dataclass
class TrackerState:
    """Everything the tracker carries from frame to frame (held in a Drake abstract state).

    ``copy()`` (also used by ``copy.deepcopy``, which Drake calls to clone a context) copies every
    array, so two contexts never share mutable data.
    """

    prev_gray: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.uint8))
    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    p_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.float32))
    next_id: int = 0
    last_time: float = -np.inf
    frames: int = 0                 # processed frames
    skipped: int = 0                # skipped frames (empty, black, stale)
    identity_drops: int = 0         # tracks ended by the identity tests (appearance, depth)
    sdot: np.ndarray = field(default_factory=lambda: np.zeros(0))
    features: TrackedFeatures = field(default_factory=TrackedFeatures)

    @staticmethod
    def initial(grid: CellGrid) -> TrackerState:
        return TrackerState(sdot=np.zeros(grid.num_cells))

    def copy(self) -> TrackerState:
        return TrackerState(
            prev_gray=self.prev_gray.copy(), ids=self.ids.copy(), p_px=self.p_px.copy(),
            next_id=self.next_id, last_time=self.last_time, frames=self.frames,
            skipped=self.skipped, identity_drops=self.identity_drops, sdot=self.sdot.copy(),
            features=self.features.copy())

    def __deepcopy__(self, memo):
        return self.copy()


def to_gray(image: np.ndarray) -> np.ndarray:
    """uint8 gray image from an H x W, H x W x 1, RGB or RGBA (Drake ``ImageRgba8U``) array."""
    img = np.asarray(image)
    if img.dtype != np.uint8:
        raise ValueError(f"color image must be uint8, got {img.dtype}")
    if img.ndim == 2:
        return img
    if img.ndim == 3 and img.shape[2] == 1:
        return img[:, :, 0]
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_RGBA2GRAY)
    raise ValueError(f"color image must be H x W x {{1,3,4}}, got shape {img.shape}")


def depth_array(depth: np.ndarray, intrinsics: PinholeIntrinsics) -> np.ndarray:
    """The depth image as an H x W array (an H x W x 1 one squeezed), checked against the
    intrinsics' size (ValueError otherwise)."""
    d = np.asarray(depth)
    if d.ndim == 3 and d.shape[2] == 1:
        d = d[:, :, 0]
    if d.ndim != 2:
        raise ValueError(f"depth image must be H x W or H x W x 1, got shape {np.shape(depth)}")
    if d.shape != (intrinsics.height, intrinsics.width):
        raise ValueError(f"depth image is {d.shape[1]}x{d.shape[0]} but the intrinsics are "
                         f"{intrinsics.width}x{intrinsics.height}")
    return d


def back_project(p_px: np.ndarray, depth: np.ndarray | None,
                 intrinsics: PinholeIntrinsics) -> tuple[np.ndarray, np.ndarray]:
    """3-D points ``p_CP`` (K x 3, metres) of pixels ``p_px`` from a depth image (pinhole model).

    ``p_CP = ((u - cx) z / fx, (v - cy) z / fy, z)`` with z the depth (metres, along +Z of C) at
    the nearest pixel. Depth holes (0, negative, inf, NaN), pixels outside the image and a
    missing or empty depth image give ``valid`` False and a zero row, never a point.
    """
    p = np.asarray(p_px, dtype=float).reshape(-1, 2)
    p_CP = np.zeros((p.shape[0], 3))
    valid = np.zeros(p.shape[0], bool)
    if depth is None or p.shape[0] == 0:
        return p_CP, valid
    if np.size(depth) == 0:
        return p_CP, valid
    d = depth_array(depth, intrinsics)
    u = np.rint(p[:, 0]).astype(np.int64)
    v = np.rint(p[:, 1]).astype(np.int64)
    inside = (u >= 0) & (u < d.shape[1]) & (v >= 0) & (v < d.shape[0])
    z = np.zeros(p.shape[0])
    z[inside] = d[v[inside], u[inside]]
    valid = inside & np.isfinite(z) & (z > 0.0)
    p_CP[valid] = pinhole_points(p[valid], z[valid], intrinsics)
    return p_CP, valid


def pinhole_points(p_px: np.ndarray, z: np.ndarray, intrinsics: PinholeIntrinsics) -> np.ndarray:
    """``p_CP = ((u - cx) z / fx, (v - cy) z / fy, z)`` (K x 3, m) for pixels ``p_px`` (K x 2) at
    depths ``z`` (K, m, along +Z of C): the pinhole model, for depths the caller has checked."""
    p = np.asarray(p_px, dtype=float).reshape(-1, 2)
    z = np.asarray(z, dtype=float).ravel()
    return np.column_stack([(p[:, 0] - intrinsics.cx) * z / intrinsics.fx,
                            (p[:, 1] - intrinsics.cy) * z / intrinsics.fy, z])


def cell_visual_change(grid: CellGrid, p_px: np.ndarray, flow_px: np.ndarray, dt: float,
                       min_flow_px: float = 0.0) -> np.ndarray:
    """Per-cell visual change ``ṡ_j`` (pixels/second): sum of flow norms in cell j over ``dt``.

    Flows shorter than ``min_flow_px`` count as 0 so that a still scene gives exactly ``ṡ = 0``.
    """
    if not dt > 0.0:
        raise ValueError(f"frame interval must be positive, got {dt}")
    norms = np.linalg.norm(np.asarray(flow_px, dtype=float).reshape(-1, 2), axis=1)
    norms[norms < min_flow_px] = 0.0
    cell = grid.cell_of(p_px)
    keep = cell >= 0
    return np.bincount(cell[keep], weights=norms[keep], minlength=grid.num_cells) / dt


def _frame_is_blank(gray: np.ndarray, params: TrackerParams) -> bool:
    return gray.size == 0 or int(gray.max()) < params.black_level


def _seed(gray: np.ndarray, p_px: np.ndarray, params: TrackerParams, count: int) -> np.ndarray:
    """New Shi–Tomasi corners at least ``min_distance_px`` away from the existing features."""
    mask = np.full(gray.shape, 255, np.uint8)
    r = max(1, int(round(params.min_distance_px)))
    for u, v in np.rint(p_px).astype(int):
        cv2.circle(mask, (int(u), int(v)), r, 0, -1)
    corners = cv2.goodFeaturesToTrack(
        gray, maxCorners=count, qualityLevel=params.quality_level,
        minDistance=params.min_distance_px, mask=mask, blockSize=params.block_size)
    if corners is None:
        return np.zeros((0, 2), np.float32)
    return corners.reshape(-1, 2).astype(np.float32)


def _lk(prev_gray: np.ndarray, next_gray: np.ndarray, pts: np.ndarray, params: TrackerParams,
        guess: np.ndarray | None = None):
    """Pyramidal Lucas-Kanade from ``pts`` in ``prev_gray`` to ``next_gray``, started at ``guess``
    (the points themselves if None)."""
    # OpenCV's Python binding takes images here, not pyramids from buildOpticalFlowPyramid.
    win = (params.lk_window_px, params.lk_window_px)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 0.03)
    start = None if guess is None else guess.astype(np.float32).reshape(-1, 1, 2).copy()
    flags = 0 if guess is None else cv2.OPTFLOW_USE_INITIAL_FLOW
    out, status, _ = cv2.calcOpticalFlowPyrLK(
        prev_gray, next_gray, pts.reshape(-1, 1, 2), start, winSize=win,
        maxLevel=params.lk_max_level, criteria=criteria, flags=flags)
    return out.reshape(-1, 2), status.reshape(-1).astype(bool)


def sample_patches(gray: np.ndarray, p_px: np.ndarray, size: int) -> np.ndarray:
    """K x size x size float32 patches of ``gray`` centred on ``p_px`` (bilinear, borders
    replicated), sampled by one ``cv2.remap`` call for all features."""
    k = p_px.shape[0]
    r = (size - 1) / 2.0
    offs = np.arange(size, dtype=np.float32) - np.float32(r)
    map_x = (p_px[:, 0, None, None].astype(np.float32) + offs[None, None, :]).repeat(size, axis=1)
    map_y = (p_px[:, 1, None, None].astype(np.float32) + offs[None, :, None]).repeat(size, axis=2)
    out = cv2.remap(gray, map_x.reshape(k * size, size), map_y.reshape(k * size, size),
                    cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(k, size, size).astype(np.float32)


def patch_ncc(a: np.ndarray, b: np.ndarray, flat: float) -> np.ndarray:
    """Normalised cross-correlation of patch pairs (K x n x n each): 1 for the same texture,
    about 0 for unrelated ones. Two flat patches (std below ``flat``) give 1, one flat and one
    textured 0."""
    a = a.reshape(a.shape[0], -1)
    b = b.reshape(b.shape[0], -1)
    a = a - a.mean(axis=1, keepdims=True)
    b = b - b.mean(axis=1, keepdims=True)
    sa = np.sqrt(np.mean(a * a, axis=1))
    sb = np.sqrt(np.mean(b * b, axis=1))
    ncc = np.mean(a * b, axis=1) / np.maximum(sa * sb, 1e-12)
    flat_a, flat_b = sa < flat, sb < flat
    return np.where(flat_a & flat_b, 1.0, np.where(flat_a | flat_b, 0.0, ncc))


def identity_kept(prev_gray: np.ndarray, gray: np.ndarray, p0: np.ndarray, p1: np.ndarray,
                  z0: np.ndarray, z1: np.ndarray, params: TrackerParams) -> np.ndarray:
    """Bool per feature: its track still shows the same surface (module docstring, *track
    identity*): NCC of its patches at ``p0`` in ``prev_gray`` and at ``p1`` in ``gray`` at least
    ``ncc_min``, and depth ``z0`` -> ``z1`` (m; NaN where invalid: no test) changed by at most
    ``depth_jump_m``."""
    keep = np.ones(p0.shape[0], bool)
    if p0.shape[0] == 0:
        return keep
    if params.ncc_min > 0:
        ncc = patch_ncc(sample_patches(prev_gray, p0, params.ncc_patch_px),
                        sample_patches(gray, p1, params.ncc_patch_px), params.ncc_flat)
        keep &= ncc >= params.ncc_min
    with np.errstate(invalid="ignore"):
        keep &= ~(np.abs(z1 - z0) > params.depth_jump_m)
    return keep


def track_frame(state: TrackerState, image: np.ndarray, depth: np.ndarray | None,
                time: float, intrinsics: PinholeIntrinsics, grid: CellGrid,
                params: TrackerParams = TrackerParams()) -> TrackerState:
    """Process one frame; returns the new state (the input state is not modified).

    Skips (returns an unchanged copy with ``skipped`` incremented) an empty image, a black
    image, or a frame whose ``time`` is not after the last processed one, so that a dropped
    frame never erases the tracks. The new ``sdot`` and ``features`` are in the returned state.
    """
    if not np.isfinite(time):
        raise ValueError(f"frame time must be finite, got {time}")
    new = state.copy()
    img = np.asarray(image)
    if img.size == 0 or time <= state.last_time:
        new.skipped += 1
        return new
    gray = to_gray(img)
    if gray.shape != (intrinsics.height, intrinsics.width):
        raise ValueError(f"color image is {gray.shape[1]}x{gray.shape[0]} but the intrinsics are "
                         f"{intrinsics.width}x{intrinsics.height}")
    if _frame_is_blank(gray, params):
        new.skipped += 1
        return new

    have_prev = state.prev_gray.size > 0 and state.ids.size > 0
    if have_prev:
        # Forward then backward; a feature is kept only if both succeed and it returns to
        # where it started (the forward–backward check rejects occlusion and patches that
        # changed, where LK "converges" to a wrong place).
        p0 = state.p_px.astype(np.float32)
        prev = state.features
        velocity = np.zeros_like(p0)
        if params.predict_flow and len(prev) == p0.shape[0]:  # the previous frame's flows, same order
            velocity = prev.flow_px.astype(np.float32)
        guess = p0 + velocity if params.predict_flow else None
        p1, ok_f = _lk(state.prev_gray, gray, p0, params, guess)
        p0_back, ok_b = _lk(gray, state.prev_gray, p1, params, p1 - velocity if params.predict_flow else None)
        fb = np.linalg.norm(p0_back - p0, axis=1)
        h, w = gray.shape
        inside = (p1[:, 0] >= 0) & (p1[:, 0] <= w - 1) & (p1[:, 1] >= 0) & (p1[:, 1] <= h - 1)
        keep = ok_f & ok_b & inside & np.isfinite(p1).all(axis=1) & (fb < params.fb_threshold_px)
        # Track identity: the same surface in both frames, by appearance and by depth.
        z0 = np.full(p0.shape[0], np.nan)
        if len(prev) == p0.shape[0]:    # the previous frame's features, in the tracks' order
            z0 = np.where(prev.valid, prev.p_CP[:, 2], np.nan)
        p1_CP, valid1 = back_project(np.where(keep[:, None], p1, 0.0), depth, intrinsics)
        z1 = np.where(valid1, p1_CP[:, 2], np.nan)
        same = identity_kept(state.prev_gray, gray, p0[keep], p1[keep], z0[keep], z1[keep],
                             params)
        new.identity_drops += int(np.sum(~same))
        keep[np.flatnonzero(keep)[~same]] = False
        ids, pts, flow = state.ids[keep], p1[keep], (p1 - p0)[keep].astype(float)
        p_CP, valid = p1_CP[keep], valid1[keep]  # back-projected once, for the identity test
        dt = time - state.last_time
        sdot = cell_visual_change(grid, pts, flow, dt, params.min_flow_px)
    else:
        ids = np.zeros(0, np.int64)
        pts = np.zeros((0, 2), np.float32)
        flow = np.zeros((0, 2))
        p_CP, valid = np.zeros((0, 3)), np.zeros(0, bool)
        sdot = np.zeros(grid.num_cells)

    if ids.size < params.reseed_fraction * params.max_corners:
        seeds = _seed(gray, pts, params, params.max_corners - ids.size)
        if seeds.shape[0] > 0:
            new_ids = np.arange(new.next_id, new.next_id + seeds.shape[0], dtype=np.int64)
            new.next_id += seeds.shape[0]
            ids = np.concatenate([ids, new_ids])
            pts = np.concatenate([pts, seeds])
            flow = np.concatenate([flow, np.zeros((seeds.shape[0], 2))])
            seed_CP, seed_valid = back_project(seeds, depth, intrinsics)
            p_CP = np.concatenate([p_CP, seed_CP])
            valid = np.concatenate([valid, seed_valid])

    new.prev_gray = gray.copy()
    new.ids = ids
    new.p_px = pts.astype(np.float32)
    new.last_time = float(time)
    new.frames += 1
    new.sdot = sdot
    new.features = TrackedFeatures(
        ids=ids.copy(), p_px=pts.astype(float), flow_px=flow, p_CP=p_CP, valid=valid,
        cell=grid.cell_of(pts), symmetric=np.zeros(ids.size, bool), time=float(time))
    return new
