"""Drift-free points of tracked features (perception.point_refinement) on synthetic images."""

import dataclasses
import warnings

import cv2
import numpy as np
import pytest

from sustain_drake.perception.optical_flow import PinholeIntrinsics
from sustain_drake.perception.point_refinement import (
    SADDLE_SYMMETRY,
    RefinementParams,
    _row_nanmedian,
    central_symmetry,
    local_depth,
    refine_pixels,
    refine_points,
)

K = PinholeIntrinsics(width=160, height=120, fx=145.0, fy=145.0, cx=79.5, cy=59.5)
SADDLE = (70.3, 50.6)  # px, a checker saddle at a sub-pixel position


def checker_image(saddle=SADDLE, cell=9.0, scale=8, to_face=((1.0, 0.0), (0.0, 1.0))):
    """A yellow/black checker whose corners include ``saddle``, drawn 8x larger and shrunk with
    area averaging (sub-pixel edges, as a renderer gives); ``to_face`` (2 x 2) maps the image's
    offsets from ``saddle`` to the face's (an oblique view's affine image)."""
    h, w = K.height * scale, K.width * scale
    v, u = np.mgrid[0:h, 0:w]
    x, y = (u + 0.5) / scale - 0.5 - saddle[0], (v + 0.5) / scale - 0.5 - saddle[1]
    (a, b), (c, d) = to_face
    uu, vv = (a * x + b * y) / cell, (c * x + d * y) / cell
    light = (np.floor(uu) + np.floor(vv)) % 2 == 0
    big = np.where(light[..., None], np.array([250, 210, 20, 255]), np.array([20, 20, 20, 255]))
    return cv2.resize(big.astype(np.uint8), (K.width, K.height), interpolation=cv2.INTER_AREA)


def test_a_drifted_track_is_moved_back_to_the_saddle_and_back_projected():
    rng = np.random.default_rng(0)
    depth = np.full((K.height, K.width, 1), 0.8, np.float32) + rng.normal(0, 1.5e-3, (K.height, K.width, 1))
    tracked = np.array([[SADDLE[0] + 1.2, SADDLE[1] - 0.9]])  # 1.5 px of drift
    p_CP, valid, p_px = refine_points(checker_image(), depth.astype(np.float32), tracked, K,
                                      RefinementParams(), return_pixels=True)
    assert valid[0]
    assert np.linalg.norm(p_px[0] - SADDLE) < 0.15
    # Depth: the median of 5 x 5 noisy pixels, much nearer 0.8 m than one pixel's 1.5 mm noise.
    assert p_CP[0, 2] == pytest.approx(0.8, abs=0.8e-3)
    assert p_CP[0, 0] == pytest.approx((SADDLE[0] - K.cx) * 0.8 / K.fx, abs=1e-3)
    assert p_CP[0, 1] == pytest.approx((SADDLE[1] - K.cy) * 0.8 / K.fy, abs=1e-3)


def test_a_window_across_a_silhouette_gives_no_point():
    flat = np.full((K.height, K.width, 4), 128, np.uint8)
    depth = np.full((K.height, K.width), 0.8, np.float32)
    # A flat patch has no gradient to move the pixel: the tracked pixel is kept.
    _, valid, p_px = refine_points(flat, depth, np.array([[70.2, 50.1]]), K, return_pixels=True)
    assert valid[0] and np.allclose(p_px[0], [70.2, 50.1], atol=1e-3)
    # Half the depth window on the tool (0.8 m), half on the background (2.5 m): no clean depth.
    depth[:, 71:] = 2.5
    assert np.isnan(local_depth(depth, np.array([[70.6, 50.0]]), RefinementParams()))[0]
    assert local_depth(depth, np.array([[60.0, 50.0]]), RefinementParams())[0] == pytest.approx(0.8)
    # Outside the image, and an empty list.
    outside_or_across = np.array([[1.0, 1.0], [200.0, 50.0], [70.6, 50.0]])
    p_CP, valid = refine_points(checker_image(), depth, outside_or_across, K)
    assert not valid.any() and not np.any(p_CP)  # zero rows, never NaN
    assert refine_points(checker_image(), depth, np.zeros((0, 2)), K)[0].shape == (0, 3)


