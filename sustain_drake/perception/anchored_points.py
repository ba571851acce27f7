"""Points anchored on the surface patch where each track began (pure numpy + OpenCV).

Eq. (30) holds for a point fixed on the hand: the same physical point in every frame. A
frame-to-frame Lucas-Kanade track is not one: each frame adds a small matching error, and after
tens of seconds its pixel is millimetres away from where it started. What makes a point fixed on
its surface, whatever the texture (a checker, wood grain, print, speckle), is the patch of
surface around it, so each track's point is tied to the patch it saw in its first frame: the
*anchor*. Every frame, that first appearance (the template) is aligned to the image by an affine
warp (a small patch of a flat face under any view is, to first order, an affine image of itself),
and the point is where the warp puts the template's centre. The point's error does not grow with
the track's age: it is that of one alignment.

The alignment is the inverse-compositional Lucas-Kanade of Baker and Matthews ("Lucas-Kanade 20
years on", 2004) with the affine warp ``W(x; p) = [[1 + p1, p3, p5], [p2, 1 + p4, p6]] (x, y, 1)``,
run on every anchor at once (one ``cv2.remap`` per iteration for all of them). Its Gauss-Newton
Hessian is the template's own, computed once when the anchor is made. The warped image is matched
to the template after removing each one's mean and contrast over the template's mask (a face
turning towards or away from a light changes its brightness, not its pattern), which is the
normalised correlation (ZNCC) that also judges the result.

The template's mask keeps only the pixels on the same surface as its centre (the depth image:
within ``surface_tolerance`` of the centre's depth): a patch over a silhouette would otherwise
follow the background behind the tool. An anchor *pins* its point when the alignment fixes the
centre on its surface (1 sd, from the residual and the masked template's Hessian, times the metres
a pixel spans at its depth) within the depth camera's noise there: the sample's error is then the
depth camera's. A patch with a single edge (a plain bar's side, a silhouette) fixes nothing along
it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import cv2
import numpy as np

from sustain_drake.perception.optical_flow import PinholeIntrinsics, pinhole_points, to_gray
from sustain_drake.perception.point_refinement import (
    RefinedPoints,
    RefinementParams,
    local_depth,
    refine_features,
)

# The alignment stops once no anchor's centre moves by more than this in an iteration, px.
CONVERGED_PX = 0.01
MAX_ITERATIONS = 12
# Least ZNCC of the aligned patch with the template: below it the patch is not the same surface
# under an affine view (an occlusion, a face turned beyond a first-order view change, the wrong
# place), and the anchor ends. The renderer's and a camera's pixel noise (a few grey levels on a
# contrast of tens) leave a clean alignment at 0.97-1.
MIN_CORRELATION = 0.9
# px: the radius about a template's centre whose pixels seed the fit of its face's plane
FACE_SEED_PX = 3.0
# Below this ZNCC (and still at least MIN_CORRELATION) the aligned patch becomes the anchor's
# template (``_refreshed``): the appearance has changed enough to matter, while the alignment is
# still sure of the point (a clean alignment is at 0.98-1).
REFRESH_CORRELATION = 0.97
# grey levels (of 255), 1 sd: the camera's pixel noise, the floor of an alignment's residual (a
# rendered image has none but its quantisation, 0.3; a camera's is 1-3)
PIXEL_NOISE = 1.0
# Least fraction of the template's pixels on the centre's surface (else no anchor is made): a
# quarter leaves a 17 x 17 template 72 pixels for its six warp parameters.
MIN_MASK_FRACTION = 0.25
# px: the image is smoothed by a Gaussian of this sigma before templates are cut and aligned: the
# alignment samples it between pixels (bilinear), which on sharp print and a renderer's aliased
# edges moves a patch by a phase-dependent tenth of a pixel; a band-limited image samples true
BLUR_SIGMA_PX = 1.0
# px per frame: the largest correction of a track's predicted centre that is still the same anchor
# (a track that jumps has found another patch).
MAX_CORRECTION_PX = 3.0


def _empty(shape, dtype=float):
    return field(default_factory=lambda: np.zeros(shape, dtype))


@dataclass(frozen=True)
class Anchors:
    """K anchors, one per track id (immutable: an update makes a new one).

    - ``ids``: the track ids (int64, sorted).
    - ``templates``: K x S x S, the track's first patch, zero mean and unit contrast over its mask.
    - ``masks``: K x S x S, 1 on the centre's surface, else 0 (float).
    - ``hessian_inv``: K x 6 x 6, the inverse of the masked template's Gauss-Newton Hessian.
    - ``steepest``: K x S*S x 6, the masked steepest-descent images (template gradient x dW/dp).
    - ``warps``: K x 2 x 3, template coordinates (offsets from its centre, px) -> image pixels.
    - ``track_px``: K x 2, the track's own pixel when last aligned (to predict the next frame).
    - ``alive``: K, False once an alignment failed (the id never gets an anchor again).
    - ``contrast``: K, the template's RMS contrast over its mask before normalising, grey levels.
    - ``points``: K x 2, the anchor's point in template coordinates (``best_point``).
    """

    ids: np.ndarray = _empty(0, np.int64)
    templates: np.ndarray = _empty((0, 0, 0), np.float32)
    masks: np.ndarray = _empty((0, 0, 0), np.float32)
    hessian_inv: np.ndarray = _empty((0, 6, 6))
    steepest: np.ndarray = _empty((0, 0, 6))
    warps: np.ndarray = _empty((0, 2, 3))
    track_px: np.ndarray = _empty((0, 2))
    alive: np.ndarray = _empty(0, bool)
    contrast: np.ndarray = _empty(0)
    points: np.ndarray = _empty((0, 2))

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    def take(self, rows: np.ndarray) -> Anchors:
        return Anchors(*(getattr(self, name)[rows] for name in _FIELDS))


_FIELDS = ("ids", "templates", "masks", "hessian_inv", "steepest", "warps", "track_px", "alive", "contrast",
           "points")


@dataclass(frozen=True)
class AnchoredPixels:
    """``anchor_step``'s result for the K tracks of a frame (same order)."""

    p_px: np.ndarray  # K x 2: the anchored point's pixel (the track's own where not pinned)
    pinned: np.ndarray  # K: the anchor is alive, aligned this frame and pins its point
    sd_px: np.ndarray  # K: the aligned centre's largest 1-sd uncertainty, px (inf where not aligned)
    correlation: np.ndarray  # K: ZNCC of the aligned patch with the template (-1 where not aligned)


