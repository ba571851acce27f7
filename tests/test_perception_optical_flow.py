"""The tracker core on synthetic moving textures: known flow, stable ids, re-seeding, the
forward–backward check, depth back-projection and holes, skipped frames."""

import cv2
import numpy as np
import pytest

from sustain_drake.perception.optical_flow import (
    CellGrid,
    PinholeIntrinsics,
    TrackerParams,
    TrackerState,
    back_project,
    cell_visual_change,
    track_frame,
)

W, H = 640, 480
K = PinholeIntrinsics(W, H, fx=500.0, fy=500.0, cx=319.5, cy=239.5)
GRID = CellGrid(W, H, rows=12, cols=16)
DT = 1.0 / 30.0


def texture(seed=0):
    rng = np.random.default_rng(seed)
    noise = rng.uniform(0, 255, (H, W)).astype(np.float32)
    smooth = cv2.GaussianBlur(noise, (0, 0), 2.0)
    smooth = (smooth - smooth.min()) / (smooth.max() - smooth.min()) * 235 + 10
    return smooth.astype(np.uint8)


def shifted(img, dx, dy):
    m = np.float32([[1, 0, dx], [0, 1, dy]])
    return cv2.warpAffine(img, m, (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


def rgba(gray):
    return np.dstack([gray, gray, gray, np.full_like(gray, 255)])


def depth_plane(z=2.0):
    return np.full((H, W, 1), z, np.float32)


def interior(p, margin=30):
    return (p[:, 0] > margin) & (p[:, 0] < W - margin) & (p[:, 1] > margin) & (p[:, 1] < H - margin)


def start(img, t=0.0, depth=None):
    return track_frame(TrackerState.initial(GRID), rgba(img), depth, t, K, GRID)


@pytest.mark.parametrize("dx, dy", [(1.0, 0.0), (1.5, -0.75), (-3.0, 2.0), (0.3, 0.4)])
def test_recovers_a_known_flow_within_a_tenth_of_a_pixel(dx, dy):
    img = texture()
    s0 = start(img)
    assert len(s0.features) > 100
    s1 = track_frame(s0, rgba(shifted(img, dx, dy)), None, DT, K, GRID)
    f = s1.features
    tracked = np.isin(f.ids, s0.ids) & interior(f.p_px)
    assert tracked.sum() > 0.9 * interior(s0.p_px).sum()
    err = np.linalg.norm(f.flow_px[tracked] - [dx, dy], axis=1)
    assert np.median(err) < 0.1 and np.percentile(err, 90) < 0.1
    # ids are stable: same id, moved by the flow
    before = dict(zip(s0.ids.tolist(), s0.p_px.tolist(), strict=True))
    for i, p in zip(f.ids[tracked][:20], f.p_px[tracked][:20], strict=True):
        assert np.allclose(p - np.array(before[int(i)]), [dx, dy], atol=0.1)
    # ṡ_j: a uniform translation gives every textured cell ≈ (number of features) * |flow| / dt
    speed = np.hypot(dx, dy) / DT
    j = np.bincount(GRID.cell_of(f.p_px[tracked]), minlength=GRID.num_cells)
    busy = np.flatnonzero(j >= 3)
    assert np.allclose(s1.sdot[busy] / j[busy], speed, rtol=0.2) or np.hypot(dx, dy) < 0.2


def test_still_scene_gives_exactly_zero_visual_change():
    img = texture()
    s1 = track_frame(start(img), rgba(img), None, DT, K, GRID)
    assert np.all(s1.sdot == 0.0)
    assert len(s1.features) > 100


def test_reseeding_refills_lost_features_with_new_ids():
    img = texture()
    s0 = start(img)
    n0, max_id = len(s0.features), int(s0.ids.max())
    # A new scene (different texture): almost every track is lost and is replaced by new ones.
    s1 = track_frame(s0, rgba(texture(seed=7)), None, DT, K, GRID)
    assert len(s1.features) >= TrackerParams().reseed_fraction * n0
    new = s1.ids[s1.ids > max_id]
    assert new.size > 0.5 * n0
    assert np.unique(s1.ids).size == s1.ids.size          # never a reused id
    assert np.all(s1.features.flow_px[np.isin(s1.ids, new)] == 0)


def test_forward_backward_check_rejects_a_feature_whose_patch_is_replaced():
    img = texture()
    s0 = start(img)
    keep_far = interior(s0.p_px, 60)
    victim = int(np.flatnonzero(keep_far)[0])
    u, v = np.rint(s0.p_px[victim]).astype(int)
    nxt = img.copy()
    nxt[v - 12:v + 13, u - 12:u + 13] = texture(seed=3)[v - 12:v + 13, u - 12:u + 13]
    s1 = track_frame(s0, rgba(nxt), None, DT, K, GRID)
    assert s0.ids[victim] not in s1.ids[: len(s1.ids)]
    # features far from the replaced patch survive with zero flow
    far = np.linalg.norm(s0.p_px - [u, v], axis=1) > 40
    assert np.isin(s0.ids[far], s1.ids).mean() > 0.95


def test_back_projection_and_depth_holes():
    depth = np.full((H, W), 2.0, np.float32)
    depth[10, 20] = 0.0
    depth[11, 20] = np.inf
    depth[12, 20] = np.nan
    depth[13, 20] = -1.0
    p = np.array([[20, 10], [20, 11], [20, 12], [20, 13], [419.5, 139.5], [700, 5]], float)
    p_CP, valid = back_project(p, depth, K)
    assert valid.tolist() == [False, False, False, False, True, False]
    assert np.all(p_CP[~valid] == 0) and np.isfinite(p_CP).all()
    assert np.allclose(p_CP[4], [100 * 2 / 500, -100 * 2 / 500, 2.0])
    # no depth image, or an empty one: all invalid
    assert not back_project(p, None, K)[1].any()
    assert not back_project(p, np.zeros((0, 0, 1), np.float32), K)[1].any()
    with pytest.raises(ValueError, match="depth image is"):
        back_project(p, np.ones((10, 10), np.float32), K)


def test_tracked_features_carry_camera_frame_points():
    img = texture()
    depth = depth_plane(1.5)
    depth[: H // 2] = 0.0                                   # top half: a hole
    s0 = start(img, depth=depth)
    f = s0.features
    top = f.p_px[:, 1] < H // 2 - 1
    bottom = f.p_px[:, 1] > H // 2 + 1
    assert not f.valid[top].any() and f.valid[bottom].all()
    assert np.allclose(f.p_CP[bottom, 2], 1.5)
    assert np.all(f.p_CP[top] == 0)


def test_empty_black_and_stale_frames_are_skipped_without_losing_tracks():
    img = texture()
    s0 = start(img)
    s = track_frame(s0, np.zeros((0, 0, 4), np.uint8), None, DT, K, GRID)      # RgbdSensorAsync
    s = track_frame(s, rgba(np.zeros((H, W), np.uint8)), None, 2 * DT, K, GRID)  # black
    s = track_frame(s, rgba(img), None, 0.0, K, GRID)                          # not newer
    assert s.skipped == 3 and s.frames == s0.frames
    assert np.array_equal(s.ids, s0.ids) and np.array_equal(s.prev_gray, s0.prev_gray)
    # the next real frame is tracked against the last good one, over the whole interval
    s3 = track_frame(s, rgba(shifted(img, 2.0, 0.0)), None, 3 * DT, K, GRID)
    tracked = np.isin(s3.ids, s0.ids) & interior(s3.features.p_px)
    assert tracked.sum() > 0.9 * interior(s0.p_px).sum()
    assert np.median(np.abs(s3.features.flow_px[tracked, 0] - 2.0)) < 0.1
    moving = s3.sdot > 0
    assert np.allclose(s3.sdot[moving].sum(), np.linalg.norm(
        s3.features.flow_px[s3.features.flow_px[:, 0] > 0.2], axis=1).sum() / (3 * DT), rtol=1e-6)


def test_state_copy_is_deep_and_input_is_not_modified():
    s0 = start(texture())
    ids = s0.ids.copy()
    s1 = track_frame(s0, rgba(shifted(texture(), 1, 0)), None, DT, K, GRID)
    assert np.array_equal(s0.ids, ids) and s0.frames == 1 and s1.frames == 2
    c = s1.copy()
    c.ids[:] = -1
    c.features.p_px[:] = -1
    assert (s1.ids >= 0).all() and (s1.features.p_px >= 0).all()


def test_cell_visual_change_sums_flow_norms_per_cell():
    p = np.array([[5, 5], [10, 10], [45, 5], [700, 5]], float)     # two in cell 0, one in 1
    flow = np.array([[3, 4], [0, 0.1], [0, 2], [9, 9]], float)
    sdot = cell_visual_change(GRID, p, flow, 0.5, min_flow_px=0.2)
    assert sdot[0] == pytest.approx(5 / 0.5) and sdot[1] == pytest.approx(2 / 0.5)
    assert sdot.sum() == pytest.approx(14.0)
    with pytest.raises(ValueError, match="frame interval"):
        cell_visual_change(GRID, p, flow, 0.0)


def test_bad_inputs_raise_value_errors():
    with pytest.raises(ValueError, match="color image is"):
        track_frame(TrackerState.initial(GRID), np.zeros((10, 10, 4), np.uint8), None, 0.0, K,
                    GRID)
    with pytest.raises(ValueError, match="uint8"):
        track_frame(TrackerState.initial(GRID), np.zeros((H, W, 4), np.float32), None, 0.0, K,
                    GRID)
    with pytest.raises(ValueError, match="focal"):
        PinholeIntrinsics(W, H, fx=0.0, fy=1.0, cx=0.0, cy=0.0)
    with pytest.raises(ValueError, match="grid"):
        CellGrid(4, 4, rows=8, cols=8)


def test_identity_check_ends_a_track_whose_patch_becomes_another_texture():
    # The same scene one frame later, except that a patch around one feature now shows another
    # texture at the same place (a person passing an arm corner). Where LK with the
    # forward-backward check still keeps the track (it converges to a look-alike spot of the
    # new texture), the appearance test ends it.
    img = texture(0)
    s0 = start(img)
    noise = np.random.default_rng(5).uniform(0, 255, (H, W)).astype(np.float32)
    other = np.clip(cv2.GaussianBlur(noise, (0, 0), 1.0) * 2 - 128, 10, 245).astype(np.uint8)
    lk_only = TrackerParams(ncc_min=0.0)
    ncc = TrackerParams(ncc_min=0.8)
    kept_by_lk = ended = 0
    for victim in np.flatnonzero(interior(s0.features.p_px, 80))[:40]:
        u, v = np.rint(s0.features.p_px[victim]).astype(int)
        nxt = img.copy()
        nxt[v - 12:v + 13, u - 12:u + 13] = other[v - 12:v + 13, u - 12:u + 13]
        if s0.ids[victim] not in track_frame(s0, rgba(nxt), None, DT, K, GRID, lk_only).ids:
            continue
        kept_by_lk += 1
        s1 = track_frame(s0, rgba(nxt), None, DT, K, GRID, ncc)
        ended += s0.ids[victim] not in s1.ids
        # Features away from the replaced patch keep their tracks.
        far = (np.linalg.norm(s0.features.p_px - [u, v], axis=1) > 40) & interior(s0.features.p_px)
        assert np.isin(s0.ids[far], s1.ids).mean() > 0.98
    assert kept_by_lk >= 5
    assert ended >= 0.8 * kept_by_lk
    # The same texture moved by a sub-pixel shift ends no track.
    assert track_frame(s0, rgba(shifted(img, 1.3, -0.7)), None, DT, K, GRID, ncc).identity_drops == 0


def test_identity_check_ends_a_track_whose_depth_jumps():
    # Another surface, 1.5 m behind, now shows where the feature was, with a look-alike
    # texture that LK follows (the default settings: the depth test is on).
    img = texture(0)
    d0 = depth_plane(1.0)
    s0 = start(img, depth=d0)
    u, v = np.rint(s0.features.p_px[np.flatnonzero(interior(s0.features.p_px, 80))[0]]).astype(int)
    d1 = d0.copy()
    d1[v - 12:v + 13, u - 12:u + 13] = 2.5       # the surface there is now 1.5 m farther
    s1 = track_frame(s0, rgba(img), d1, DT, K, GRID)
    gone = np.setdiff1d(s0.ids, s1.ids)
    moved = s0.features.p_px[np.isin(s0.ids, gone)]
    assert gone.size >= 1 and s1.identity_drops == gone.size
    assert np.all(np.abs(moved - [u, v]).max(axis=1) <= 13)
    # Depth noise of a few mm never ends a track.
    noisy = d0 + np.random.default_rng(1).normal(0, 0.005, d0.shape).astype(np.float32)
    assert track_frame(s0, rgba(img), noisy, DT, K, GRID).identity_drops == 0


def checker_shifted(offset, period=16, scale=8):
    """A checker of ``period`` px shifted right by ``offset`` px (drawn 8x larger, area-averaged)."""
    v, u = np.mgrid[0:H * scale, 0:W * scale]
    uu = ((u + 0.5) / scale - 0.5 - offset) / (period / 2)
    vv = ((v + 0.5) / scale - 0.5) / (period / 2)
    img = np.where((np.floor(uu) + np.floor(vv)) % 2 == 0, 220, 30).astype(np.uint8)
    return cv2.resize(img, (W, H), interpolation=cv2.INTER_AREA)


def test_predicted_flow_keeps_tracks_on_a_periodic_texture_moving_faster_than_half_its_period():
    def correct_tracks(predict):
        params = TrackerParams(predict_flow=predict)
        s = track_frame(TrackerState.initial(GRID), rgba(checker_shifted(0.0)), None, 0.0, K, GRID, params)
        start_u = dict(zip(s.features.ids, s.features.p_px[:, 0], strict=True))
        x, v = 0.0, 0.0
        for k in range(1, 12):  # accelerating by 2 px per frame up to 12 px: 3/4 of the 16 px period
            v = min(v + 2.0, 12.0)
            x += v
            s = track_frame(s, rgba(checker_shifted(x)), None, k * DT, K, GRID, params)
        f = s.features
        errors = [u - start_u[i] - x for i, u in zip(f.ids, f.p_px[:, 0], strict=True)
                  if i in start_u and 40 < u < W - 40]
        return int(np.sum(np.abs(errors) < 0.5)), len(start_u)

    kept, seeded = correct_tracks(True)
    assert kept > 0.5 * seeded  # those not leaving the image, each on its own period
    assert correct_tracks(False)[0] < 0.1 * seeded  # from rest, the coarse level loses them