def test_params_validation():
    with pytest.raises(ValueError, match="window"):
        RefinementParams(corner_window_px=-1)
    with pytest.raises(ValueError, match="window"):
        RefinementParams(symmetry_window_px=-1)
    with pytest.raises(ValueError, match="min_symmetry"):
        RefinementParams(min_symmetry=1.5)
    with pytest.raises(ValueError, match="min_fraction"):
        RefinementParams(min_fraction=0.0)


def test_feature_refiner_system_refines_only_features_of_the_shown_frame():
    from pydrake.systems.sensors import CameraInfo, ImageDepth32F, ImageRgba8U

    from sustain_drake.perception.optical_flow import TrackedFeatures
    from sustain_drake.systems.candidate_identifiers import FeatureRefiner

    info = CameraInfo(K.width, K.height, K.fx, K.fy, K.cx, K.cy)
    refiner = FeatureRefiner(info)
    context = refiner.CreateDefaultContext()
    color, depth = ImageRgba8U(K.width, K.height), ImageDepth32F(K.width, K.height)
    color.mutable_data[:] = checker_image()
    depth.mutable_data[:] = 0.8
    features = TrackedFeatures(ids=np.array([5]), p_px=np.array([[SADDLE[0] + 1.0, SADDLE[1] + 0.8]]),
                               flow_px=np.zeros((1, 2)), p_CP=np.zeros((1, 3)), valid=np.array([False]),
                               cell=np.zeros(1, np.int64), time=2.0)  # fmt: skip
    refiner.GetInputPort("tracked_features").FixValue(context, features)
    refiner.GetInputPort("color_image").FixValue(context, color)
    refiner.GetInputPort("depth_image").FixValue(context, depth)
    refiner.GetInputPort("image_time").FixValue(context, [2.0])
    out = refiner.GetOutputPort("tracked_features").Eval(context)
    assert out.ids.tolist() == [5] and out.valid[0] and out.time == 2.0
    assert np.linalg.norm(out.p_px[0] - SADDLE) < 0.15 and out.p_CP[0, 2] == pytest.approx(0.8)
    refiner.GetInputPort("image_time").FixValue(context, [2.0 + 1 / 30])  # the next frame's image
    out = refiner.GetOutputPort("tracked_features").Eval(context)
    assert not out.valid.any() and not np.any(out.p_CP)


def slanted_plane_depth(normal, c):
    """The depth image of the plane ``normal . p_C = c`` (camera frame, m) and its exact depth at
    any sub-pixel ``(u, v)``: ``z = c / (normal . r(u, v))`` for the pinhole ray ``r``."""
    def z_at(u, v):
        r = np.stack([(np.asarray(u) - K.cx) / K.fx, (np.asarray(v) - K.cy) / K.fy, np.ones_like(u)])
        return c / np.tensordot(normal, r, axes=1)
    v, u = np.mgrid[0:K.height, 0:K.width].astype(float)
    return z_at(u, v).astype(np.float32), z_at


