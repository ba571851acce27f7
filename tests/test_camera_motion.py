"""The camera notices its own motion from the static scene (perception.camera_motion), on synthetic
feature sets, and its Drake system."""

import cv2
import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource
from pydrake.systems.sensors import CameraInfo

from sustain_drake.perception import camera_motion
from sustain_drake.perception.camera_motion import CameraMotionParams, CameraMotionState
from sustain_drake.perception.optical_flow import PinholeIntrinsics, TrackedFeatures
from sustain_drake.systems.camera_motion_detector import CameraMotionDetector
from sustain_drake.systems.motion_coincidence_detector import FeatureBodyFlags

SIZE = (320, 240)
INTRINSICS = PinholeIntrinsics(SIZE[0], SIZE[1], 580.0, 580.0, SIZE[0] / 2 - 0.5, SIZE[1] / 2 - 0.5)
FPS = 30.0
PARAMS = CameraMotionParams()


class Scene:
    """Tracked features of a synthetic scene: ``groups`` name -> (pixels K x 2, robot flag); each
    frame every group moves by its own per-frame motion (a callable of the pixels)."""

    def __init__(self, seed=0, background=40, person=12, robot=15):
        rng = np.random.default_rng(seed)
        self.rng = rng
        self.groups = {
            "background": [rng.uniform([10, 10], [310, 230], (background, 2)), False],
            "person": [rng.uniform([200, 40], [240, 200], (person, 2)), False],
            "robot": [rng.uniform([120, 60], [180, 200], (robot, 2)), True],
        }
        self.ids = {}
        next_id = 0
        for name, (p, _) in self.groups.items():
            self.ids[name] = np.arange(next_id, next_id + len(p))
            next_id += len(p)

    def frame(self, motions):
        """Moves each group by ``motions[name]`` (a function of its pixels, default still) and
        returns (ids, p_px, flow_px, robot) of the new frame."""
        ids, p, flow, robot = [], [], [], []
        for name, group in self.groups.items():
            before = group[0]
            after = motions.get(name, lambda q: q)(before)
            group[0] = after
            ids.append(self.ids[name])
            p.append(after)
            step = after - before
            step[np.linalg.norm(step, axis=1) < 0.2] = 0.0  # the tracker's min_flow_px
            flow.append(step)
            robot.append(np.full(len(after), group[1]))
        return np.concatenate(ids), np.vstack(p), np.vstack(flow), np.concatenate(robot)


def shift(d):
    return lambda q: q + np.asarray(d, float)


def run(scene, frames, motions_of_k, arm_moving_of_k=lambda k: False, state=None, start=0, params=PARAMS):
    """Runs ``frames`` frames; returns the final state and the per-frame outputs."""
    state = state or CameraMotionState()
    outputs = []
    for k in range(start, start + frames):
        ids, p, flow, robot = scene.frame(motions_of_k(k))
        frame = TrackedFeatures(ids=ids, p_px=p, flow_px=flow, time=k / FPS)
        state = camera_motion.step(state, frame, robot, arm_moving_of_k(k), params, SIZE)
        outputs.append(state.output())
    return state, np.array(outputs)


def walking_person(k):
    return {"person": shift([3.0, 0.2])}


def test_a_camera_pan_is_one_move_despite_a_walking_person_and_a_moving_arm():
    scene = Scene()
    arm = {"robot": lambda q: q + np.array([2.5, -1.0]) + 0.02 * (q - 150)}  # the arm's own motion

    def motions(k):
        m = {**walking_person(k), **arm}
        if 30 <= k < 45:  # the camera pans and tilts: everything moves by (2, 1.5) px per frame more
            for name in m:
                m[name] = (lambda f: lambda q: f(q) + [2.0, 1.5])(m[name])
            m["background"] = shift([2.0, 1.5])
        return m

    state, out = run(scene, 30, motions, lambda k: True)
    assert state.moves == 0 and not state.moving  # a person and the arm alone: nothing
    state, out = run(scene, 15, motions, lambda k: True, state, start=30)
    assert state.moves == 1 and state.moving
    assert state.move_start == pytest.approx(30 / FPS)  # the episode's first moving frame
    # Declared as soon as the composed motion reaches move_px (2.5 px per frame: on the 2nd frame).
    assert np.flatnonzero(out[:, 1] == 1)[0] == 1
    assert state.accumulated_px == pytest.approx(15 * np.hypot(2.0, 1.5), rel=0.02)
    state, out = run(scene, 10, motions, lambda k: True, state, start=45)
    assert state.moves == 1 and not state.moving
    assert np.flatnonzero(out[:, 0] == 0)[0] == PARAMS.rest_frames - 1  # the episode ends at rest


