"""Motion that excites what is unknown (issue 25): the D-optimal gain per second, the static
payload's posture information, a greedy choice that identifies a payload in two rests, and the
eye-to-hand information of a hand path."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sustain_drake.identification import EyeToHandIdentifier, IdentificationError, PayloadIdentifier
from sustain_drake.identification.excitation import best_candidate, information_gains
from sustain_drake.identification.eye_to_hand import (
    EyeToHandEstimate,
    pack_x,
    path_information,
    predicted_points,
)
from sustain_drake.identification.payload import STANDARD_GRAVITY_W, posture_information
from tests.eye_to_hand_data import make_samples, make_truth
from tests.test_payload import make_wrenches


def test_the_least_determined_direction_is_filled_first():
    """Information along x only: a candidate adding along y gains far more than one adding along x,
    even ten times more of it."""
    M = np.diag([100.0, 0.0])
    along_x, along_y = np.diag([1000.0, 0.0]), np.diag([0.0, 1.0])
    gains = information_gains(M, [along_x, along_y])
    assert gains[1] > 5.0 * gains[0] > 0.0
    assert best_candidate(M, [along_x, along_y], [1.0, 1.0]) == 1


def test_the_choice_does_not_depend_on_the_units_of_the_unknowns():
    rng = np.random.default_rng(3)
    def psd(n):
        a = rng.normal(size=(n, 3))
        return a @ a.T
    M, added = psd(3) + np.eye(3) * 0.1, [psd(3) for _ in range(6)]
    D = np.diag([1e-3, 1.0, 1e4])  # the unknowns in other units
    scaled = information_gains(D @ M @ D, [D @ d @ D for d in added])
    np.testing.assert_allclose(scaled, information_gains(M, added), rtol=1e-6, atol=1e-9)


def test_gain_per_second():
    """Twice the information in four times the time loses to the original."""
    M, d = np.diag([1.0, 1.0]), np.diag([0.0, 1.0])
    assert best_candidate(M, [2.0 * d, d], [4.0, 1.0]) == 1
    assert best_candidate(M, [2.0 * d, d], [1.0, 1.0]) == 0


@pytest.mark.parametrize("durations", [[1.0], [1.0, 0.0], [1.0, -2.0]])
def test_bad_durations_raise(durations):
    with pytest.raises(ValueError):
        best_candidate(np.eye(2), [np.eye(2), np.eye(2)], durations)


def test_posture_information_predicts_the_samples_it_will_get():
    """The statistic of n rest samples at R0 holds M; n more predicted at R0 add exactly M (the mass
    is read off the statistic); the block is S's over [1/m; p_KCm]."""
    R0 = Rotation.from_euler("xyz", [0.4, -0.3, 1.2]).as_matrix()
    wrench, R = make_wrenches(0.6, np.array([0.01, -0.02, 0.15]), 40, orientations=np.tile(R0, (40, 1, 1)))
    ident = PayloadIdentifier()
    for w, r in zip(wrench, R, strict=True):
        ident.add(w, r)
    M, (dM,) = posture_information(ident.state, [R0], STANDARD_GRAVITY_W, 40)
    np.testing.assert_allclose(M, ident.core.S[:4, :4])
    np.testing.assert_allclose(dM, M, rtol=1e-9, atol=1e-9)


def test_greedy_rests_identify_a_payload_where_one_orientation_cannot():
    """From one rest, the chooser's next orientation among random ones turns gravity in K far from
    the first, and the two rests' samples identify the payload (one rest never does)."""
    rng = np.random.default_rng(0)
    mass, p = 0.6, np.array([0.01, -0.02, 0.15])
    R0 = Rotation.random(random_state=rng).as_matrix()
    ident = PayloadIdentifier()
    first, _ = make_wrenches(mass, p, 60, seed=1, force_noise=0.02, torque_noise=5e-4,
                             orientations=np.tile(R0, (60, 1, 1)))
    for w in first:
        ident.add(w, R0)
    assert not ident.solve().verdict.converged
    candidates = Rotation.random(16, random_state=rng).as_matrix()
    M, added = posture_information(ident.state, candidates, STANDARD_GRAVITY_W, 60)
    chosen = candidates[best_candidate(M, added, [1.0] * 16)]
    g0, g1 = R0.T @ STANDARD_GRAVITY_W, chosen.T @ STANDARD_GRAVITY_W
    angle = np.degrees(np.arccos(g0 @ g1 / (g0 @ g0)))
    others = [np.degrees(np.arccos(g0 @ (c.T @ STANDARD_GRAVITY_W) / (g0 @ g0))) for c in candidates]
    assert min(angle, 180 - angle) >= max(min(a, 180 - a) for a in others) - 1e-9  # the most turned
    second, _ = make_wrenches(mass, p, 60, seed=2, force_noise=0.02, torque_noise=5e-4,
                              orientations=np.tile(chosen, (60, 1, 1)))
    for w in second:
        ident.add(w, chosen)
    solution = ident.solve()
    assert solution.verdict.converged, solution.verdict
    assert abs(solution.mass - mass) / mass < 0.01 and np.linalg.norm(solution.p_KCm - p) < 2e-3