def test_the_depth_of_a_slanted_face_is_read_at_the_sub_pixel_point():
    points = np.array([[80.4, 60.3], [78.45, 52.2], [82.6, 66.7]])
    # A face turned 30 deg about the camera's y axis, 0.75 m away: its depth changes by 3 mm per
    # pixel across u.
    normal = np.array([np.sin(np.radians(30)), 0.0, np.cos(np.radians(30))])
    depth, z_at = slanted_plane_depth(normal, 0.75 * normal[2])
    exact = z_at(points[:, 0], points[:, 1])
    gradient = abs(z_at(81.0, 60.0) - z_at(80.0, 60.0))
    assert gradient > 0.0025
    plane = local_depth(depth, points, RefinementParams(depth_plane=True))
    median = local_depth(depth, points, RefinementParams(depth_plane=False))
    # The plane gives the depth on the sub-pixel ray (to float32 round-off of the image); the
    # rounded window's median is off by the sub-pixel offset (0.4 px) times the gradient.
    assert np.max(np.abs(plane - exact)) < 2e-5
    assert np.min(np.abs(median - exact)) > 0.3 * gradient
    # The face's incidence (ray against normal, 29-31 deg at these pixels) from the fitted plane:
    # a limit half a degree above every point's keeps them all, half a degree below none.
    rays = np.c_[(points[:, 0] - K.cx) / K.fx, (points[:, 1] - K.cy) / K.fy, np.ones(3)]
    angles = np.degrees(np.arccos(np.abs(rays @ normal) / np.linalg.norm(rays, axis=1)))
    assert 28 < angles.min() and angles.max() < 32
    for limit, kept in ((angles.max() + 0.5, True), (angles.min() - 0.5, False)):
        z = local_depth(depth, points, RefinementParams(depth_plane=True, max_incidence_deg=limit), K)
        assert np.isfinite(z).all() if kept else np.isnan(z).all()
    # With the station's per-pixel noise (1.3 mm), over many draws: unbiased,
    # and the noise of one pixel divided by about the window's side.
    rng = np.random.default_rng(1)
    errors = []
    for _ in range(200):
        noisy = depth + rng.normal(0.0, 1.3e-3, depth.shape).astype(np.float32)
        errors.append(local_depth(noisy, points, RefinementParams(depth_plane=True)) - exact)
    errors = np.array(errors)
    assert np.all(np.abs(errors.mean(axis=0)) < 0.15e-3)  # unbiased
    assert np.sqrt(np.mean(errors**2)) < 0.45e-3  # about 1.3 mm / sqrt(25 pixels)


def test_the_plane_ignores_the_background_pixels_of_a_window():
    # A fronto-parallel face at 0.8 m whose edge cuts the window: the background pixels (2.5 m)
    # are left out of the fit (min_fraction allows up to 30 % of them).
    depth = np.full((K.height, K.width), 0.8, np.float32)
    depth[:, 72:] = 2.5  # 5 x 5 window at u = 70: 1 column of 5 on the background
    z = local_depth(depth, np.array([[70.3, 50.2]]), RefinementParams(depth_plane=True))
    assert z[0] == pytest.approx(0.8, abs=1e-6)
    # Pixels on one line only (a degenerate window) give no depth, not a NaN passed on silently.
    from sustain_drake.perception.point_refinement import plane_depth
    use = np.zeros((1, 25), bool)
    use[0, 10:15] = True  # one row of the window
    du, dv = np.meshgrid(np.arange(-2, 3.0), np.arange(-2, 3.0))
    assert np.isnan(plane_depth(np.full((1, 25), 0.8), use, du.reshape(1, -1), dv.reshape(1, -1))[0])[0]


def cell_image(centre, half_size=(3.3, 4.5), scale=8):
    """A yellow checker cell of the rod (6.6 x 9 px, as at 0.75 m) centred at a sub-pixel
    ``centre``, with its two diagonal neighbours touching its corners (the rod's two-column
    checker), drawn 8x larger and shrunk with area averaging."""
    a, b = half_size
    v, u = np.mgrid[0:K.height * scale, 0:K.width * scale]
    uu, vv = (u + 0.5) / scale - 0.5, (v + 0.5) / scale - 0.5
    lit = (np.abs(uu - centre[0]) < a) & (np.abs(vv - centre[1]) < b)
    for dv in (-2 * b, 2 * b):
        lit |= (np.abs(uu - centre[0] - 2 * a) < a) & (np.abs(vv - centre[1] - dv) < b)
    big = np.where(lit, 220, 20).astype(np.uint8)
    return cv2.resize(big, (K.width, K.height), interpolation=cv2.INTER_AREA)