def test_the_person_alone_the_robot_alone_or_a_few_outliers_never_move_the_camera():
    scene = Scene(seed=1)
    # The person walks through for 5 s, even across most of the image.
    state, out = run(scene, 150, walking_person)
    assert out[:, 1].max() == 0 and out[:, 0].max() == 0
    # The arm rests 1 s (its body features are anchors then: a body at rest is static scene) and
    # moves: it outnumbers the static scene, but a moving arm's body features are not the scene.
    scene = Scene(seed=2, background=25, person=0, robot=40)

    def arm_after_rest(k):
        return {"robot": shift([2.0, 1.0])} if k >= 30 else {}

    state, out = run(scene, 90, arm_after_rest, lambda k: k >= 30)
    assert out[:, 1].max() == 0 and out[:, 0].max() == 0
    # Unflagged features of the arm (not yet known as the body) that rested: a minority of the
    # anchors, they do not make the consensus.
    scene = Scene(seed=3, background=30, person=0, robot=15)
    scene.groups["robot"][1] = False
    state, out = run(scene, 90, arm_after_rest, lambda k: k >= 30)
    assert out[:, 1].max() == 0 and out[:, 0].max() == 0
    # A few background features jitter (tracking outliers): 5 of 40.
    scene = Scene(seed=4, person=0, robot=0)
    rng = np.random.default_rng(4)

    def outliers(k):
        def jitter(q):
            q = q.copy()
            q[:5] += rng.normal(0, 3.0, (5, 2))
            return q
        return {"background": jitter}

    state, out = run(scene, 150, outliers)
    assert out[:, 1].max() == 0 and out[:, 0].max() == 0


def test_a_person_who_stood_and_walks_on_is_no_camera_move_however_many_their_features():
    # The person stands 2 s while the arm moves (their features become anchors: still against the
    # scene through the arm's motion), outnumbering the scene's 30 anchors, then walks on
    # slowly (1.2 px per frame, under inlier_px: the scene's anchors are inliers of the person's
    # per-frame motion too, and the person's drift from their still pixels is the consensus).
    scene = Scene(seed=11, background=30, person=50, robot=10)

    def person_walks_on(k):
        return {"person": shift([1.2, 0.3])} if k >= 60 else {}

    state, out = run(scene, 150, person_walks_on, lambda k: True)
    assert out[:, 1].max() == 0 and state.moves == 0
    # A camera pan at the same pace while the person stands moves every anchor: one move.
    scene = Scene(seed=11, background=30, person=50, robot=10)

    def camera_pans(k):
        return {"background": shift([1.2, 0.3]), "person": shift([1.2, 0.3])} if k >= 60 else {}

    state, out = run(scene, 150, camera_pans, lambda k: True)
    assert state.moves == 1


def test_unflagged_arm_features_that_rested_do_not_become_the_scene_when_the_arm_moves_again():
    # A near camera: the arm (its features not flagged by the body detector) fills most of the
    # image, 60 features against 25 of the background. The arm moves, rests 1 s, moves again: its
    # features, still only while it rested, are no anchors when it moves.
    scene = Scene(seed=7, background=25, person=0, robot=60)
    scene.groups["robot"][1] = False

    def arm(k):
        return {} if 30 <= k < 60 else {"robot": shift([2.0, 1.0])}

    state, out = run(scene, 120, arm, lambda k: not 30 <= k < 60)
    assert out[:, 1].max() == 0