def _grid(half: int) -> tuple[np.ndarray, np.ndarray]:
    offsets = np.arange(-half, half + 1, dtype=np.float32)
    x, y = np.meshgrid(offsets, offsets)  # rows are y (v), columns x (u)
    return x, y


def _shading_out(values: np.ndarray, masks: np.ndarray, half: int) -> np.ndarray:
    """``values`` (K x S x S x m) less their masked least-squares fit by the shading basis
    ``(1, x, y)`` of each patch: what a brightness, and a brightness changing linearly across the
    patch (a light's falloff, a face turning towards it), cannot explain."""
    x, y = _grid(half)
    basis = np.stack([np.ones_like(x), x, y], axis=2).reshape(-1, 3)  # n x 3
    m = masks.reshape(masks.shape[0], -1)  # K x n
    v = values.reshape(values.shape[0], -1, values.shape[-1])  # K x n x m
    gram = np.einsum("ni,kn,nj->kij", basis, m, basis) + 1e-9 * np.eye(3)
    coef = np.linalg.solve(gram, np.einsum("ni,kn,knm->kim", basis, m, v))
    return ((v - np.einsum("ni,kim->knm", basis, coef)) * m[:, :, None]).reshape(values.shape)


def _normalised(patches: np.ndarray, masks: np.ndarray, half: int) -> tuple[np.ndarray, np.ndarray]:
    """Patches without their shading (``_shading_out``) over their masked contrast (RMS); and that
    contrast."""
    weight = masks.sum(axis=(1, 2))
    flat = _shading_out(patches[..., None], masks, half)[..., 0]
    contrast = np.sqrt((flat * flat).sum(axis=(1, 2)) / np.maximum(weight, 1.0))
    return flat / np.maximum(contrast, 1e-6)[:, None, None], contrast


