"""Drift-free 3-D points of tracked features for identification (pure numpy + OpenCV).

A frame-to-frame Lucas-Kanade track drifts: each frame adds a small matching error, and after
tens of seconds the tracked pixel is millimetres away from the mark it started on
(``bench/bench_hand_eye_candidates.py`` measured 6-10 mm after 15 s on the hand-eye rod). An
identifier that assumes a point fixed on the hand (Eq. (30)) reads that drift as a model error.
``refine_points`` ties the point back to the image each frame:

- the pixel is moved to the image's own corner (or the centre of a small mark) near the tracked
  position with ``cv2.cornerSubPix`` (the point where the image gradients in the window are
  orthogonal to the offset: a checker saddle, an L corner, or the centre of a square smaller than
  the window). The track's drift only has to stay within the window; the refined point does not
  accumulate it;
- the depth is the median of a small window around the refined pixel (the mark lies on a flat
  face: the median of a plane sampled symmetrically about a point is the depth at the point, and
  per-pixel depth noise drops by about the window's side), taken only when at least
  ``min_fraction`` of the window is within ``surface_tolerance`` of that median (a window that
  straddles a silhouette mixes the tool and the background: no point).

The tracker (``optical_flow``) is untouched: its tracks keep their own pixels; a consumer that
needs fixed points (the candidate identifiers) refines the features it uses.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from sustain_drake.perception.optical_flow import PinholeIntrinsics, pinhole_points, to_gray


@dataclass(frozen=True)
class RefinementParams:
    """Attributes:
    corner_window_px: half side of ``cornerSubPix``'s search window (px); 0 keeps the tracked pixel.
    max_shift_px: a refined pixel farther than this from the tracked one is not a corner of this
        track (no point).
    depth_window_px: half side of the depth median window (px); 0 takes the one nearest pixel.
    surface_tolerance: m; window pixels within this of the median are on the same surface.
    min_fraction: of the window's pixels that must be on that surface.
    """

    corner_window_px: int = 2
    max_shift_px: float = 2.0
    depth_window_px: int = 2
    surface_tolerance: float = 0.008
    min_fraction: float = 0.7

    def __post_init__(self):
        if self.corner_window_px < 0 or self.depth_window_px < 0:
            raise ValueError(f"window sizes must be >= 0 ({self})")
        if not (self.max_shift_px > 0 and self.surface_tolerance > 0 and 0 < self.min_fraction <= 1):
            raise ValueError(f"max_shift_px, surface_tolerance and min_fraction must be positive ({self})")


_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 0.01)


def refine_pixels(gray: np.ndarray, p_px: np.ndarray, params: RefinementParams):
    """Sub-pixel corners near ``p_px`` (K x 2) in a grayscale image: ``(refined, ok)``; a pixel
    whose window leaves the image, or that moves more than ``max_shift_px``, is not ok."""
    p = np.asarray(p_px, dtype=np.float32).reshape(-1, 2)
    ok = np.isfinite(p).all(axis=1)
    if params.corner_window_px == 0 or p.shape[0] == 0:
        return p.astype(float), ok
    w = params.corner_window_px
    h, width = gray.shape
    ok &= (p[:, 0] >= w + 1) & (p[:, 0] <= width - w - 2) & (p[:, 1] >= w + 1) & (p[:, 1] <= h - w - 2)
    refined = p.copy()
    if ok.any():
        corners = p[ok].reshape(-1, 1, 2).copy()
        cv2.cornerSubPix(gray, corners, (w, w), (-1, -1), _CRITERIA)
        refined[ok] = corners.reshape(-1, 2)
    ok &= np.isfinite(refined).all(axis=1)
    ok &= np.linalg.norm(refined - p, axis=1) <= params.max_shift_px
    return refined.astype(float), ok


def local_depth(depth: np.ndarray, p_px: np.ndarray, params: RefinementParams) -> np.ndarray:
    """Robust depth at each pixel (m): the median of a ``(2 k + 1)^2`` window, NaN when fewer than
    ``min_fraction`` of its pixels are valid and within ``surface_tolerance`` of that median."""
    d = np.asarray(depth, dtype=float)
    if d.ndim == 3:
        d = d[:, :, 0]
    p = np.asarray(p_px, dtype=float).reshape(-1, 2)
    k = params.depth_window_px
    out = np.full(p.shape[0], np.nan)
    if p.shape[0] == 0:
        return out
    u = np.rint(p[:, 0]).astype(np.int64)
    v = np.rint(p[:, 1]).astype(np.int64)
    inside = (u >= k) & (u < d.shape[1] - k) & (v >= k) & (v < d.shape[0] - k)
    if not inside.any():
        return out
    offsets = np.arange(-k, k + 1)
    rows = v[inside, None, None] + offsets[None, :, None]
    cols = u[inside, None, None] + offsets[None, None, :]
    window = d[rows, cols].reshape(int(inside.sum()), -1)
    window = np.where(np.isfinite(window) & (window > 0), window, np.nan)
    with np.errstate(all="ignore"):
        median = np.nanmedian(window, axis=1) if window.size else np.zeros(0)
        same = np.abs(window - median[:, None]) <= params.surface_tolerance
    good = np.isfinite(median) & (same.mean(axis=1) >= params.min_fraction)
    values = np.where(good, median, np.nan)
    out[inside] = values
    return out


def refine_points(image: np.ndarray, depth: np.ndarray, p_px: np.ndarray, intrinsics: PinholeIntrinsics,
                  params: RefinementParams = RefinementParams(), return_pixels: bool = False):
    """``(p_CP, valid)`` (K x 3 in m, K) for tracked pixels ``p_px``: the sub-pixel corner near each
    and the robust depth there, back-projected with the pinhole model (and the refined pixels,
    K x 2, third, if ``return_pixels``). A point without a corner nearby or without a clean depth
    is not valid (a zero row, never NaN; its pixel is the tracked one)."""
    p = np.asarray(p_px, dtype=float).reshape(-1, 2)
    if p.shape[0] == 0 or np.size(image) == 0 or np.size(depth) == 0:
        out = np.zeros((p.shape[0], 3)), np.zeros(p.shape[0], bool)
        return (*out, p.copy()) if return_pixels else out
    refined, ok = refine_pixels(to_gray(np.asarray(image)), p, params)
    z = local_depth(depth, refined, params)
    ok &= np.isfinite(z) & (z > 0)
    p_CP = np.zeros((p.shape[0], 3))
    p_CP[ok] = pinhole_points(refined[ok], z[ok], intrinsics)  # with the robust depth
    if return_pixels:
        return p_CP, ok, np.where(ok[:, None], refined, p)
    return p_CP, ok