def test_too_few_background_features_never_judge_a_frame():
    scene = Scene(seed=5, background=PARAMS.min_background - 1, person=0, robot=0)
    state, _ = run(scene, 30, lambda k: {})
    state, out = run(scene, 30, lambda k: {"background": shift([3.0, 0.0])}, state=state, start=30)
    assert out[:, 1].max() == 0 and not state.last.judged


def test_a_resting_arm_is_static_scene_and_a_small_move_is_not_a_camera_move():
    """With the arm at rest its body features are anchors (a body at rest is static scene); a
    camera move below move_px is an episode but no camera move."""
    scene = Scene(seed=6, background=3, person=0, robot=20)
    state, _ = run(scene, 30, lambda k: {})
    state, out = run(scene, 2, lambda k: {"background": shift([1.2, 0]), "robot": shift([1.2, 0])},
                     state=state, start=30)  # fmt: skip
    assert out[-1, 0] == 1 and state.moves == 0 and state.accumulated_px == pytest.approx(2.4, rel=0.02)
    state, out = run(scene, 5, lambda k: {}, state=state, start=32)
    assert state.moves == 0 and not state.moving
    # The same arm moving (not at rest): its body features are not the scene; 3 anchors are too few.
    state, out = run(scene, 10, lambda k: {"background": shift([3.0, 0]), "robot": shift([3.0, 0])},
                     lambda k: True, state=state, start=37)  # fmt: skip
    assert state.moves == 0


def test_bad_input_and_parameters():
    with pytest.raises(ValueError, match="camera motion parameters"):
        CameraMotionParams(move_px=0.1, still_px=0.5)
    def frame(n, flows=None, time=0.0, **points):
        return TrackedFeatures(ids=np.arange(n), p_px=np.zeros((n, 2)), flow_px=np.zeros((flows or n, 2)),
                               time=time, **points)  # fmt: skip

    with pytest.raises(ValueError, match="one per feature"):
        camera_motion.step(CameraMotionState(), frame(3, flows=2, time=0.1), np.zeros(3, bool), False, PARAMS,
                           SIZE)  # fmt: skip
    with pytest.raises(ValueError, match="2 points, 3 valid flags"):
        points = frame(3, time=0.1, p_CP=np.zeros((2, 3)), valid=np.ones(3, bool))
        camera_motion.step(CameraMotionState(), points, np.zeros(3, bool), False, PARAMS, SIZE, INTRINSICS)
    # A frame not newer than the last is skipped.
    state = camera_motion.step(CameraMotionState(), frame(3, time=1.0), np.zeros(3, bool), False, PARAMS,
                               SIZE)  # fmt: skip
    assert camera_motion.step(state, frame(2, time=1.0), np.zeros(2, bool), False, PARAMS, SIZE) is state


class ScriptedFeatures(LeafSystem):
    """Tracked features of a 40-point static scene, at 30 Hz, panned by 2 px per frame from 1.0 to
    1.5 s; the feature flags (none on the body) beside them."""

    def __init__(self):
        super().__init__()
        rng = np.random.default_rng(7)
        self._p0 = rng.uniform([10, 10], [310, 230], (40, 2))
        self.DeclareAbstractOutputPort("tracked_features", lambda: AbstractValue.Make(TrackedFeatures()),
                                       self._features)  # fmt: skip
        self.DeclareAbstractOutputPort("feature_on_body", lambda: AbstractValue.Make(FeatureBodyFlags()),
                                       self._flags)  # fmt: skip

    @staticmethod
    def _offset(k):
        return 2.0 * np.clip(k - 30, 0, 15)

    def _features(self, context, output):
        k = int(np.floor(context.get_time() * FPS + 1e-9))
        p = self._p0 + [self._offset(k), 0.0]
        flow = np.tile([self._offset(k) - self._offset(k - 1), 0.0], (40, 1))
        output.set_value(TrackedFeatures(ids=np.arange(40), p_px=p, flow_px=flow, p_CP=np.zeros((40, 3)),
                                         valid=np.zeros(40, bool), cell=np.zeros(40, np.int64), time=k / FPS))

    def _flags(self, context, output):
        output.set_value(FeatureBodyFlags(ids=np.arange(40), on_body=np.zeros(40, bool),
                                          in_body_cell=np.zeros(40, bool), actuator=np.full(40, -1)))