def _warp_patches(gray: np.ndarray, warps: np.ndarray, half: int) -> np.ndarray:
    """K x S x S patches of ``gray`` at each warp of the template grid (bilinear; one remap)."""
    x, y = _grid(half)
    k, side = warps.shape[0], 2 * half + 1
    if k == 0:
        return np.zeros((0, side, side), np.float32)
    w = warps.astype(np.float32)
    map_u = w[:, 0, 0, None, None] * x + w[:, 0, 1, None, None] * y + w[:, 0, 2, None, None]
    map_v = w[:, 1, 0, None, None] * x + w[:, 1, 1, None, None] * y + w[:, 1, 2, None, None]
    out = cv2.remap(gray, map_u.reshape(k * side, side), map_v.reshape(k * side, side),
                    cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)
    return out.reshape(k, side, side)


def _face_masks(depths: np.ndarray, z: np.ndarray, half: int, tolerance: float) -> np.ndarray:
    """K x S x S float masks of the template pixels on the centre's face: within ``tolerance`` (m)
    of the plane fitted (in inverse depth, exactly affine in the pixel for a plane) first to the
    pixels within ``FACE_SEED_PX`` of the centre and ``tolerance`` of its depth ``z``, then again to
    every pixel within ``tolerance`` of that plane. A mask by the centre's depth alone would keep a
    thin band of a face seen obliquely (its depth changes by millimetres per pixel) and the edge of
    the next face."""
    x, y = _grid(half)
    d = depths.astype(float)
    finite = np.isfinite(d) & (d > 0)
    inverse = np.where(finite, 1.0 / np.where(finite, d, 1.0), 0.0)
    basis = np.stack([np.ones_like(x), x, y], axis=2).reshape(-1, 3).astype(float)
    use = finite & (np.abs(d - z[:, None, None]) <= tolerance) & (np.hypot(x, y) <= FACE_SEED_PX)
    plane = np.full(d.shape, np.nan)
    for _ in range(2):
        w = use.reshape(use.shape[0], -1).astype(float)
        gram = np.einsum("ni,kn,nj->kij", basis, w, basis)
        ok = np.linalg.cond(gram) < 1e8 if len(gram) else np.zeros(0, bool)
        if not ok.any():
            break
        coef = np.zeros((len(gram), 3))
        rhs = np.einsum("ni,kn,kn->ki", basis, w, inverse.reshape(len(gram), -1))
        coef[ok] = np.linalg.solve(gram[ok], rhs[ok][:, :, None])[:, :, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            plane = np.where(ok[:, None, None], 1.0 / (basis @ coef.T).T.reshape(d.shape), np.nan)
        use = finite & (np.abs(d - plane) <= tolerance)
    return use.astype(np.float32)


def _templates(patches: np.ndarray, masks: np.ndarray, half: int):
    """What the alignment needs of K patches (K x S x S) and their face masks: ``(templates,
    steepest, hessian_inv, contrast, usable)``: the patches normalised, the masked steepest-descent
    images with the shading projected out, the inverse Gauss-Newton Hessian, the RMS contrast
    (grey levels), and whether the patch has texture and determines its warp."""
    k, side = patches.shape[0], 2 * half + 1
    # The gradients use central differences: a pixel counts only with both neighbours on the surface.
    inner = masks.copy()
    inner[:, :, 1:-1] *= masks[:, :, :-2] * masks[:, :, 2:]
    inner[:, 1:-1, :] *= masks[:, :-2, :] * masks[:, 2:, :]
    inner[:, [0, -1], :] = 0.0
    inner[:, :, [0, -1]] = 0.0
    templates, contrast = _normalised(patches, masks, half)
    gy, gx = np.gradient(templates, axis=(1, 2))
    x, y = _grid(half)
    # dW/dp at p = 0: du = (x, 0, y, 0, 1, 0), dv = (0, x, 0, y, 0, 1); with the shading projected
    # out (Baker and Matthews' "project out" of appearance variation), as it is from the error.
    steepest = np.stack([gx * x, gy * x, gx * y, gy * y, gx, gy], axis=3)
    steepest = _shading_out(steepest, inner, half).reshape(k, side * side, 6)
    hessian = np.einsum("kni,knj->kij", steepest, steepest)
    usable = (contrast > 1e-3) & (np.linalg.cond(hessian) < 1e8 if k else np.zeros(0, bool))
    hessian_inv = np.zeros_like(hessian)
    if usable.any():
        hessian_inv[usable] = np.linalg.inv(hessian[usable])
    return (templates.astype(np.float32), steepest.astype(np.float32), hessian_inv, contrast.astype(float),
            usable)


def make_anchors(gray: np.ndarray, depth: np.ndarray, ids: np.ndarray, p_px: np.ndarray,
                 z: np.ndarray, half: int, surface_tolerance: float) -> Anchors:
    """New anchors for tracks ``ids`` at their sub-pixel pixels ``p_px`` (K x 2) with centre depths
    ``z`` (K, m; NaN: no anchor) in a float32 gray image and its depth image (m): templates of
    ``(2 half + 1)^2`` pixels, masked to the pixels within ``surface_tolerance`` (m) of the centre's
    depth. A track whose template leaves the image, has too few pixels on its centre's surface, or
    no texture there gets a dead anchor (``alive`` False)."""
    k = len(ids)
    if k == 0:
        return Anchors()
    p = np.asarray(p_px, dtype=float).reshape(-1, 2)
    warps = np.zeros((k, 2, 3))
    warps[:, 0, 0] = warps[:, 1, 1] = 1.0
    warps[:, :, 2] = p
    h, w = gray.shape
    inside = (np.isfinite(p).all(axis=1) & (p[:, 0] >= half + 1) & (p[:, 0] <= w - half - 2)
              & (p[:, 1] >= half + 1) & (p[:, 1] <= h - half - 2) & np.isfinite(z))
    patches = np.nan_to_num(_warp_patches(gray, warps, half))
    depths = _warp_patches(np.asarray(depth, np.float32), np.rint(warps), half)
    masks = _face_masks(depths, np.asarray(z, float), half, surface_tolerance)
    templates, steepest, hessian_inv, contrast, usable = _templates(patches, masks, half)
    enough = masks.mean(axis=(1, 2)) >= MIN_MASK_FRACTION
    alive = inside & enough & usable
    points = np.zeros((k, 2))
    if alive.any():
        points[alive] = best_point(hessian_inv[alive], 0.5 * half)
    return Anchors(np.asarray(ids, np.int64), templates, masks, hessian_inv, steepest, warps, p.copy(),
                   alive, contrast, points)


def _point_jacobian(c: np.ndarray) -> np.ndarray:
    """K x 2 x 6: d W(c; p) / dp at p = 0 for template points ``c`` (K x 2)."""
    J = np.zeros((c.shape[0], 2, 6))
    J[:, 0, 0] = J[:, 1, 1] = c[:, 0]
    J[:, 0, 2] = J[:, 1, 3] = c[:, 1]
    J[:, 0, 4] = J[:, 1, 5] = 1.0
    return J


def best_point(hessian_inv: np.ndarray, reach: float) -> np.ndarray:
    """The template point (K x 2, px from its centre, within ``reach`` of it) whose position the
    affine alignment determines best: the minimum of ``trace(J_c H^-1 J_c^T)`` over ``c``, a
    quadratic. Any point fixed in the template is fixed on the surface; the template's centre is
    only one of them, and where the texture lies to one side of it, its position trades off
    against the warp's shear and scale (a small change of appearance, such as a pixel's footprint
    turning with the view, then moves it by a pixel or more while the match stays at 0.999)."""
    u, v = hessian_inv[:, [0, 2, 4]][:, :, [0, 2, 4]], hessian_inv[:, [1, 3, 5]][:, :, [1, 3, 5]]
    M = u + v
    c = -np.linalg.solve(M[:, :2, :2], M[:, :2, 2:3])[:, :, 0]
    norm = np.linalg.norm(c, axis=1, keepdims=True)
    return np.where(norm > reach, c * reach / np.maximum(norm, 1e-12), c)


def align(gray: np.ndarray, anchors: Anchors, predicted: np.ndarray, half: int):
    """Inverse-compositional affine alignment of every anchor's template to ``gray`` from the
    warps ``predicted`` (K x 2 x 3): ``(warps, correlation (K,), sd_px (K,))``. ``sd_px`` is the
    aligned centre's largest 1-sd uncertainty in the image (px): the residual's variance times the
    translation block of the inverse Hessian, mapped by the warp's linear part."""
    k = len(anchors)
    warps = np.array(predicted, dtype=float)
    active = np.ones(k, bool)
    for _ in range(MAX_ITERATIONS):
        rows = np.flatnonzero(active)
        if rows.size == 0:
            break
        patches = _warp_patches(gray, warps[rows], half)
        valid = np.isfinite(patches).all(axis=(1, 2))
        normalised, _ = _normalised(np.nan_to_num(patches), anchors.masks[rows], half)
        error = (normalised - anchors.templates[rows]).reshape(rows.size, -1)
        step = np.einsum("kij,knj,kn->ki", anchors.hessian_inv[rows], anchors.steepest[rows], error)
        # W <- W o W(dp)^-1
        delta = np.zeros((rows.size, 3, 3))
        delta[:, 0, :] = [1.0, 0.0, 0.0] + step[:, [0, 2, 4]]
        delta[:, 1, :] = [0.0, 1.0, 0.0] + step[:, [1, 3, 5]]
        delta[:, 2, 2] = 1.0
        full = np.zeros((rows.size, 3, 3))
        full[:, :2] = warps[rows]
        full[:, 2, 2] = 1.0
        updated = full @ np.linalg.inv(delta)
        moved = np.linalg.norm(updated[:, :2, 2] - warps[rows, :, 2], axis=1)
        warps[rows] = np.where(valid[:, None, None], updated[:, :2], warps[rows])
        active[rows] = valid & (moved > CONVERGED_PX)
    patches = _warp_patches(gray, warps, half)
    valid = np.isfinite(patches).all(axis=(1, 2))
    normalised, _ = _normalised(np.nan_to_num(patches), anchors.masks, half)
    weight = anchors.masks.sum(axis=(1, 2))
    correlation = (normalised * anchors.templates).sum(axis=(1, 2)) / np.maximum(weight, 1.0)
    residual = ((normalised - anchors.templates) ** 2).sum(axis=(1, 2)) / np.maximum(weight - 9.0, 1.0)
    # Never below the camera's own pixel noise (a clean match of a noiseless image is no proof that a
    # patch pins its centre: along an edge it does not, whatever the residual).
    residual = np.maximum(residual, (PIXEL_NOISE / np.maximum(anchors.contrast, 1e-6)) ** 2)
    # The anchor's point's covariance in template coordinates (J_c H^-1 J_c^T), then in the image.
    J = _point_jacobian(anchors.points)
    point_cov = J @ anchors.hessian_inv @ np.transpose(J, (0, 2, 1)) * residual[:, None, None]
    linear = warps[:, :, :2]
    image_cov = linear @ point_cov @ np.transpose(linear, (0, 2, 1))
    sd = np.sqrt(np.maximum(np.linalg.eigvalsh(image_cov)[:, -1], 0.0)) if k else np.zeros(0)
    correlation = np.where(valid, correlation, -1.0)
    sd = np.where(valid, sd, np.inf)
    return warps, correlation, sd


def anchor_step(anchors: Anchors, gray: np.ndarray, depth: np.ndarray, ids: np.ndarray,
                p_px: np.ndarray, z: np.ndarray, half: int, surface_tolerance: float,
                max_sd_px: np.ndarray | float = np.inf) -> tuple[Anchors, AnchoredPixels]:  # fmt: skip
    """One frame: the anchors of the tracks ``ids`` (their pixels ``p_px``, K x 2, and the depths
    ``z`` at them, K, m, NaN where none) aligned to ``gray`` (uint8 or float32), new anchors
    (``make_anchors``) for new tracks, and those of ended tracks dropped. An aligned point is pinned
    when its centre's sd is at most ``max_sd_px`` (K or one value, px). Returns the new anchors and
    each track's ``AnchoredPixels``."""
    g = cv2.GaussianBlur(np.asarray(gray, np.float32), (0, 0), BLUR_SIGMA_PX)
    ids = np.asarray(ids, np.int64)
    p = np.asarray(p_px, dtype=float).reshape(-1, 2)
    k = ids.shape[0]
    out_px, pinned = p.copy(), np.zeros(k, bool)
    sd, correlation = np.full(k, np.inf), np.full(k, -1.0)
    if k == 0:
        return Anchors(), AnchoredPixels(out_px, pinned, sd, correlation)
    position = np.minimum(np.searchsorted(anchors.ids, ids), max(len(anchors) - 1, 0))
    known = anchors.ids[position] == ids if len(anchors) else np.zeros(k, bool)
    old = anchors.take(position[known])
    rows = np.flatnonzero(known)
    live = np.flatnonzero(old.alive)
    if live.size:
        current = old.take(live)
        predicted = current.warps.copy()
        predicted[:, :, 2] += p[rows[live]] - current.track_px
        warps, corr, centre_sd = align(g, current, predicted, half)
        correction = np.linalg.norm(warps[:, :, 2] - predicted[:, :, 2], axis=1)
        ok = (corr >= MIN_CORRELATION) & (correction <= MAX_CORRECTION_PX) & np.isfinite(centre_sd)
        alive = old.alive.copy()
        alive[live] = ok
        new_warps = old.warps.copy()
        new_warps[live] = np.where(ok[:, None, None], warps, old.warps[live])
        track_px = old.track_px.copy()
        track_px[live] = p[rows[live]]
        old = _refreshed(dataclasses.replace(old, warps=new_warps, track_px=track_px, alive=alive),
                         live[ok & (corr < REFRESH_CORRELATION)], g, half)
        target = rows[live]
        at_point = np.einsum("kij,kj->ki", warps[:, :, :2], current.points) + warps[:, :, 2]
        out_px[target] = np.where(ok[:, None], at_point, p[target])
        sd[target], correlation[target] = centre_sd, corr
        pinned[target] = ok & (centre_sd <= np.broadcast_to(max_sd_px, (k,))[target])
    fresh_rows = np.flatnonzero(~known)
    fresh = make_anchors(g, depth, ids[fresh_rows], p[fresh_rows], np.asarray(z, float)[fresh_rows], half,
                         surface_tolerance)
    # A new anchor's frame is its template: it says nothing yet of how well the patch pins a point.
    correlation[fresh_rows[fresh.alive]] = 1.0
    merged = _concat(old, fresh)
    order = np.argsort(merged.ids, kind="stable")
    return merged.take(order), AnchoredPixels(out_px, pinned, sd, correlation)


def _refreshed(anchors: Anchors, rows: np.ndarray, gray: np.ndarray, half: int) -> Anchors:
    """The anchors with the templates of ``rows`` replaced by the patches their warps align now, in
    the same template coordinates (the same mask, the same point): the template update of Matthews,
    Ishikawa and Baker ("The template update problem", 2004). A face that keeps turning changes its
    appearance beyond what an affine warp of its first patch explains; the patch aligned to the
    first is the same surface, so the point keeps its place on it up to that one alignment's error
    (a few hundredths of a pixel), not a track's frame-by-frame drift."""
    if rows.size == 0:
        return anchors
    patches = np.nan_to_num(_warp_patches(gray, anchors.warps[rows], half))
    templates, steepest, hessian_inv, contrast, usable = _templates(patches, anchors.masks[rows], half)
    rows, keep = rows[usable], np.flatnonzero(usable)
    new = {"templates": templates, "steepest": steepest, "hessian_inv": hessian_inv, "contrast": contrast}
    out = {name: getattr(anchors, name).copy() for name in new}
    for name, value in new.items():
        out[name][rows] = value[keep]
    return dataclasses.replace(anchors, **out)


def _concat(a: Anchors, b: Anchors) -> Anchors:
    if len(a) == 0:
        return b
    if len(b) == 0:
        return a
    return Anchors(*(np.concatenate([getattr(a, n), getattr(b, n)]) for n in _FIELDS))


@dataclass(frozen=True)
class AnchoredTracks:
    """What the refiner carries from frame to frame: the anchors of the tracks whose point is the
    patch they began on, and the ids of the tracks whose point is a centrally symmetric corner
    (``saddles``, sorted). A track's kind is fixed where it is first seen with a point."""

    anchors: Anchors = field(default_factory=Anchors)
    saddles: np.ndarray = _empty(0, np.int64)


def refine_anchored(tracks: AnchoredTracks, image: np.ndarray, depth: np.ndarray, ids: np.ndarray,
                    p_px: np.ndarray, intrinsics: PinholeIntrinsics, params: RefinementParams,
                    depth_sigma) -> tuple[AnchoredTracks, RefinedPoints]:
    """The refiner's points of one frame with anchors (``params.anchor_window_px`` > 0).

    A track first seen on a centrally symmetric corner (``refine_features`` with the symmetry test:
    a checker saddle, a mark's centre) keeps that corner as its point, refined again each frame
    and valid only where it is still symmetric: nothing is more precise on a printed pattern. Any
    other track first seen with a depth is anchored to its first patch: its point is the anchored
    pixel (``anchor_step``), valid where the anchor pins it (the centre's 1 sd times ``z / f``,
    the metres a pixel spans at depth ``z``, within the depth noise ``depth_sigma(z)``, m) and the
    depth on the face's plane there is clean (``local_depth``). The output's ``symmetric`` marks
    the corners (the candidates' first choice); anchored points are the second."""
    p = np.asarray(p_px, dtype=float).reshape(-1, 2)
    ids = np.asarray(ids, np.int64)
    corners = refine_features(image, depth, p, intrinsics, dataclasses.replace(params, anchor_window_px=0))
    z_track = local_depth(depth, p, params, intrinsics)
    saddle = np.isin(ids, tracks.saddles)
    new = ~saddle & ~np.isin(ids, tracks.anchors.ids)
    saddle |= new & corners.symmetric
    plain = ~saddle & (~new | np.isfinite(z_track))
    gray = to_gray(np.asarray(image))
    with np.errstate(invalid="ignore"):
        z_safe = np.where(np.isfinite(z_track), z_track, 1.0)
        max_sd = np.where(np.isfinite(z_track), depth_sigma(z_safe) * intrinsics.fx / z_safe, 0.0)
    d = np.asarray(depth)
    d = d[:, :, 0] if d.ndim == 3 else d
    rows = np.flatnonzero(plain)
    anchors, anchored = anchor_step(tracks.anchors, gray, d, ids[rows], p[rows], z_track[rows],
                                    params.anchor_window_px, params.surface_tolerance, max_sd[rows])
    z = np.full(rows.size, np.nan)
    if anchored.pinned.any():
        z[anchored.pinned] = local_depth(depth, anchored.p_px[anchored.pinned], params, intrinsics)
    pinned = anchored.pinned & np.isfinite(z) & (z > 0)
    p_CP = np.where(saddle[:, None], corners.p_CP, 0.0)
    valid = saddle & corners.symmetric
    p_out = np.where(valid[:, None], corners.p_px, p)
    p_CP[rows[pinned]] = pinhole_points(anchored.p_px[pinned], z[pinned], intrinsics)
    valid[rows[pinned]] = True
    p_out[rows[pinned]] = anchored.p_px[pinned]
    symmetric = valid & saddle
    return (AnchoredTracks(anchors, np.sort(ids[saddle])),
            RefinedPoints(p_CP, valid, p_out, symmetric))
