"""``view_correlation``: how many independent samples a point's samples are worth when part of its
error repeats with its view (the one-way analysis of variance of its residuals over its views)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from eye_to_hand_data import make_truth
from scipy.spatial.transform import Rotation

from sustain_drake.identification import EyeToHandIdentifier
from sustain_drake.identification.candidates.fitting import S_of
from sustain_drake.identification.view_correlation import (
    MIN_VIEWS,
    independent_samples,
    repeated_share,
    view_row,
)

P_HP = np.array([0.05, 0.02, 0.12])  # m


def point_over_views(rho: float, views: int, held: int, seed: int, sigma: float = 1e-3):
    """One point seen from ``views`` hand poses, ``held`` samples each; each sample's error (per
    axis, ``sigma`` in all) a draw per view of variance ``rho sigma^2`` repeated over the view and a
    draw per sample of the rest. Returns ``(truth, S, view sums)``."""
    truth = make_truth(2)
    rng = np.random.default_rng(seed)
    R_CW, p_WC = truth.X_WC[:3, :3].T, truth.X_WC[:3, 3]
    identifier, rows = EyeToHandIdentifier(), []
    for q in Rotation.random(views, random_state=rng).as_matrix():
        p_WH = rng.uniform(-0.2, 0.2, 3) + [0.5, 0.0, 0.4]
        p_C = R_CW @ (q @ P_HP + p_WH - p_WC) + rng.normal(0.0, sigma * math.sqrt(rho), 3)
        row = np.zeros(16)
        for _ in range(held):
            sample = p_C + rng.normal(0.0, sigma * math.sqrt(1.0 - rho), 3)
            identifier.add(sample, q, p_WH)
            row += view_row(sample, q, p_WH)
        rows.append(row)
    return truth, S_of(identifier.state), np.array(rows)


def at_truth(truth, S, rows, function=independent_samples):
    return function(rows, S, truth.X_WC[:3, :3], truth.X_WC[:3, 3], P_HP)


@pytest.mark.parametrize("rho", [0.0, 0.3, 0.6, 0.9])
def test_the_repeated_share_is_recovered_from_the_residuals(rho):
    """Over 40 views of 20 samples the estimate lies within 0.12 of the share drawn (its sd is
    about 0.05 at these sizes), and the count follows Kish's ``n / (1 + (m - 1) rho)``."""
    truth, S, rows = point_over_views(rho, 40, 20, seed=int(rho * 10))
    share = at_truth(truth, S, rows, repeated_share)
    assert share == pytest.approx(rho, abs=0.12)
    assert at_truth(truth, S, rows) == pytest.approx(800.0 / (1.0 + 19.0 * share))


def test_independent_errors_count_as_their_samples_and_repeated_ones_as_their_views():
    truth, S, rows = point_over_views(0.0, 40, 20, seed=1)
    assert at_truth(truth, S, rows) > 0.6 * 800
    truth, S, rows = point_over_views(1.0, 40, 20, seed=2)
    assert 40.0 <= at_truth(truth, S, rows) <= 42.0  # every view one sample


def test_a_wrong_camera_makes_the_errors_follow_the_view_and_the_count_falls():
    """At a camera 5 mm and 0.3 deg off, the residuals of independent 1 mm errors repeat with the
    view: the analysis sees it, so a wrong camera cannot shrink its own region by its samples."""
    truth, S, rows = point_over_views(0.0, 40, 20, seed=3)
    R = truth.X_WC[:3, :3] @ Rotation.from_rotvec([0.0, 0.005, 0.0]).as_matrix()
    wrong = independent_samples(rows, S, R, truth.X_WC[:3, 3] + [0.005, 0.0, 0.0], P_HP)
    assert wrong < 0.25 * at_truth(truth, S, rows)


def test_too_few_views_count_as_one_sample_each():
    truth, S, rows = point_over_views(0.0, MIN_VIEWS - 1, 50, seed=4)
    assert at_truth(truth, S, rows, repeated_share) == 1.0
    assert at_truth(truth, S, rows) == pytest.approx(MIN_VIEWS - 1)


def test_noise_free_samples_count_in_full_and_nothing_is_never_zero_or_nan():
    truth, S, rows = point_over_views(0.0, 10, 5, seed=5, sigma=0.0)
    assert at_truth(truth, S, rows) == pytest.approx(50.0)
    empty = independent_samples(np.zeros((0, 16)), np.zeros((16, 16)), np.eye(3), np.zeros(3), np.zeros(3))
    assert empty == 1.0


def test_the_views_sums_are_the_samples_sums():
    """A view's row is linear in its samples: the sum over views of ``n_v`` is the statistic's
    sample count, and one view's residual sum is zero at the truth for noise-free samples."""
    truth, S, rows = point_over_views(0.5, 6, 7, seed=6)
    assert rows[:, 0].sum() == S[9, 9] == 42
    truth, S, rows = point_over_views(0.0, 6, 7, seed=6, sigma=0.0)
    assert at_truth(truth, S, rows, repeated_share) == 0.0