def test_the_system_declares_one_move_and_its_context_clones():
    builder = DiagramBuilder()
    scene = builder.AddSystem(ScriptedFeatures())
    info = CameraInfo(SIZE[0], SIZE[1], 290.0, 290.0, 159.5, 119.5)
    detector = builder.AddSystem(CameraMotionDetector(5, 192, SIZE, period=1.0 / FPS, offset=0.5 / FPS,
                                                      camera_info=info))  # fmt: skip
    q = builder.AddSystem(ConstantVectorSource(np.zeros(5)))
    for name in ("tracked_features", "feature_on_body"):
        builder.Connect(scene.GetOutputPort(name), detector.GetInputPort(name))
    builder.Connect(q.get_output_port(), detector.GetInputPort("actuator_positions"))
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(1.02)
    context = detector.GetMyContextFromRoot(simulator.get_context())
    assert list(detector.GetOutputPort("camera_motion").Eval(context)) == [0.0, 0.0]
    # Judged still since the features became anchors (0.5 s still).
    assert 0.5 <= detector.GetOutputPort("scene_still_since").Eval(context)[0] <= 0.6
    assert detector.GetOutputPort("move_start").Eval(context)[0] == -np.inf  # no move yet
    saved = simulator.get_context().Clone()
    simulator.AdvanceTo(1.2)
    context = detector.GetMyContextFromRoot(simulator.get_context())
    assert list(detector.GetOutputPort("camera_motion").Eval(context)) == [1.0, 1.0]
    assert detector.GetOutputPort("scene_still_since").Eval(context)[0] == np.inf  # moving
    assert 1.02 < detector.GetOutputPort("move_start").Eval(context)[0] < 1.2  # its first moving frame
    simulator.AdvanceTo(2.0)
    assert 1.5 < detector.GetOutputPort("scene_still_since").Eval(context)[0] < 1.7  # since the move ended
    assert list(detector.GetOutputPort("camera_motion").Eval(context)) == [0.0, 1.0]
    displacement = detector.GetOutputPort("accumulated_displacement").Eval(context)[0]
    assert displacement == pytest.approx(30.0, rel=1e-6)
    # The scene's correspondences across the move: every feature, 30 px further right after it
    # (no depth given: the points before are NaN, far away).
    turn = detector.GetOutputPort("scene_turn").Eval(context)
    assert turn.move == 1 and len(turn) == 40 and np.all(np.isnan(turn.q0))
    u0 = turn.b0[:, 0] / turn.b0[:, 2] * 290.0 + 159.5
    u1 = turn.b1[:, 0] / turn.b1[:, 2] * 290.0 + 159.5
    assert np.allclose(u1 - u0, 30.0)
    # The cloned context kept its own state (nothing in Python attributes).
    clone = detector.GetMyContextFromRoot(saved)
    assert list(detector.GetOutputPort("camera_motion").Eval(clone)) == [0.0, 0.0]
    assert detector.GetOutputPort("scene_turn").Eval(clone).move == 0
    with pytest.raises(ValueError, match="camera_info is 640x480"):
        CameraMotionDetector(5, 192, SIZE, camera_info=CameraInfo(640, 480, 580.0, 580.0, 319.5, 239.5))
    # The grey image: none yet (0 x 0) is no image; one of another size is a clear error.
    detector.GetInputPort("gray_image").FixValue(context, np.zeros((0, 0), np.uint8))
    simulator.AdvanceTo(2.1)
    detector.GetInputPort("gray_image").FixValue(context, np.zeros((10, 10), np.uint8))
    with pytest.raises(ValueError, match=r"gray_image is \(10, 10\), expected \(240, 320\)"):
        simulator.AdvanceTo(2.2)


