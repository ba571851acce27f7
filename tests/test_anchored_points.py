"""Points anchored on the patch where each track began (perception.anchored_points), on synthetic
views of textured planes, and the FeatureRefiner that keeps the anchors in its state."""

import dataclasses

import cv2
import numpy as np
import pytest

from sustain_drake.perception.anchored_points import AnchoredTracks, Anchors, anchor_step, refine_anchored
from sustain_drake.perception.optical_flow import PinholeIntrinsics, TrackedFeatures
from sustain_drake.perception.point_refinement import RefinementParams

HALF = 8
TOLERANCE = 0.008
W, H = 320, 240


def texture(seed=0, shape=(400, 500), blur=2.0):
    """A smooth random texture (wood grain, print, speckle alike: no corner structure to rely on)."""
    rng = np.random.default_rng(seed)
    t = cv2.GaussianBlur(rng.uniform(0, 255, shape).astype(np.float32), (0, 0), blur)
    return cv2.normalize(t, None, 20, 235, cv2.NORM_MINMAX)


def view(tex, homography):
    return cv2.warpPerspective(tex, homography, (W, H), flags=cv2.INTER_LINEAR).astype(np.uint8)


def apply(homography, p):
    q = np.c_[p, np.ones(len(p))] @ np.asarray(homography).T
    return q[:, :2] / q[:, 2:]


def homography(f):
    """Frame f of a view that turns, tilts (perspective), scales and translates the plane."""
    a = 0.012 * f
    return np.array([[np.cos(a) * (1 + 0.004 * f), -np.sin(a), 4 * np.sin(0.1 * f)],
                     [np.sin(a), np.cos(a) * (1 - 0.002 * f), 0.2 * f],
                     [3e-5 * f, -2e-5 * f, 1.0]])


FLAT = np.ones((H, W), np.float32)


def test_the_anchored_point_stays_on_the_plane_point_where_its_track_began():
    tex = texture()
    rng = np.random.default_rng(1)
    start = rng.uniform([100, 80], [W - 100, H - 80], (20, 2))
    ids = np.arange(20)
    anchors = Anchors()
    for f in range(50):
        true = apply(homography(f), start)
        # A track that drifts 0.04 px per frame and jitters: 2 px off after 50 frames.
        track = true + 0.04 * f + rng.normal(0, 0.05, true.shape)
        anchors, out = anchor_step(anchors, view(tex, homography(f)), FLAT, ids, track, np.ones(20),
                                   HALF, TOLERANCE, max_sd_px=0.1)
        if f == 0:
            first = track + anchors.points  # each anchor's point: the patch point it pins best
            assert not out.pinned.any()  # a new anchor's own frame says nothing of it yet
            continue
        assert out.pinned.all() and (out.correlation > 0.97).all()
        error = np.linalg.norm(out.p_px - apply(homography(f), first), axis=1)
        assert np.median(error) < 0.05 and error.max() < 0.15, f"frame {f}: {error.max():.3f} px off"
    assert np.linalg.norm(track - apply(homography(49), first), axis=1).min() > 1.5  # the track drifted


