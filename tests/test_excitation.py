"""Motion that excites what is unknown (issue 25): the D-optimal gain per second, the static
payload's posture information, and a greedy choice that identifies a payload in two rests."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sustain_drake.identification import PayloadIdentifier
from sustain_drake.identification.excitation import best_candidate, information_gains
from sustain_drake.identification.payload import STANDARD_GRAVITY_W, posture_information
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