def test_features_still_while_the_arm_moves_are_static_scene_not_hand_candidates():
    scene = Scene(seed=8, background=25, person=0, robot=10)
    scene.groups["robot"][1] = False  # in no body cell, as after a camera move
    static_ids, hand_ids = scene.ids["background"], scene.ids["robot"]
    # The arm rests 1 s: nothing is known to be static yet (a resting hand is still too).
    state, _ = run(scene, 30, lambda k: {})
    assert not camera_motion.static_features(state, np.concatenate([static_ids, hand_ids]), PARAMS).any()
    # The joints start to move; the image lags (the hand's features still for 2 frames): no
    # feature is static scene yet, the arm has not moved long enough.
    state, _ = run(scene, 2, lambda k: {}, lambda k: True, state, start=30)
    assert not camera_motion.static_features(state, hand_ids, PARAMS).any()
    # The arm moves the hand's features for 1 s: the still ones are the static scene.
    state, _ = run(scene, 30, lambda k: {"robot": shift([1.0, 0.5])}, lambda k: True, state, start=32)
    assert camera_motion.static_features(state, static_ids, PARAMS).all()
    assert not camera_motion.static_features(state, hand_ids, PARAMS).any()
    # A hand feature creeping (0.15 px per frame, a point near the axis of a wrist roll): its
    # drift adds up, it is not static.
    state, _ = run(scene, 30, lambda k: {"robot": shift([0.15, 0.0])}, lambda k: True, state, start=62)
    assert not camera_motion.static_features(state, hand_ids, PARAMS).any()


def test_a_slow_pan_while_the_arm_rests_is_a_camera_move():
    """A pan whose every frame stays below ``still_px`` (a head's slow ramp, then a creep) is one
    camera move: the anchors' drift from their still pixels adds up. Judged frame by frame alone,
    every anchor restarts once ``feature_still_px`` away, all in one frame, and the move is lost."""
    scene = Scene(seed=11, background=40, person=0, robot=15)
    state, _ = run(scene, 30, lambda k: {})
    per_frame = 0.9 * PARAMS.still_px
    ramp = [0.1 * per_frame, 0.4 * per_frame, 0.7 * per_frame] + [per_frame] * 17

    def pan(k):
        return {"background": shift([ramp[k - 30], 0.0]), "robot": shift([ramp[k - 30], 0.0])}

    state, out = run(scene, len(ramp), pan, state=state, start=30)
    assert sum(ramp) > 2 * PARAMS.move_px
    assert state.moves == 1 and state.last.judged
    assert state.accumulated_px == pytest.approx(sum(ramp), rel=0.1)
    state, out = run(scene, 10, lambda k: {}, state=state, start=30 + len(ramp))
    assert state.moves == 1 and not state.moving
    # Still, with the tracker's sub-pixel noise: no episode.
    rng = np.random.default_rng(3)

    def jitter(k):
        return {"background": lambda q: q + rng.normal(0.0, 0.05, q.shape)}

    state, out = run(scene, 60, jitter, state=state, start=60)
    assert state.moves == 1 and out[:, 0].max() == 0


def texture(shape, seed):
    """Print at every scale (posters, boxes, their letters): blobs of 2 to 32 px, grey levels."""
    rng = np.random.default_rng(seed)
    image = sum(cv2.GaussianBlur(rng.uniform(-1, 1, shape).astype(np.float32), (0, 0), sigma) * sigma
                for sigma in (2.0, 8.0, 32.0))
    return cv2.normalize(image, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)


def textured_frames(shift_px, seed=5, person_step=None):
    """A still textured wall seen before and after an image shift of ``shift_px`` (px, a pan of
    ``shift_px / f`` rad): per view the grey image and its strongest corners (pixels, and their
    points at 2 m). ``person_step``: a person (a textured block over two thirds of the image)
    stands in the first view and has walked that many px in the second, where its corners are
    not anchors (it moves)."""
    wall = texture((300, 520), seed)
    person = texture((160, 220), seed + 1)
    views = []
    for k, dx in enumerate((0, shift_px)):
        gray = np.ascontiguousarray(wall[30:30 + SIZE[1], 50 + dx:50 + dx + SIZE[0]])
        mask = None
        if person_step is not None:
            x = 40 + k * person_step
            gray[40:200, x:x + 220] = person[:, :min(220, SIZE[0] - x)]
            if k == 1:
                mask = np.full(gray.shape, 255, np.uint8)
                mask[30:210, x - 10:] = 0
        px = cv2.goodFeaturesToTrack(gray, 60, 0.01, 10, mask=mask).reshape(-1, 2).astype(float)
        p_CP = np.column_stack([(px - [INTRINSICS.cx, INTRINSICS.cy]) / INTRINSICS.fx * 2.0,
                                np.full(len(px), 2.0)])
        views.append((gray, px, p_CP))
    return views