def test_a_feature_on_a_small_cell_is_moved_to_the_cell_centroid():
    from sustain_drake.perception.optical_flow import to_gray
    from sustain_drake.perception.point_refinement import blob_centres, refine_pixels
    rng = np.random.default_rng(0)
    blob, corner = [], []
    for _ in range(30):
        centre = np.array([70.0, 50.0]) + rng.uniform(0, 1, 2)
        tracked = (centre + rng.uniform(-1, 1, 2))[None]
        image = cell_image(centre)
        p, ok = refine_pixels(image, tracked, RefinementParams(blob_window_px=6))
        assert ok[0]
        blob.append(p[0] - centre)
        p, ok = refine_pixels(image, tracked, RefinementParams(blob_window_px=0))
        corner.append(p[0] - centre)
    # The centroid of the whole cell: a few hundredths of a pixel; cornerSubPix's 5 x 5 window
    # sees part of the cell's edges only, and its point depends on where the window falls.
    assert np.sqrt(np.mean(np.square(blob))) < 0.06
    assert np.sqrt(np.mean(np.square(corner))) > 3 * np.sqrt(np.mean(np.square(blob)))
    # A checker saddle is no blob (its bright region runs to the window's border): not moved by it.
    centres, is_blob = blob_centres(to_gray(checker_image()), np.array([SADDLE]), 6)
    assert not is_blob[0] and np.isnan(centres[0]).all()
    # Too little contrast (a plain patch): no blob.
    assert not blob_centres(np.full((K.height, K.width), 90, np.uint8), np.array([[70.0, 50.0]]), 6)[1][0]


def square_image(corner=(60.3, 40.6), size=14.0, scale=8):
    """A bright square on black whose top-left corner is ``corner`` (an L corner), drawn 8x larger
    and shrunk with area averaging."""
    h, w = K.height * scale, K.width * scale
    v, u = np.mgrid[0:h, 0:w]
    uu, vv = (u + 0.5) / scale - 0.5 - corner[0], (v + 0.5) / scale - 0.5 - corner[1]
    inside = (uu >= 0) & (uu < size) & (vv >= 0) & (vv < size)
    gray = np.where(inside, 220, 15).astype(np.uint8)
    return cv2.resize(gray, (K.width, K.height), interpolation=cv2.INTER_AREA)


def test_central_symmetry_tells_a_saddle_from_an_l_corner_an_edge_and_a_flat_patch():
    gray = cv2.cvtColor(checker_image(), cv2.COLOR_RGBA2GRAY)
    square = square_image()
    assert central_symmetry(gray, np.array([SADDLE]), 3)[0] > 0.9
    assert central_symmetry(square, np.array([[60.3, 40.6]]), 3)[0] < 0.0  # the L corner itself
    assert central_symmetry(square, np.array([[60.3, 47.0]]), 3)[0] < -0.8  # on the square's edge
    flat = np.full((K.height, K.width), 128, np.uint8)
    outside = np.array([[1.0, 1.0], [70.0, 50.0]])
    assert np.all(central_symmetry(flat, outside, 3) == -1.0)


def test_with_the_symmetry_test_only_saddles_are_points():
    depth = np.full((K.height, K.width), 0.8, np.float32)
    params = RefinementParams(corner_window_px=4, max_shift_px=4.0, symmetry_window_px=3)
    # Shi-Tomasi (block 7) puts a square's L corner ~2.5 px inside the square: cornerSubPix finds the
    # corner with a 9 x 9 window, but an L corner is no point (its sub-pixel position depends on
    # the view); a flat patch is none either (without the test both were kept as valid).
    inside_l = np.array([[60.3 + 2.5, 40.6 + 2.5], [20.0, 100.0]])
    _, valid = refine_points(square_image(), depth, inside_l, K, params)
    assert not valid.any()
    assert refine_points(square_image(), depth, inside_l, K, RefinementParams())[1].all()
    # A saddle 2.8 px from the tracked pixel is found and kept.
    tracked = np.array([[SADDLE[0] + 2.0, SADDLE[1] - 2.0]])
    p_CP, valid, p_px = refine_points(checker_image(), depth, tracked, K, params, return_pixels=True)
    assert valid[0] and np.linalg.norm(p_px[0] - SADDLE) < 0.15


