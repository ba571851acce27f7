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
  accumulate it. On the rod the tracker's features are the yellow cells' centres (its Shi-Tomasi
  block of 7 px is larger than a 6-7 x 7-9 px cell; ``bench_hand_eye_candidates.py`` snaps them
  to the rod's known marks), of which the 5 x 5 window sees part of the edges only; with
  ``blob_window_px`` a feature on a small bright mark is moved to the whole mark's intensity
  centroid instead (``blob_centres``);
- the depth comes from a small window of the depth image around the refined pixel, taken only
  when at least ``min_fraction`` of the window is within ``surface_tolerance`` of the window's
  median (a window that straddles a silhouette mixes the tool and the background: no point).
  The mark lies on a flat face, so with ``depth_plane`` the face's plane is fitted to those
  same-surface pixels and the refined pixel's own ray is intersected with it (``plane_depth``):
  the window is centred on the ROUNDED pixel while the corner is sub-pixel, and on a face seen
  obliquely the depth changes by several millimetres per pixel, so the window's median is off
  by up to half a pixel's depth gradient. Without it the depth is the median (per-pixel noise
  drops by about the window's side either way).

The tracker (``optical_flow``) is untouched: its tracks keep their own pixels; a consumer that
needs fixed points (the candidate identifiers) refines the features it uses.
"""

# No "from __future__ import annotations": yaml_load_typed reads RefinementParams' real field types.

from dataclasses import dataclass
from typing import NamedTuple

import cv2
import numpy as np

from sustain_drake.perception.optical_flow import PinholeIntrinsics, pinhole_points, sample_patches, to_gray


@dataclass
class RefinementParams:
    """Sub-pixel corners and robust depth for the tracked features an identifier uses (see the
    module docstring); each step beyond ``cornerSubPix`` and the median depth is off by default."""

    corner_window_px: int = 2  # px: half side of cornerSubPix's search window; 0 keeps the tracked pixel
    # px: a refined pixel farther than this from the tracked one is no corner of the track (no point)
    max_shift_px: float = 2.0
    depth_window_px: int = 2  # px: half side of the depth median window; 0 takes the one nearest pixel
    # m: window pixels within this of the median depth are on the same surface
    surface_tolerance: float = 0.008
    min_fraction: float = 0.7  # fraction of the window's pixels that must be on that surface (else no point)
    # take the depth where the refined pixel's ray meets the plane fitted to the same-surface pixels
    # (plane_depth): on an oblique face the median is off by half a pixel's depth gradient; False: median
    depth_plane: bool = False
    # px: half side of a window; a feature on a bright mark wholly inside it moves to the mark's
    # intensity centroid (blob_centres): a rod cell is smaller than the tracker's 7 px block; 0: off
    blob_window_px: int = 0
    # deg: with depth_plane, a point whose face is seen more obliquely than this is invalid (a
    # pixel's error along the face is tan(angle) times as large along the ray); 90: off
    max_incidence_deg: float = 90.0
    # px: half side k of the (2 k + 1)^2 window about which the image must be centrally symmetric
    # (min_symmetry): a saddle or mark centre stays on the same tool point under any view; 0: off
    symmetry_window_px: int = 0
    # least correlation of the window with itself turned 180 deg (1: symmetric, -1: a straight edge)
    min_symmetry: float = 0.5
    # px: half side of the template each track's point is anchored to (perception.anchored_points:
    # the point is where the track's first patch aligns each frame, not a corner); 0: off
    anchor_window_px: int = 0

    def __post_init__(self):
        if not -1.0 <= self.min_symmetry <= 1.0:
            raise ValueError(f"min_symmetry must be in [-1, 1] ({self})")
        if (self.corner_window_px < 0 or self.depth_window_px < 0 or self.blob_window_px < 0
                or self.symmetry_window_px < 0 or self.anchor_window_px < 0):
            raise ValueError(f"window sizes must be >= 0 ({self})")
        if not 0 < self.max_incidence_deg <= 90:
            raise ValueError(f"max_incidence_deg must be in (0, 90] ({self})")
        if not (self.max_shift_px > 0 and self.surface_tolerance > 0 and 0 < self.min_fraction <= 1):
            raise ValueError(f"max_shift_px, surface_tolerance and min_fraction must be positive ({self})")


# Least central symmetry of a point kept as a corner under any view. A sub-pixel point moves, when
# the blur, the pixel footprint or the anti-aliasing about it change with the view, by the gradient
# of that change applied to the window's antisymmetric part A; central_symmetry is
# (|S|^2 - |A|^2) / (|S|^2 + |A|^2) with S the symmetric part, so 0.9 keeps |A| <= 0.23 |S| (a
# printed saddle: perspective and shading across the window) and turns away the saddles and blobs
# of a random texture, symmetric at 0.5 (|A| = 0.58 |S|) but moving with the view.
SADDLE_SYMMETRY = 0.9

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
    refined = refined.astype(float)
    if params.blob_window_px > 0 and ok.any():
        centres, is_blob = blob_centres(gray, p, params.blob_window_px)
        refined = np.where(is_blob[:, None], centres, refined)
    ok &= np.isfinite(refined).all(axis=1)
    ok &= np.linalg.norm(refined - p, axis=1) <= params.max_shift_px
    if params.symmetry_window_px > 0 and ok.any():
        ok[ok] = central_symmetry(gray, refined[ok], params.symmetry_window_px) >= params.min_symmetry
    return refined, ok


def central_symmetry(gray: np.ndarray, p_px: np.ndarray, half: int) -> np.ndarray:
    """How centrally symmetric the image is about each sub-pixel point (K,): the normalised
    correlation of the ``(2 half + 1)^2`` window centred on the point (bilinear,
    ``optical_flow.sample_patches``) with the same window turned by 180 deg, both less the window's
    mean. 1 for a checker saddle or a round mark's centre, about -1 on a straight edge, in between
    for an L corner; -1 for a window that leaves the image or has no texture."""
    p = np.asarray(p_px, dtype=float).reshape(-1, 2)
    side = 2 * half + 1
    out = np.full(p.shape[0], -1.0)
    h, w = np.shape(gray)
    inside = np.flatnonzero(np.isfinite(p).all(axis=1) & (p[:, 0] >= half) & (p[:, 0] <= w - 1 - half)
                            & (p[:, 1] >= half) & (p[:, 1] <= h - 1 - half))
    if inside.size == 0:
        return out
    windows = sample_patches(np.asarray(gray, np.float32), p[inside], side).astype(float)
    windows -= windows.mean(axis=(1, 2), keepdims=True)
    energy = np.einsum("kij,kij->k", windows, windows)
    turned = np.einsum("kij,kij->k", windows, windows[:, ::-1, ::-1])
    textured = energy > 1e-6 * side * side
    out[inside[textured]] = turned[textured] / energy[textured]
    return out


def blob_centres(gray: np.ndarray, p_px: np.ndarray, half: int, min_contrast: float = 40.0):
    """Intensity centroids of bright marks (``(centres (K x 2), is_blob (K,))``, px): in the
    ``(2 half + 1)^2`` window around each rounded pixel, the bright pixels (above the middle of the
    window's 10-90 % intensity range, at least ``min_contrast`` grey levels wide) connected to the
    pixel (4-connectivity), grown by one pixel for their anti-aliased edge, weighted by their
    brightness between the dark and bright levels. Only a region that does not touch the window's
    border (the whole mark is seen) and has at least 4 pixels is a blob.

    The centroid of the whole region uses every edge pixel's partial coverage, so it is stable to
    a few hundredths of a pixel from frame to frame; a corner window sees a part of the mark's
    edges only, which part depending on where the window falls and how the face is foreshortened
    (1-2 mm of wander on the rod). Under perspective the centroid of the projected mark differs
    from the projection of its centre by a fraction of the mark's size times its size over the
    depth (18 mm x 18 mm / 0.75 m: about 0.4 mm at most, nearly constant over a track)."""
    g = np.asarray(gray, dtype=np.float32)
    p = np.asarray(p_px, dtype=float).reshape(-1, 2)
    centres, is_blob = np.full(p.shape, np.nan), np.zeros(p.shape[0], bool)
    h, w = g.shape
    finite = np.isfinite(p).all(axis=1)
    u0 = np.rint(np.where(finite, p[:, 0], -1)).astype(np.int64)
    v0 = np.rint(np.where(finite, p[:, 1], -1)).astype(np.int64)
    inside = np.flatnonzero(finite & (u0 >= half) & (u0 < w - half) & (v0 >= half) & (v0 < h - half))
    if inside.size == 0:
        return centres, is_blob
    # Every window at once; only the bright, contrasted ones (a few of the features) go on to the
    # per-window connected components.
    offsets = np.arange(-half, half + 1)
    windows = g[v0[inside, None, None] + offsets[None, :, None],
                u0[inside, None, None] + offsets[None, None, :]]
    lo, hi = np.percentile(windows.reshape(inside.size, -1), (10, 90), axis=1)
    mid = 0.5 * (lo + hi)
    maybe = (hi - lo >= min_contrast) & (windows[:, half, half] > mid)
    kernel = np.ones((3, 3), np.uint8)
    rows, cols = np.mgrid[-half:half + 1, -half:half + 1]
    for j in np.flatnonzero(maybe):
        k, window = inside[j], windows[j]
        _, labels = cv2.connectedComponents((window > mid[j]).astype(np.uint8), connectivity=4)
        region = labels == labels[half, half]
        touches_border = region[0].any() or region[-1].any() or region[:, 0].any() or region[:, -1].any()
        if region.sum() < 4 or touches_border:
            continue
        # Its anti-aliased edge, but not another mark's pixels (a checker's diagonal neighbours).
        grown = cv2.dilate(region.astype(np.uint8), kernel).astype(bool) & ((labels == 0) | region)
        weight = np.clip((window - lo[j]) / (hi[j] - lo[j]), 0.0, 1.0) * grown
        total = weight.sum()
        centres[k] = (u0[k] + (weight * cols).sum() / total, v0[k] + (weight * rows).sum() / total)
        is_blob[k] = True
    return centres, is_blob


def local_depth(depth: np.ndarray, p_px: np.ndarray, params: RefinementParams,
                intrinsics: PinholeIntrinsics | None = None) -> np.ndarray:
    """Robust depth at each (sub-pixel) pixel (m), from the ``(2 k + 1)^2`` window around the
    rounded pixel: NaN when fewer than ``min_fraction`` of its pixels are valid and within
    ``surface_tolerance`` of the window's median; else the median, or with ``depth_plane`` the
    depth where the pixel's own ray meets the plane fitted to those same-surface pixels
    (``plane_depth``), NaN too when ``intrinsics`` are given and that plane is seen beyond
    ``max_incidence_deg`` (``incidence``)."""
    d = np.asarray(depth)  # the windows alone are turned to float below, not the whole image
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
    window = d[rows, cols].reshape(int(inside.sum()), -1).astype(float)
    window = np.where(np.isfinite(window) & (window > 0), window, np.nan)
    with np.errstate(all="ignore"):
        median = _row_nanmedian(window)
        same = np.abs(window - median[:, None]) <= params.surface_tolerance
    good = np.isfinite(median) & (same.mean(axis=1) >= params.min_fraction)
    values = median
    if params.depth_plane and k > 0 and good.any():
        du, dv = np.meshgrid(offsets, offsets)  # window order: rows are v, columns u
        # Offsets from the sub-pixel point itself, so that the fit's intercept is its depth.
        du = du.ravel()[None, :] - (p[inside, 0] - u[inside])[:, None]
        dv = dv.ravel()[None, :] - (p[inside, 1] - v[inside])[:, None]
        values, coef = plane_depth(window, same & good[:, None], du, dv)
        if intrinsics is not None and params.max_incidence_deg < 90.0:
            steep = incidence(coef, p[inside], intrinsics) > np.radians(params.max_incidence_deg)
            values = np.where(steep, np.nan, values)
    out[inside] = np.where(good, values, np.nan)
    return out


def _row_nanmedian(window: np.ndarray) -> np.ndarray:
    """``np.nanmedian(window, axis=1)`` (NaN for a row of NaNs, no warning), bit for bit: the mean
    of the two middle values (the middle one twice when odd) of each sorted row, as numpy's masked
    median computes it, without its per-call overhead (about 10x faster on a frame's windows)."""
    s = np.sort(window, axis=1)  # NaNs last
    n = np.count_nonzero(~np.isnan(window), axis=1)
    high = n // 2
    low = np.where(n % 2 == 1, high, high - 1)
    rows = np.arange(window.shape[0])
    with np.errstate(all="ignore"):
        median = (s[rows, low] + s[rows, high]) / 2.0
    return np.where(n > 0, median, np.nan)


def plane_depth(z: np.ndarray, use: np.ndarray, du: np.ndarray, dv: np.ndarray):
    """Depth (m) at pixel offset (0, 0) of the plane through the 3-D points of a depth window, and
    the plane's inverse depth ``(a, b, c)`` (``1 / z = a + b du + c dv``): ``(K,), (K x 3)`` for
    ``K`` windows of ``n`` pixels (``z``), the pixels to fit (``use``) and their offsets ``du, dv``
    (px).

    A plane ``n . p_C = d`` in the camera frame and the pinhole ray ``p_C = z r(u, v)``, with
    ``r = ((u - c_x) / f_x, (v - c_y) / f_y, 1)`` affine in the pixel, give ``1 / z = n . r / d``:
    the inverse depth of a plane is exactly affine in the pixel offsets, whatever the intrinsics.
    So a linear least-squares fit of ``1 / z = a + b du + c dv`` over the pixels ``use`` is the
    plane fitted with its errors along the rays (the depth camera's, with the same relative weight
    over a small window), and ``1 / a`` is where the ray at offset (0, 0) meets it. NaN for a
    window whose pixels do not define a plane (fewer than three, or all on one line)."""
    use = use & np.isfinite(z) & (z > 0)
    w = use.astype(float)
    inv = np.where(use, 1.0 / np.where(use, z, 1.0), 0.0)
    A = np.stack([np.ones_like(du), du, dv], axis=2)  # K x n x 3
    H = np.einsum("kni,kn,knj->kij", A, w, A)
    g = np.einsum("kni,kn,kn->ki", A, w, inv)
    coef = np.full((z.shape[0], 3), np.nan)
    ok = np.linalg.cond(H) < 1e8 if H.size else np.zeros(0, bool)
    if ok.any():
        coef[ok] = np.linalg.solve(H[ok], g[ok][:, :, None])[:, :, 0]
    with np.errstate(all="ignore"):
        at_point = np.where(coef[:, 0] > 0, 1.0 / coef[:, 0], np.nan)
    return at_point, coef


def incidence(coef: np.ndarray, p_px: np.ndarray, intrinsics: PinholeIntrinsics) -> np.ndarray:
    """The angle (rad) between the camera ray at each pixel ``p_px`` and the normal of the plane
    whose inverse depth about that pixel is ``coef`` (``plane_depth``): with ``1 / z = (n . r) / d``,
    ``n / d = (b f_x, c f_y, a - b (u - c_x) - c (v - c_y))`` and ``n . r / d = a`` at the pixel.
    0 for a face seen head-on, pi/2 at a grazing view (where a pixel's error along the face is
    ``tan`` of it times as large along the ray)."""
    a, b, c = coef[:, 0], coef[:, 1], coef[:, 2]
    p = np.asarray(p_px, dtype=float).reshape(-1, 2)
    x, y = (p[:, 0] - intrinsics.cx) / intrinsics.fx, (p[:, 1] - intrinsics.cy) / intrinsics.fy
    n = np.stack([b * intrinsics.fx, c * intrinsics.fy, a - b * (p[:, 0] - intrinsics.cx)
                  - c * (p[:, 1] - intrinsics.cy)], axis=1)
    with np.errstate(all="ignore"):
        cosine = np.abs(a) / (np.linalg.norm(n, axis=1) * np.sqrt(x * x + y * y + 1.0))
    return np.arccos(np.clip(cosine, 0.0, 1.0))


class RefinedPoints(NamedTuple):
    """``refine_features``' result for K tracked pixels."""

    p_CP: np.ndarray  # K x 3, m; a zero row where not valid (never NaN)
    valid: np.ndarray  # K: a point was measured
    p_px: np.ndarray  # K x 2: the refined pixel where valid, else the tracked one
    # K: valid and centrally symmetric (the symmetry test ran and passed); a valid point that is
    # not was refined without the test, or anchored on its patch (perception.anchored_points)
    symmetric: np.ndarray


def refine_features(image: np.ndarray, depth: np.ndarray, p_px: np.ndarray, intrinsics: PinholeIntrinsics,
                    params: RefinementParams | None = None) -> RefinedPoints:
    """The sub-pixel corner near each tracked pixel ``p_px`` and the robust depth there,
    back-projected with the pinhole model. A point without a corner nearby (with the symmetry test:
    without a centrally symmetric one) or without a clean depth is not valid."""
    params = RefinementParams() if params is None else params
    p = np.asarray(p_px, dtype=float).reshape(-1, 2)
    none = np.zeros(p.shape[0], bool)
    if p.shape[0] == 0 or np.size(image) == 0 or np.size(depth) == 0:
        return RefinedPoints(np.zeros((p.shape[0], 3)), none, p.copy(), none.copy())
    gray = to_gray(np.asarray(image))
    refined, ok = refine_pixels(gray, p, params)
    z = local_depth(depth, refined, params, intrinsics)
    ok &= np.isfinite(z) & (z > 0)
    p_CP = np.zeros((p.shape[0], 3))
    p_CP[ok] = pinhole_points(refined[ok], z[ok], intrinsics)  # with the robust depth
    # refine_pixels keeps only symmetric points when the symmetry test runs
    symmetric = ok.copy() if params.symmetry_window_px > 0 else none.copy()
    return RefinedPoints(p_CP, ok, np.where(ok[:, None], refined, p), symmetric)


def refine_points(image: np.ndarray, depth: np.ndarray, p_px: np.ndarray, intrinsics: PinholeIntrinsics,
                  params: RefinementParams | None = None, return_pixels: bool = False):
    """``(p_CP, valid)`` (K x 3 in m, K) of ``refine_features`` (and the pixels, K x 2, third, if
    ``return_pixels``)."""
    r = refine_features(image, depth, p_px, intrinsics, params)
    return (r.p_CP, r.valid, r.p_px) if return_pixels else (r.p_CP, r.valid)
