"""Per-feature confirmation: a feature is on the body after its own flow rises from 0 in two
confirming trials of its cell; features already moving, outside the tested cells or outside the
response window do not count; lost tracks are forgotten."""

import numpy as np
import pytest

from sustain_drake.perception.body_features import (
    FeatureMemory,
    FeatureParams,
    features_on_body,
    update_feature_memory,
)
from sustain_drake.perception.coincidence import CoincidenceState

DT = 1.0 / 30.0


def trial_state(trial_count, t0, cells=(0,), n_c=4, window=0.3):
    s = CoincidenceState(1, n_c)
    s.trial_count = np.float64(trial_count)
    s.trial_t0 = np.float64(t0)
    s.trial_until = np.float64(t0 + window)
    s.trial_cells[list(cells)] = 1.0
    return s


def run(mem, state, t0, t1, ids, cell, flow_at, arm_moving=True):
    """Step from t0 to t1; ``flow_at(t)`` gives the per-feature flow magnitude (px/frame); the
    arm moves all along unless ``arm_moving`` is False."""
    for k in range(int(round((t1 - t0) / DT))):
        t = t0 + (k + 1) * DT
        if arm_moving:
            state.last_motion_a[:] = t
        mags = np.asarray(flow_at(t), float)
        mem = update_feature_memory(mem, state, t, ids, cell, np.stack([mags, 0 * mags], 1))
    return mem


def test_two_trial_onsets_make_a_feature_body_and_nothing_else_does():
    ids = np.array([7, 3, 9, 5])              # unsorted on purpose
    cell = np.array([0, 0, 0, 2])             # feature 5 is outside the tested cell
    mem = FeatureMemory()

    def flows(t0):
        def at(t):
            # 7: rises 0.1 s after the trial onset; 3: moving all along (a walking person);
            # 9: rises 0.5 s after (outside the window); 5: rises at once, wrong cell.
            return [0.5 * (t > t0 + 0.1), 0.5, 0.5 * (t > t0 + 0.5), 0.5 * (t > t0)]
        return at

    for trial, t0 in ((1, 1.0), (2, 3.0)):
        state = trial_state(trial, t0)
        mem = run(mem, state, t0 - 0.5, t0 + 1.0, ids, cell, flows(t0))
        # between trials, everything rests for a while
        mem = run(mem, trial_state(trial, t0), t0 + 1.0, t0 + 1.5, ids, cell, lambda t: [0] * 4,
                  arm_moving=False)
    on = features_on_body(mem, ids)
    assert on.tolist() == [True, False, False, False]
    assert features_on_body(mem, np.array([3, 7])).tolist() == [False, True]


def test_one_hit_per_trial_and_lost_tracks_are_forgotten():
    ids = np.array([1, 2])
    cell = np.array([0, 0])
    mem = FeatureMemory()
    state = trial_state(1, 1.0)

    def stop_and_go(t):                       # two onsets inside one trial's window
        return [0.5 * ((1.03 < t < 1.1) or (t > 1.25)), 0.0]

    mem = run(mem, state, 0.5, 1.5, ids, cell, stop_and_go)
    assert mem.hits.tolist() == [1.0, 0.0]
    mem = update_feature_memory(mem, state, 1.6, np.array([2]), np.array([0]), np.zeros((1, 2)))
    assert mem.ids.tolist() == [2]
    assert not features_on_body(mem, np.array([1])).any()


def test_memory_copy_is_deep_and_bad_inputs_raise():
    mem = update_feature_memory(FeatureMemory(), trial_state(1, 0.0), 0.1, np.array([4]),
                                np.array([0]), np.ones((1, 2)))
    c = mem.copy()
    c.hits[:] = 9
    assert mem.hits[0] != 9
    with pytest.raises(ValueError, match="disagree"):
        update_feature_memory(mem, trial_state(1, 0.0), 0.2, np.array([4, 5]), np.array([0]),
                              np.ones((1, 2)))
    with pytest.raises(ValueError, match="grids differ"):
        update_feature_memory(mem, trial_state(1, 0.0), 0.2, np.array([4]), np.array([10]),
                              np.ones((1, 2)))
    with pytest.raises(ValueError, match="invalid feature parameters"):
        FeatureParams(hits=0)


def test_a_feature_seeded_while_moving_has_no_onset():
    """A corner seeded on a walking person inside a tested cell, moving from its first tracked
    frame, never "rises up from 0": no hit, whatever the trial."""
    state = trial_state(1, 1.0)
    mem = FeatureMemory()
    ids, cell = np.array([11, 12]), np.array([0, 0])
    # 11 appears at 1.05 s already moving; 12 appears at 0.5 s at rest and rises at 1.1 s.
    mem = update_feature_memory(mem, state, 0.5, ids[1:], cell[1:], np.zeros((1, 2)))
    mem = run(mem, state, 0.5, 1.0, ids[1:], cell[1:], lambda t: [0.0])
    mem = run(mem, state, 1.0, 1.4, ids, cell, lambda t: [0.5, 0.5 * (t > 1.1)])
    assert mem.hits.tolist() == [0.0, 1.0]


def test_a_body_feature_moving_while_the_arm_is_still_loses_its_hits():
    """Eq. (26) per feature: a confirmed track that moves while every actuator has been still
    for 0.3 s (it slid off the arm onto a passing person) is no longer body."""
    mem = FeatureMemory(np.array([1, 2]), np.full(2, -1.0), np.array([2.0, 2.0]),
                        np.array([2.0, 2.0]))
    state = trial_state(2, 0.0)
    state.last_motion_a[:] = 1.0                     # the arm stopped at 1.0 s
    mem = run(mem, state, 1.0, 1.2, np.array([1, 2]), np.array([0, 0]),
              lambda t: [0.5, 0.0], arm_moving=False)
    assert features_on_body(mem, np.array([1, 2])).tolist() == [True, True]   # within 0.3 s
    mem = run(mem, state, 1.2, 1.5, np.array([1, 2]), np.array([0, 0]),
              lambda t: [0.5, 0.0], arm_moving=False)
    assert features_on_body(mem, np.array([1, 2])).tolist() == [False, True]


def test_one_hit_setting_confirms_after_one_trial_and_still_time_motion_revokes_it():
    # diagrams/body_detection.yaml uses feature_hits: 1. Its safety net is Eq. (26): a feature
    # that moves while every actuator has been still loses its hit (a track gone onto a person).
    one = FeatureParams(hits=1)
    ids, cell = np.array([1, 2]), np.array([0, 0])
    state = trial_state(1, 1.0)
    rises = lambda t: [0.5 * (t > 1.1), 0.0]  # noqa: E731 - feature 1 answers the trial
    mem = run(FeatureMemory(), state, 0.5, 1.5, ids, cell, rises)
    assert features_on_body(mem, ids, one).tolist() == [True, False]
    assert features_on_body(mem, ids).tolist() == [False, False]  # default: two trials
    # The arm stops; 0.5 s later feature 1 moves by itself: no longer body.
    state.last_motion_a[:] = 1.5
    mem = run(mem, state, 1.5, 2.0, ids, cell, lambda t: [0.0, 0.0], arm_moving=False)
    assert features_on_body(mem, ids, one).tolist() == [True, False]
    mem = run(mem, state, 2.0, 2.2, ids, cell, lambda t: [0.5, 0.0], arm_moving=False)
    assert features_on_body(mem, ids, one).tolist() == [False, False]