def _print_texture(rng, n):
    """A print of overlapping polygons and grain-like strokes, anti-aliased, n x n px."""
    img = np.full((n, n), 128, np.float32)
    for _ in range(25):
        c, r = rng.uniform(0, n, 2), rng.uniform(15, 80)
        a = np.sort(rng.uniform(0, 2 * np.pi, rng.integers(3, 6)))
        cv2.fillPoly(img, [(c + r * np.c_[np.cos(a), np.sin(a)]).astype(np.int32)],
                     float(rng.uniform(0, 255)), lineType=cv2.LINE_AA)
    for _ in range(10):
        x, y = rng.uniform(0, n), np.linspace(0, n, 50)
        stroke = np.c_[x + 40 * np.sin(y / n * 6 + rng.uniform(0, 6)), y].astype(np.int32)
        cv2.polylines(img, [stroke], False, float(rng.uniform(0, 255)), int(rng.integers(2, 8)), cv2.LINE_AA)
    return img


def _tilt(n, angle, axis_angle, f):
    """The homography (px) of a face seen head-on at 0.8 m as it turns by ``angle`` about an axis in
    it at ``axis_angle`` through its centre."""
    R, _ = cv2.Rodrigues(np.array([np.cos(axis_angle), np.sin(axis_angle), 0.0]) * angle)
    K_ = np.array([[f, 0, n / 2], [0, f, n / 2], [0, 0, 1.0]])
    centre, normal = np.array([0, 0, 0.8]), np.array([0, 0, 1.0])
    H = K_ @ (R + np.outer(centre - R @ centre, normal) / 0.8) @ np.linalg.inv(K_)
    return H / H[2, 2]