# ---- eye-to-hand ----------------------------------------------------------------------------------
def _eye_to_hand(truth, X_WH):
    p_W = np.einsum("nij,j->ni", X_WH[:, :3, :3], truth.p_HP) + X_WH[:, :3, 3]
    p_C = (p_W - truth.X_WC[:3, 3]) @ truth.X_WC[:3, :3]
    ident = EyeToHandIdentifier()
    for p, X in zip(p_C, X_WH, strict=True):
        ident.add_pose(p, X)
    return ident, p_C


def _about_axis(axis, angles, seed=0):
    rng = np.random.default_rng(seed)
    X_WH = np.tile(np.eye(4), (len(angles), 1, 1))
    X_WH[:, :3, :3] = Rotation.from_rotvec(np.outer(angles, axis)).as_matrix()
    X_WH[:, :3, 3] = rng.uniform(-0.1, 0.1, (len(angles), 3)) + [0.4, 0.0, 0.3]
    return X_WH


def test_path_information_predicts_the_samples_it_will_get():
    """Predicted with the true camera and point, a path's ``dM`` is exactly what its samples add to the
    statistic (weights 1 and 2: each pose counted as many times); ``M`` is S's block over the 15
    unknowns, and the points predicted are the camera's."""
    truth = make_truth(3)
    before, _ = _eye_to_hand(truth, make_samples(truth, 30)[1])
    _, X_new = make_samples(truth, 12, seed=7)
    estimate = EyeToHandEstimate(truth.X_WC[:3, :3], truth.X_WC[:3, 3], truth.p_HP,
                                 pack_x(truth.X_WC[:3, :3], truth.X_WC[:3, 3], truth.p_HP), 0.0)
    p_CP = predicted_points(estimate, X_new)
    weights = np.r_[np.ones(6), 2.0 * np.ones(6)]
    M, (dM,) = path_information(before.state, [(p_CP, X_new, weights)])
    after = EyeToHandIdentifier()
    after.set_state(before.state)
    for p, X, w in zip(p_CP, X_new, weights, strict=True):
        for _ in range(int(w)):
            after.add_pose(p, X)
    np.testing.assert_allclose(M, before.core.S[:15, :15])
    np.testing.assert_allclose(dM, (after.core.S - before.core.S)[:15, :15], rtol=1e-9, atol=1e-9)
    p_W = np.einsum("nij,j->ni", X_new[:, :3, :3], truth.p_HP) + X_new[:, :3, 3]
    np.testing.assert_allclose(truth.X_WC[:3, :3] @ p_CP.T + truth.X_WC[:3, 3:4], p_W.T, atol=1e-12)


def test_a_turn_about_a_new_axis_is_worth_more_than_more_of_the_same():
    """A statistic of hand rotations about z only leaves the translation along z undetermined (issue
    25): a path turning about x gains more than a path of the same size turning about z again."""
    truth = make_truth(5)
    ident, _ = _eye_to_hand(truth, _about_axis([0.0, 0.0, 1.0], np.linspace(-1.0, 1.0, 40)))
    estimate = EyeToHandEstimate(truth.X_WC[:3, :3], truth.X_WC[:3, 3], truth.p_HP,
                                 pack_x(truth.X_WC[:3, :3], truth.X_WC[:3, 3], truth.p_HP), 0.0)
    paths = []
    for axis in ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0]):
        X = _about_axis(axis, np.linspace(-0.3, 0.3, 8), seed=2)
        paths.append((predicted_points(estimate, X), X, np.full(8, 10.0)))
    M, added = path_information(ident.state, paths)
    null = np.linalg.eigh(M)[1][:, 0]  # p_WC and p_HP moving together along z
    assert null @ M @ null < 1e-9 * np.trace(M)
    assert null @ added[0] @ null < 1e-9 * np.trace(added[0])  # the turn about z leaves it unknown
    assert null @ added[1] @ null > 1e-3 * np.trace(added[1])  # the turn about x determines it
    gains = information_gains(M, added)
    assert gains[1] > gains[0] + 5.0 > 5.0  # nats: the undetermined direction's worth
    assert best_candidate(M, added, [1.0, 1.0]) == 1


@pytest.mark.parametrize("path", [
    (np.zeros((2, 3)), np.tile(np.eye(4), (2, 1, 1)), np.array([1.0, -1.0])),  # a negative weight
    (np.zeros((3, 3)), np.tile(np.eye(4), (2, 1, 1)), np.ones(2)),  # points and poses disagree
    (np.zeros((2, 3)), np.tile(np.eye(3), (2, 1, 1)), np.ones(2)),  # not 4 x 4 poses
])
def test_path_information_refuses_bad_paths(path):
    with pytest.raises(IdentificationError):
        path_information(EyeToHandIdentifier().state, [path])