def run_gap(shift_px, with_image=True, gap_frames=6, person_step=None):
    """The arm moving throughout; 40 frames of the wall, ``gap_frames`` with no track at all (a
    person in front of the camera), then the wall shifted by ``shift_px`` with every track new
    (``person_step``: see ``textured_frames``). Returns the final state and the frame of the first
    declared move (None)."""
    (g0, px0, p0), (g1, px1, p1) = textured_frames(shift_px, person_step=person_step)
    state, declared = CameraMotionState(), None
    for k in range(120):
        if k < 40:
            gray, ids, px, p = g0, np.arange(len(px0)), px0, p0
        elif k < 40 + gap_frames:
            gray, ids, px, p = g1, np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 3))
        else:
            gray, ids, px, p = g1, 1000 + np.arange(len(px1)), px1, p1
        frame = TrackedFeatures(ids=ids, p_px=px, flow_px=np.zeros_like(px), p_CP=p,
                                valid=np.ones(len(ids), bool), time=k / FPS)
        state = camera_motion.step(state, frame, np.zeros(len(ids), bool), np.array([True]), PARAMS, SIZE,
                                   INTRINSICS, gray if with_image else None)
        if declared is None and state.moves:
            declared = k
    return state, declared


def test_a_move_while_the_tracks_were_broken_is_found_from_the_still_scenes_image():
    """Every track ends while the camera pans 12 px (a person passing in front of it): the new
    tracks never moved, so only the still scene's image before and after shows the move; the
    reference's anchors followed into the image after are its turn (each the same corner, 12 px
    over). Without the image the move is missed; with no move, none is found."""
    state, k = run_gap(12)
    assert k is not None and k < 40 + 6 + 15 + PARAMS.turn_frames + 3
    assert state.moves == 1 and abs(state.accumulated_px - 12.0) < 0.5
    turn = state.turn
    assert turn.move == 1 and len(turn) >= 20 and turn.start < 40 / FPS
    assert state.move_start == turn.start  # the reference's time: at most when the camera began to move
    def pixels(b):
        return b[:, :2] / b[:, 2:] * INTRINSICS.fx + [INTRINSICS.cx, INTRINSICS.cy]

    # Each the same corner (Lucas-Kanade to a few hundredths of a pixel, 0.33 px on one), its depth
    # after from the new track on it.
    off = np.linalg.norm(pixels(turn.b1) - pixels(turn.b0) - [-12.0, 0.0], axis=1)
    assert np.median(off) < 0.01 and off.max() < PARAMS.inlier_px
    assert np.allclose(turn.q0[:, 2], 2.0) and np.allclose(turn.q1[:, 2], 2.0)
    assert run_gap(12, with_image=False)[0].moves == 0
    # A pan of 80 px (0.14 rad; a quarter of the image): the pyramid follows it.
    far, _ = run_gap(80)
    assert far.moves == 1 and abs(far.accumulated_px - 80.0) < 0.5 and len(far.turn) >= 8
    still, k_still = run_gap(0)
    assert k_still is None and still.reference is not None and not still.gap
    # A person who stood still among the reference's anchors (most of them) has walked 30 px: the
    # reference's anchors agree on the person's step, the still scene now (the anchors followed
    # back) on none. No move.
    (g0, px0, _), _ = textured_frames(0, person_step=30)
    on_person = np.mean((px0[:, 0] >= 40) & (px0[:, 1] >= 40) & (px0[:, 1] < 200))
    assert on_person > 0.6
    walked, k_walked = run_gap(0, person_step=30)
    assert k_walked is None and walked.moves == 0