def test_anchored_points_stay_on_the_same_surface_point_under_a_true_perspective_turn():
    """Points anchored on their first patch (perception.anchored_points) under a true perspective
    view, not the alignment's own affine model: a printed face drawn 4x larger and area-averaged,
    seen head-on and turned by 40 deg in 5 deg steps about four axes, each step's anchors started
    from where a track would put them (the homography's move of the point, plus jitter). The
    anchored points land where the homography puts the first view's points to about a seventh of
    a pixel (median; a patch of this print that is one large polygon's edge and a faint stroke
    wanders by a pixel, the tail the candidates' fits must bear); the corners refined in the
    last view alone (``refine_pixels``) are off several times as much, as they slide with the
    view."""
    from sustain_drake.perception.anchored_points import Anchors, anchor_step

    rng = np.random.default_rng(1)
    scale, n = 4, 1024
    texture = _print_texture(rng, n)

    def view(H_big):
        image = cv2.warpPerspective(texture, H_big, (n, n), flags=cv2.INTER_LINEAR, borderValue=128)
        return np.clip(cv2.resize(image, None, fx=1 / scale, fy=1 / scale, interpolation=cv2.INTER_AREA),
                       0, 255).astype(np.float32)

    first = view(np.eye(3))
    tracked = cv2.goodFeaturesToTrack(first.astype(np.uint8), 400, 0.01, 5, blockSize=7).reshape(-1, 2)
    p = tracked[np.all((tracked > 40) & (tracked < n / scale - 40), axis=1)].astype(float)
    ids, flat = np.arange(len(p)), np.ones((n // scale, n // scale), np.float32)
    to_low = np.array([[1 / scale, 0, -(scale - 1) / (2 * scale)], [0, 1 / scale, -(scale - 1) / (2 * scale)],
                       [0, 0, 1]])
    anchored_errors, corner_errors = [], []
    for axis_angle in (0.3, 1.2, 2.0, 2.8):
        anchors, _ = anchor_step(Anchors(), first, flat, ids, p, np.ones(len(p)), 8, 0.008, np.inf)
        points = p + anchors.points  # each anchor's point (the patch point its alignment pins best)
        for degrees in range(5, 45, 5):
            H = to_low @ _tilt(n, np.radians(degrees), axis_angle, scale * 579.4) @ np.linalg.inv(to_low)
            expected = cv2.perspectiveTransform(p.reshape(-1, 1, 2), H).reshape(-1, 2)
            image = view(np.linalg.inv(to_low) @ H @ to_low)
            anchors, out = anchor_step(anchors, image, flat, ids, expected + rng.normal(0, 0.05, p.shape),
                                       np.ones(len(p)), 8, 0.008, np.inf)
        truth = cv2.perspectiveTransform(points.reshape(-1, 1, 2), H).reshape(-1, 2)
        anchored_errors.append(np.linalg.norm(out.p_px - truth, axis=1)[out.pinned])
        corner = RefinementParams(corner_window_px=4, max_shift_px=4.0)
        start, _ = refine_pixels(first.astype(np.uint8), p, corner)
        carried = cv2.perspectiveTransform(start.reshape(-1, 1, 2), H).reshape(-1, 2)
        found, ok = refine_pixels(image.astype(np.uint8), carried + 0.5, corner)
        corner_errors.append(np.linalg.norm(found - carried, axis=1)[ok])
    anchored, corners = np.concatenate(anchored_errors), np.concatenate(corner_errors)
    assert anchored.size >= 0.8 * 4 * len(p)  # most anchors survive the 40 deg turn
    assert np.median(anchored) < 0.2
    assert np.median(corners) > 2.5 * np.median(anchored)


@pytest.mark.parametrize("rows", [0, 1, 7, 300])
def test_row_nanmedian_is_numpys_nanmedian_bit_for_bit(rows):
    rng = np.random.default_rng(rows)
    window = rng.choice([0.5, 0.7, 0.71, 1.3], size=(rows, 25)) + rng.normal(0, 1e-3, (rows, 25))
    window[rng.random(window.shape) < rng.random((rows, 1))] = np.nan  # some rows mostly NaN
    window[:1] = np.nan  # an all-NaN row: NaN
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # numpy's "All-NaN slice encountered"
        expected = np.nanmedian(window, axis=1)
    assert _row_nanmedian(window).tobytes() == expected.tobytes()


def test_a_saddle_seen_obliquely_is_symmetric_and_a_random_textures_points_are_not():
    # A checker corner on a face turned by 50 deg (foreshortened to cos 50 = 0.64 across, and
    # sheared) stays centrally symmetric about its crossing: an affine image of a saddle is a saddle.
    oblique = cv2.cvtColor(checker_image(to_face=((1 / 0.64, 0.3), (0.0, 1.0))), cv2.COLOR_RGBA2GRAY)
    assert central_symmetry(oblique, np.array([SADDLE]), 3)[0] >= SADDLE_SYMMETRY
    # A fine random texture: the refined corners that pass the old 0.5 (a speckle's blob or saddle)
    # are refused at SADDLE_SYMMETRY, so their tracks are anchored on their patch instead.
    rng = np.random.default_rng(3)
    speckle = cv2.GaussianBlur(rng.uniform(0, 255, (K.height, K.width)).astype(np.float32), (0, 0), 1.2)
    speckle = cv2.normalize(speckle, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    corners = cv2.goodFeaturesToTrack(speckle, 200, 0.01, 5, blockSize=7).reshape(-1, 2).astype(float)
    loose = RefinementParams(corner_window_px=4, max_shift_px=4.0, symmetry_window_px=3)
    _, kept_loose = refine_pixels(speckle, corners, loose)
    assert kept_loose.sum() >= 5  # the old threshold takes several of them as corners
    _, kept = refine_pixels(speckle, corners, dataclasses.replace(loose, min_symmetry=SADDLE_SYMMETRY))
    assert kept.sum() <= 0.2 * kept_loose.sum()