def test_a_patch_with_one_straight_edge_pins_nothing():
    edge = np.zeros((H, W), np.float32)
    edge[:, : W // 2] = 200.0
    edge = cv2.GaussianBlur(edge, (0, 0), 1.0)
    p = np.array([[W / 2 - 0.5, 120.0]])
    anchors, _ = anchor_step(Anchors(), edge, FLAT, [7], p, [1.0], HALF, TOLERANCE, max_sd_px=0.5)
    moved = np.roll(edge, 1, axis=0)  # sliding along the edge changes nothing in the image
    moved = moved + np.random.default_rng(0).normal(0, 1.0, moved.shape).astype(np.float32)
    _, out = anchor_step(anchors, moved, FLAT, [7], p, [1.0], HALF, TOLERANCE, max_sd_px=0.5)
    assert not out.pinned[0]


def test_the_background_behind_a_silhouette_is_not_part_of_the_template():
    tool, background = texture(0), texture(5)
    depth = np.full((H, W), 2.0, np.float32)
    depth[:, :160] = 0.8  # the tool's face: the left half
    p = np.array([[155.0, 120.0]])  # 5 px from the silhouette: a third of its template is background

    def frame(shift):
        image = np.where(depth < 1.0, tool[:H, :W], background[:H, shift:shift + W])
        return image.astype(np.uint8)

    anchors, _ = anchor_step(Anchors(), frame(0), depth, [3], p, [0.8], HALF, TOLERANCE, max_sd_px=0.2)
    point = p[0] + anchors.points[0]
    for shift in (3, 6, 9):  # the background slides behind the still tool
        anchors, out = anchor_step(anchors, frame(shift), depth, [3], p, [0.8], HALF, TOLERANCE,
                                   max_sd_px=0.2)
        assert out.pinned[0] and np.linalg.norm(out.p_px[0] - point) < 0.05


def test_an_occluded_patch_ends_its_anchor_for_good():
    tex, other = texture(0), texture(9)
    p = np.array([[100.0, 100.0], [220.0, 150.0]])
    anchors, _ = anchor_step(Anchors(), view(tex, np.eye(3)), FLAT, [1, 2], p, [1.0, 1.0], HALF, TOLERANCE)
    covered = view(tex, np.eye(3))
    covered[80:120, 80:120] = view(other, np.eye(3))[80:120, 80:120]  # something passes over point 1
    anchors, out = anchor_step(anchors, covered, FLAT, [1, 2], p, [1.0, 1.0], HALF, TOLERANCE)
    assert out.pinned.tolist() == [False, True]
    anchors, out = anchor_step(anchors, view(tex, np.eye(3)), FLAT, [1, 2], p, [1.0, 1.0], HALF, TOLERANCE)
    assert out.pinned.tolist() == [False, True]  # uncovered, but it is no longer known to be the same point
    assert anchors.ids.tolist() == [1, 2] and anchors.alive.tolist() == [False, True]


def test_tracks_come_and_go():
    tex = view(texture(), np.eye(3))
    anchors, out = anchor_step(Anchors(), tex, FLAT, [], np.zeros((0, 2)), [], HALF, TOLERANCE)
    assert len(anchors) == 0 and out.p_px.shape == (0, 2)
    anchors, _ = anchor_step(anchors, tex, FLAT, [4, 9], [[100.0, 100.0], [200.0, 100.0]], [1.0, 1.0],
                             HALF, TOLERANCE)
    # Track 4 ended, 12 is new; one near the border and one without depth get dead anchors.
    anchors, out = anchor_step(anchors, tex, FLAT, [9, 12, 13, 14],
                               [[200.0, 100.0], [150.0, 150.0], [3.0, 100.0], [60.0, 60.0]],
                               [1.0, 1.0, 1.0, np.nan], HALF, TOLERANCE)
    assert anchors.ids.tolist() == [9, 12, 13, 14]
    assert anchors.alive.tolist() == [True, True, False, False]
    assert out.pinned.tolist() == [True, False, False, False]


K = PinholeIntrinsics(width=W, height=H, fx=290.0, fy=290.0, cx=159.5, cy=119.5)


def test_refine_anchored_back_projects_pinned_points_with_the_depth_noise_gate():
    tex = view(texture(), np.eye(3))
    depth = np.full((H, W), 0.7, np.float32)
    params = RefinementParams(anchor_window_px=HALF, depth_plane=True, symmetry_window_px=3)
    p = np.array([[100.0, 80.0], [200.0, 160.0]])
    sigma = lambda z: 0.001 + 0.0 * z  # noqa: E731 (1 mm at any depth: 0.41 px at 0.7 m)
    anchors, first = refine_anchored(AnchoredTracks(), tex, depth, [1, 2], p, K, params, sigma)
    assert not first.valid.any() and not np.any(first.p_CP)
    anchors, out = refine_anchored(anchors, tex, depth, [1, 2], p + 0.3, K, params, sigma)
    assert out.valid.all() and not out.symmetric.any()  # anchored points: the second choice
    assert np.allclose(out.p_px, p + anchors.anchors.points, atol=0.02)  # the anchors, not the tracks' 0.3 px
    assert out.p_CP[:, 2] == pytest.approx([0.7, 0.7], abs=1e-4)
    assert out.p_CP[0, 0] == pytest.approx((out.p_px[0, 0] - K.cx) * 0.7 / K.fx, abs=1e-4)
    # With no depth at a point it is not valid, never NaN.
    holes = depth.copy()
    holes[150:170, 190:210] = np.nan
    _, out = refine_anchored(anchors, tex, holes, [1, 2], p, K, params, sigma)
    assert out.valid.tolist() == [True, False] and np.isfinite(out.p_CP).all()


def test_params_reject_a_negative_anchor_window():
    with pytest.raises(ValueError, match="window"):
        RefinementParams(anchor_window_px=-1)


def test_feature_refiner_keeps_its_anchors_in_the_context():
    from pydrake.systems.sensors import CameraInfo, ImageDepth32F, ImageRgba8U

    from sustain_drake.systems.candidate_identifiers import FeatureRefiner

    info = CameraInfo(W, H, K.fx, K.fy, K.cx, K.cy)
    period = 1.0 / 30.0
    refiner = FeatureRefiner(info, RefinementParams(anchor_window_px=HALF, depth_plane=True),
                             period=period, offset=0.5 * period)
    context = refiner.CreateDefaultContext()
    tex = texture()
    depth = ImageDepth32F(W, H)
    depth.mutable_data[:] = 0.7
    p0 = np.array([[100.0, 80.0]])

    def show(f, context):
        color = ImageRgba8U(W, H)
        shift = np.array([[1, 0, 0.5 * f], [0, 1, 0.25 * f], [0, 0, 1]])
        color.mutable_data[:, :, :3] = view(tex, shift)[:, :, None]
        color.mutable_data[:, :, 3] = 255
        features = TrackedFeatures(ids=np.array([5]), p_px=apply(shift, p0) + 0.1 * f,
                                   flow_px=np.zeros((1, 2)), p_CP=np.zeros((1, 3)), valid=np.array([False]),
                                   cell=np.zeros(1, np.int64), time=f * period)  # fmt: skip
        refiner.GetInputPort("tracked_features").FixValue(context, features)
        refiner.GetInputPort("color_image").FixValue(context, color)
        refiner.GetInputPort("depth_image").FixValue(context, depth)
        refiner.GetInputPort("image_time").FixValue(context, [f * period])
        return shift

    from pydrake.systems.analysis import Simulator

    show(0, context)
    out = refiner.GetOutputPort("tracked_features").Eval(context)
    assert not out.valid.any()  # no update has seen this frame yet
    simulator = Simulator(refiner, context)
    points = []
    for f in range(1, 6):
        simulator.AdvanceTo((f - 1 + 0.6) * period)  # the update of frame f - 1 has run
        shift = show(f, simulator.get_mutable_context())
        simulator.AdvanceTo((f + 0.6) * period)
        out = refiner.GetOutputPort("tracked_features").Eval(simulator.get_context())
        assert out.valid[0]
        points.append(out.p_px[0] - apply(shift, p0)[0])  # the anchor's point, moved with the image
    assert np.ptp(np.array(points), axis=0).max() < 0.05
    clone = simulator.get_context().Clone()  # the anchors are in the context, not the system
    assert refiner.GetOutputPort("tracked_features").Eval(clone).valid[0]
    assert dataclasses.replace(out).ids.tolist() == [5]


def test_a_track_begun_on_a_checker_saddle_keeps_the_saddle_and_others_are_anchored():
    """The kinds are fixed where a track is first seen: a centrally symmetric corner stays that
    corner (refined each frame, valid only while still symmetric, never anchored), any other point
    is anchored on its patch (the second choice)."""
    v, u = np.mgrid[0:H, 0:W]
    saddle = (80.5, 120.5)  # between pixels: a hard-edged checker puts it there exactly
    light = (np.floor((u - saddle[0]) / 9.0) + np.floor((v - saddle[1]) / 9.0)) % 2 == 0
    image = np.where(light, 220.0, 30.0).astype(np.float32)
    image[:, 160:] = texture()[:H, 160:W]  # print on the right half
    image = image.astype(np.uint8)
    depth = np.full((H, W), 0.7, np.float32)
    params = RefinementParams(anchor_window_px=HALF, corner_window_px=4, max_shift_px=4.0,
                              symmetry_window_px=3, depth_plane=True)
    sigma = lambda z: 0.001 + 0.0 * z  # noqa: E731
    tracked = np.array([[saddle[0] + 1.2, saddle[1] - 0.8], [220.0, 140.0]])  # print: not symmetric
    tracks, out = refine_anchored(AnchoredTracks(), image, depth, [1, 2], tracked, K, params, sigma)
    assert tracks.saddles.tolist() == [1] and tracks.anchors.ids.tolist() == [2]
    assert out.valid.tolist() == [True, False] and out.symmetric.tolist() == [True, False]
    assert np.linalg.norm(out.p_px[0] - saddle) < 0.15
    tracks, out = refine_anchored(tracks, image, depth, [1, 2], tracked + 0.2, K, params, sigma)
    assert out.valid.tolist() == [True, True] and out.symmetric.tolist() == [True, False]
    anchor = tracked[1] + tracks.anchors.points[0]
    assert np.linalg.norm(out.p_px[1] - anchor) < 0.05  # the anchor, not the track's 0.2 px
    # The saddle covered by a flat patch: no point, and it does not become an anchored one.
    covered = image.copy()
    covered[100:140, 60:100] = 128
    tracks, out = refine_anchored(tracks, covered, depth, [1, 2], tracked, K, params, sigma)
    assert out.valid.tolist() == [False, True] and tracks.saddles.tolist() == [1]
    assert tracks.anchors.ids.tolist() == [2]
