"""The camera from tracks that end before any converges: the joint TLS of K points
(``eye_to_hand_points.joint_tls``) and the consensus of the tracks since a reset
(``candidates.track_consensus``)."""

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_candidates import CRITERIA, DT, P_TOOL, TRUTH, hand_pose, other_link, seen

from sustain_drake.identification import candidates
from sustain_drake.identification.candidates import (
    CandidateBank,
    CandidateParams,
    FrameInput,
    track_consensus,
)
from sustain_drake.identification.candidates.fitting import REGION_95, S_of
from sustain_drake.identification.errors import IdentificationError
from sustain_drake.identification.eye_to_hand import EyeToHandIdentifier
from sustain_drake.identification.eye_to_hand_points import joint_tls, refine_joint

R_TRUE, P_TRUE = TRUTH.X_WC[:3, :3], TRUTH.X_WC[:3, 3]
# The loop's rules that matter here (``loops.hand_eye.hand_eye_parts``): the joint fit, 100 samples
# and 0.05 rad of hand rotation to join, the points within twice the best one's RMS error, the
# camera's 95 % region within 2 mm and 0.2 deg.
PARAMS = CandidateParams(joint=True, joint_consistency=2.0, observe_min_samples=100, min_rotation_spread=0.05,
                         camera_accuracy=0.002, camera_rotation_accuracy=math.radians(0.2))
# No single track of 120 frames converges on its own (the paper's rule needs 250 samples).
SHORT = replace(CRITERIA, min_samples=250)


def rotation_error_deg(R):
    return math.degrees(Rotation.from_matrix(R.T @ R_TRUE).magnitude())


def short_track(feature_id, p_HP, start, rng, n=120, link=False, noise=0.5e-3):
    """A candidate that tracked ``p_HP`` over ``hand_pose`` frames ``start`` to ``start + n`` (a
    point of another link, rigid with the hand only while that link stands still, with ``link``)."""
    identifier = EyeToHandIdentifier()
    for k in range(start, start + n):
        X = hand_pose(k)
        X_seen, p = other_link(X, k, p_HP) if link else (X, p_HP)
        identifier.add(seen(X_seen, p, rng, noise=noise), X[:3, :3], X[:3, 3])
    end = (start + n - 1) * DT
    return candidates.Candidate(feature_id, identifier.state, identifier.solve(), start * DT, end)


def points(k):
    return P_TOOL + [0.02 * (k % 3), -0.015 * (k % 2), 0.01 * k]


def test_joint_tls_gives_the_camera_no_point_gives_alone():
    """Five points tracked for 40 frames each at different times (0.5 mm of noise): one point's own
    TLS camera is metres off, the joint TLS (no starting guess) within centimetres, refined jointly
    within the hand-eye targets (2-3 mm on five draws: 200 samples); its points are each point's own."""
    rng = np.random.default_rng(4)
    tracks = [short_track(k, points(k), 40 * k, rng, n=40) for k in range(5)]
    alone = [np.linalg.norm(c.solution.projected.p_WC - P_TRUE) for c in tracks]
    S_list = [S_of(c.statistic) for c in tracks]
    R, p_WC, P = joint_tls(S_list)
    assert min(alone) > 0.5  # metres: 40 samples of one point pin nothing
    assert np.linalg.norm(p_WC - P_TRUE) < 0.03 and rotation_error_deg(R) < 1.0
    R, p_WC, P = refine_joint(S_list, R, p_WC, P)
    assert np.linalg.norm(p_WC - P_TRUE) < 4e-3 and rotation_error_deg(R) < 0.2
    assert np.abs(P - np.array([points(k) for k in range(5)])).max() < 1e-3
    with pytest.raises(IdentificationError, match="at least one statistic"):
        joint_tls([])


def test_the_consensus_is_the_hands_camera_when_another_links_points_outnumber_it():
    """Three points of the hand tracked early, then two more of the hand with four of another link
    (rigid with the hand while it stands, turning 0.6 rad about the hand's x otherwise): fitted all
    together the camera is centimetres off; the consensus leaves the other link out (its points
    agree only among themselves, within one time), and the camera is the hand's."""
    rng = np.random.default_rng(1)
    early = [short_track(k, points(k), 0, rng) for k in range(3)]
    late = [short_track(3 + k, points(3 + k), 130, rng) for k in range(2)]
    link = [short_track(10 + k, [0.05 * k, -0.1, 0.2 + 0.03 * k], 130, rng, link=True) for k in range(4)]
    members = early + late + link
    S_list = [S_of(c.statistic) for c in members]
    R, p_WC, _ = refine_joint(S_list, *joint_tls(S_list))
    assert np.linalg.norm(p_WC - P_TRUE) > 0.01
    (R, p_WC, P), inliers, errors = track_consensus.consensus(members, PARAMS)
    assert sorted(c.feature_id for c in inliers) == [0, 1, 2, 3, 4]
    hand = [S_of(c.statistic) for c in early + late]
    R_hand, p_hand, _ = refine_joint(hand, *joint_tls(hand))
    assert np.allclose(p_WC, p_hand, atol=1e-9) and np.allclose(R, R_hand, atol=1e-9)
    assert np.linalg.norm(p_WC - P_TRUE) < 3e-3 and rotation_error_deg(R) < 0.2


def run(params, criteria, windows=4, per_window=120):
    """Every track ends after ``per_window`` frames (a person walking between the camera and the
    arm) and four new points of the hand are tracked: the bank after ``windows`` of them."""
    bank, rng = CandidateBank(), np.random.default_rng(2)
    for k in range(windows * per_window):
        w, X = k // per_window, hand_pose(k)
        ids = [100 * w + i for i in range(4)]
        p = [seen(X, points(4 * w + i), rng) for i in range(4)]
        frame = FrameInput(k * DT, 0.0, X, k * DT, np.array(ids), np.array(p), np.ones(4, bool),
                           np.ones(4, bool), None)
        bank = candidates.step(bank, params, criteria, frame)
    return bank


def test_tracks_that_end_before_any_converges_give_the_camera_together():
    """No track lives the 250 samples the paper's rule needs: with the joint fit the points of two
    times give the camera (within 1 mm and 0.05 deg), adopted as such, once the second time's
    tracks have 100 samples; without it nothing is adopted."""
    bank = run(PARAMS, SHORT)
    assert [a.kind for a in bank.adoptions] == [track_consensus.KIND]
    adoption = bank.adoptions[0]
    assert 120 * DT + 99 * DT <= adoption.time <= 240 * DT
    assert np.linalg.norm(adoption.estimate.p_WC - P_TRUE) < 1e-3
    assert rotation_error_deg(adoption.estimate.R_WC) < 0.05
    region = REGION_95 * np.array(adoption.camera_sd)  # within the targets it was adopted against
    assert 0.0 < region[0] <= PARAMS.camera_accuracy and 0.0 < region[1] <= PARAMS.camera_rotation_accuracy
    leader = bank.find(bank.leader)
    assert np.linalg.norm(leader.solution.estimate.p_HP - points(4 + leader.feature_id - 100)) < 1e-3
    assert run(replace(PARAMS, joint=False), SHORT).adoptions == ()


def test_tracks_of_one_time_alone_give_no_camera():
    """Tracks seen together share their time's motion, so their agreement is not a confirmation:
    with one window of tracks, however long, no consensus is adopted."""
    bank = run(PARAMS, replace(CRITERIA, min_samples=10_000), windows=1, per_window=400)
    assert bank.adoptions == ()