def test_the_camera_stays_unmoved_across_a_gap_the_still_scenes_image_shows_no_move_in():
    """``scene_still_since`` joins the still frames across a gap (every track ended: a person in
    front of the camera) once the reference, matched after it, shows no move; it is inf until that
    check, and it restarts after a move found so, or where no image can check the gap."""
    def still_since_during(shift_px, with_image=True):
        (g0, px0, p0), (g1, px1, p1) = textured_frames(shift_px)
        state, seen = CameraMotionState(), []
        for k in range(120):
            if k < 40:
                gray, ids, px, p = g0, np.arange(len(px0)), px0, p0
            elif k < 46:
                gray, ids, px, p = g1, np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 3))
            else:
                gray, ids, px, p = g1, 1000 + np.arange(len(px1)), px1, p1
            frame = TrackedFeatures(ids=ids, p_px=px, flow_px=np.zeros_like(px), p_CP=p,
                                    valid=np.ones(len(ids), bool), time=k / FPS)
            state = camera_motion.step(state, frame, np.zeros(len(ids), bool), np.array([True]), PARAMS,
                                       SIZE, INTRINSICS, gray if with_image else None)
            seen.append(state.scene_still_since())
        return np.array(seen)

    still = still_since_during(0)
    first = still[39]
    assert first < 40 / FPS and np.all(still[41:46] == np.inf)  # the gap, not yet checked
    assert np.all(still[-20:] == first)  # checked: the camera did not move since before the gap
    moved = still_since_during(12)
    assert np.all(moved[-20:] > 46 / FPS) and np.all(np.isfinite(moved[-20:]))
    unchecked = still_since_during(0, with_image=False)
    assert np.all(unchecked[-20:] > 46 / FPS) and np.all(np.isfinite(unchecked[-20:]))


def run_tracked_pan(shift_px, with_image=True, pan_frames=6):
    """The arm moving throughout; 40 frames of the wall, then a pan of ``shift_px`` over
    ``pan_frames`` frames that the tracks follow (the move is declared), and every track ends as
    the camera comes to rest (the wall after it is tracked anew). Returns the final state."""
    (g0, px0, p0), (g1, px1, p1) = textured_frames(shift_px)
    state = CameraMotionState()
    for k in range(120):
        if k < 40 + pan_frames:
            step = min(max(k - 40 + 1, 0), pan_frames)
            gray, ids, p = (g0 if k < 40 else g1), np.arange(len(px0)), p0
            px = px0 - [shift_px * step / pan_frames, 0.0]
            flow = np.tile([-shift_px / pan_frames if 40 <= k else 0.0, 0.0], (len(px0), 1))
        else:
            gray, ids, px, p, flow = g1, 1000 + np.arange(len(px1)), px1, p1, np.zeros_like(px1)
        frame = TrackedFeatures(ids=ids, p_px=px, flow_px=flow, p_CP=p, valid=np.ones(len(ids), bool),
                                time=k / FPS)
        state = camera_motion.step(state, frame, np.zeros(len(ids), bool), np.array([True]), PARAMS, SIZE,
                                   INTRINSICS, gray if with_image else None)
    return state


def test_a_declared_move_whose_tracks_all_ended_takes_its_turn_from_the_still_scenes_image():
    """The tracks follow a 30 px pan (the move is declared) but all end as the camera comes to rest
    (a person walks past, a near camera whose view the arm fills): no anchor is tracked across the
    move, so the still frame before it, matched into the view after, gives the turn (each
    correspondence the same corner, 30 px over). Without the image there is no turn."""
    state = run_tracked_pan(30)
    assert state.moves == 1 and state.turn.move == 1 and len(state.turn) >= 20
    assert state.turn.start == pytest.approx(40 / FPS) and state.before_move is None
    pixels = [b[:, :2] / b[:, 2:] * INTRINSICS.fx + [INTRINSICS.cx, INTRINSICS.cy]
              for b in (state.turn.b0, state.turn.b1)]
    off = np.linalg.norm(pixels[1] - pixels[0] - [-30.0, 0.0], axis=1)
    assert np.median(off) < 0.05 and off.max() < PARAMS.inlier_px
    blind = run_tracked_pan(30, with_image=False)
    assert blind.moves == 1 and len(blind.turn) == 0
