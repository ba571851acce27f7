"""Eq. (27) on hand-made signals, the state's flat-vector round trip, and the body rule on a
long synthetic run with a busy self-moving distractor."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sustain_drake.perception.coincidence import (
    NEVER,
    CoincidenceParams,
    CoincidenceState,
    causal_and,
    onset,
    rho,
    step,
)
from sustain_drake.perception.synthetic import SyntheticWorld, run

DT = 1.0 / 30.0


def drive(actuator_moving, visual_moving, params=None):
    """Run the detector on boolean per-sample signals (T x n_a, T x n_c); returns the states."""
    a_mov = np.atleast_2d(np.asarray(actuator_moving, float))
    s_mov = np.atleast_2d(np.asarray(visual_moving, float))
    state = CoincidenceState(a_mov.shape[1], s_mov.shape[1])
    q = np.zeros(a_mov.shape[1])
    states = []
    for k in range(a_mov.shape[0]):
        q = q + 0.5 * DT * a_mov[k]           # 0.5 rad/s while moving
        state = step(state, (k + 1) * DT, q, 50.0 * s_mov[k],
                     CoincidenceParams() if params is None else params)
        states.append(state)
    return states


def signal(n, *intervals):
    """Boolean signal of n samples, 1 on [start, stop) sample intervals."""
    x = np.zeros(n, bool)
    for start, stop in intervals:
        x[start:stop] = True
    return x


def test_rho_and_onset_are_the_paper_definitions():
    assert onset(np.array([True, True, False]), np.array([NEVER, 0.95, NEVER]), 1.0, 0.1).tolist() \
        == [True, False, False]
    assert rho(1.0, np.array([0.8, 0.6, NEVER, 1.0]), 0.3).tolist() == [True, False, False, True]


def test_causal_and_needs_the_actuator_first():
    t_a = np.array([1.0])
    # actuator 0.1 s before the cell: fires; cell 0.1 s before the actuator: does not;
    # same instant: fires (same sample interval); actuator onset 0.4 s old: outside τ_a.
    t_s = np.array([1.1, 0.9, 1.0])
    assert causal_and(1.15, t_a, 0.3, t_s, 0.3).tolist() == [[True, False, True]]
    assert not causal_and(1.4, t_a, 0.3, np.array([1.35]), 0.3).any()


def test_actuator_then_visual_increments_once_per_pair():
    n = 90
    act = signal(n, (30, 60))                 # onset at sample 30
    vis = signal(n, (33, 60))                 # visual 0.1 s later, stays on
    states = drive(act[:, None], vis[:, None])
    assert states[-1].eps[0, 0] == 1          # once, although both stay on for 0.9 s
    assert states[32].eps[0, 0] == 0 and states[33].eps[0, 0] == 1


def test_visual_then_actuator_does_not_increment():
    n = 90
    states = drive(signal(n, (33, 60))[:, None], signal(n, (30, 60))[:, None])
    assert states[-1].eps.sum() == 0


def test_visual_outside_the_window_does_not_increment():
    n = 90
    # actuator onset at 30 (1.033 s), visual onset 12 samples = 0.4 s later > τ_a = 0.3 s.
    states = drive(signal(n, (30, 80))[:, None], signal(n, (42, 80))[:, None])
    assert states[-1].eps.sum() == 0


def test_each_new_pair_of_onsets_increments_again():
    n = 150
    act = signal(n, (30, 45), (90, 105))      # two actuator onsets, quiet in between
    vis = signal(n, (32, 47), (92, 107))
    other = signal(n, (60, 75))               # a cell moving only while the robot is still
    states = drive(act[:, None], np.stack([vis, other], axis=1))
    assert states[-1].eps.tolist() == [[2, 0]]


def test_a_one_sample_dropout_is_not_a_new_onset():
    n = 90
    vis = signal(n, (32, 50), (51, 70))       # one sample of 0 (a dropped frame) in the motion
    states = drive(signal(n, (30, 70))[:, None], vis[:, None])
    assert states[-1].eps[0, 0] == 1
    assert states[-1].t_onset_s[0] == pytest.approx(33 * DT)


def test_state_vector_round_trip_and_copy_are_deep():
    states = drive(signal(60, (10, 30))[:, None], signal(60, (12, 30))[:, None])
    s = states[-1]
    v = s.to_vector()
    assert v.shape == (CoincidenceState.size(1, 1),)
    assert np.array_equal(CoincidenceState.from_vector(v, 1, 1).to_vector(), v)
    c = s.copy()
    c.eps[0, 0] += 5
    assert s.eps[0, 0] == 1
    assert np.isfinite(v).all()
    with pytest.raises(ValueError, match="state vector"):
        CoincidenceState.from_vector(v[:-1], 1, 1)


def test_from_vector_gives_every_field_its_shape_and_own_memory():
    fresh = CoincidenceState(3, 5)
    v = np.arange(CoincidenceState.size(3, 5), dtype=float)
    s = CoincidenceState.from_vector(v, 3, 5)
    for name in CoincidenceState.__slots__[2:]:
        assert getattr(s, name).shape == getattr(fresh, name).shape, name
        assert not np.shares_memory(getattr(s, name), v)
    assert (s.n_a, s.n_c) == (3, 5) and np.array_equal(s.to_vector(), v)


def test_bad_inputs_raise_one_line_value_errors():
    s = step(CoincidenceState(2, 3), 0.1, np.zeros(2), np.zeros(3))
    with pytest.raises(ValueError, match="finite"):
        step(s, 0.2, np.array([0.0, np.nan]), np.zeros(3))
    with pytest.raises(ValueError, match="expected 2 actuator values"):
        step(s, 0.2, np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="time must increase"):
        step(s, 0.1, np.zeros(2), np.zeros(3))
    with pytest.raises(ValueError, match="tau_a"):
        CoincidenceParams(tau_a=0.0)


def test_increment_raises_a_confirming_request_at_the_onset_posture():
    n = 60
    states = drive(signal(n, (30, 60))[:, None], signal(n, (32, 60))[:, None])
    s = states[-1]
    assert s.request_active == 1 and s.request_count == 1
    # posture at the actuator onset: the value before it moved (29 samples of rest at 0)
    assert s.q_request[0] == pytest.approx(0.0)
    assert s.candidates.tolist() == [1.0]
    p = CoincidenceParams()
    assert p.hold_min <= s.hold_time(p) <= p.hold_min + p.hold_spread
    assert not s.body(p)[0]                   # a coincidence alone is not body
    assert s.request_joint == -1              # move all joints again, by default
    single = drive(signal(n, (30, 60))[:, None], signal(n, (32, 60))[:, None],
                   CoincidenceParams(single_joint_confirm=True))[-1]
    assert single.request_joint == 0


def test_confirming_hits_make_body_and_a_miss_takes_evidence_away():
    """Scripted confirmations: each 1.5 s cycle rests at q* = 0, moves out for 0.33 s, holds,
    and jumps back to q* (the jump starts far from q*, so it is not a trial)."""
    p = CoincidenceParams()
    n_cycle, n_cycles = 45, 5
    state = CoincidenceState(1, 2)
    evidence_after_miss = None
    for k in range(n_cycle * n_cycles):
        phase, cycle = k % n_cycle, k // n_cycle
        q = 0.5 * DT * (np.clip(phase, 15, 25) - 15) if phase < 40 else 0.0
        body_moves = 16 <= phase < 27                  # one frame after the actuator
        chance = cycle == 0 and 16 <= phase < 22       # coincides once, with the body cell
        state = step(state, (k + 1) * DT, np.array([q]), 50.0 * np.array([body_moves, chance]), p)
        if k == 2 * n_cycle:
            evidence_after_miss = state.evidence[1]
    assert state.body(p).tolist() == [True, False]
    assert state.hits[0, 0] >= 2 and state.misses[0, 0] == 0
    assert state.misses[0, 1] == 1 and evidence_after_miss < 0
    assert state.moves(p).tolist() == [[True, False]]


def test_busy_distractor_never_becomes_body_while_driven_cells_do():
    """Whole pipeline on synthetic per-cell signals: 8 cells with self-caused visual onsets
    at ~0.5/s and a robot moving at random, honouring confirming requests."""
    world = SyntheticWorld()
    body_cells = sorted(world.body_drivers)
    for seed in (0, 1, 2):
        state, times, masks, _ = run(world, 90.0, seed)
        ever = masks.any(axis=0)
        assert not ever[list(world.distractor_cells)].any(), seed
        assert ever[body_cells].all(), seed
        assert not ever[[j for j in range(world.n_c) if j not in body_cells
                         and j not in world.distractor_cells]].any()
        # counting alone (the paper's Σ_i ε_ij > 0) would have let the distractor through
        assert (state.eps[:, list(world.distractor_cells)].sum(axis=0) > 0).any()


def test_without_confirming_motions_nothing_is_body():
    state, _, masks, _ = run(SyntheticWorld(), 30.0, 0, honour_requests=False)
    assert not masks.any()
    assert state.eps.sum() > 0


def test_chance_probability_uses_the_prior_rate_and_the_trial_window():
    s = CoincidenceState(1, 1)
    assert s.chance_probability(CoincidenceParams())[0] == pytest.approx(1 - np.exp(-0.5 * 0.3))
    short = CoincidenceParams(response_window=0.1)
    assert s.chance_probability(short)[0] == pytest.approx(1 - np.exp(-0.5 * 0.1))
    with pytest.raises(ValueError, match="response_window"):
        CoincidenceParams(response_window=0.5)


def test_visual_onsets_while_the_robot_is_still_are_counter_evidence():
    n = 300                                   # 10 s, the robot never moves
    busy = np.zeros(n, bool)
    for start in range(10, n, 60):            # onsets every 2 s
        busy[start:start + 8] = True
    states = drive(np.zeros((n, 1), bool), np.stack([busy, np.zeros(n, bool)], axis=1))
    s, p = states[-1], CoincidenceParams()
    assert s.unexplained[0] == pytest.approx(5, rel=0.2) and s.unexplained[1] == 0
    assert s.still_evidence(p)[0] < -3 < 0 < s.still_evidence(p)[1]
    assert s.chance_probability(p)[1] < 0.05 < s.chance_probability(p)[0]


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.booleans(), st.booleans()), min_size=2, max_size=90))
def test_eq27_count_matches_a_brute_force_reference(samples):
    """ε_ij equals the number of visual onsets whose latest actuator onset is at most τ earlier
    (onset: moving now, not at the previous sample; τ_a = τ_s)."""
    act = np.array([False] + [a for a, _, _ in samples])
    vis = np.array([[False, False]] + [[v, w] for _, v, w in samples])
    params = CoincidenceParams(tau_a=0.31, tau_s=0.31, quiet_a=0.05, quiet_s=0.05)
    eps = drive(act[:, None], vis, params)[-1].eps[0]

    def onsets(x):
        return [k for k in range(1, x.size) if x[k] and not x[k - 1]]

    a_on = onsets(act)
    for j in range(2):
        expected = 0
        for k in onsets(vis[:, j]):
            earlier = [m for m in a_on if m <= k]
            expected += bool(earlier) and (k - earlier[-1]) * DT <= 0.31
        assert eps[j] == expected


def test_a_trial_is_a_new_move_from_rest_not_a_late_joint_of_the_same_move():
    """Joint 0 starts at sample 30 and its cell responds: a request at q* = 0. Joint 1 starts
    3 samples later from the same posture while joint 0 still moves: no trial. After a rest,
    a move from q* starts one."""
    n = 120
    a0 = signal(n, (30, 50), (90, 100))
    a1 = signal(n, (33, 50))
    states = drive(np.stack([a0, a1], axis=1), signal(n, (31, 50))[:, None])
    s_late = states[40]
    assert s_late.request_count == 1 and s_late.trial_count == 0
    assert s_late.q_request.tolist() == [0.0, 0.0]
    # Joint 0 moved 20 samples at 0.5 rad/s (0.33 rad) away from q*: its move from there at
    # sample 90 starts far from q*, still no trial; a rest at q* and a move from it would.
    assert states[-1].trial_count == 0
    back = drive(np.stack([signal(n, (30, 50), (90, 100)), signal(n, (33, 50))], axis=1),
                 signal(n, (31, 50), (91, 100))[:, None],
                 CoincidenceParams(posture_tolerance=0.4))
    assert back[-1].trial_count == 1 and back[-1].hits[0, 0] == 1


def test_known_body_cells_and_the_request_interval_hold_requests_back():
    """A coincidence in a cell known to hold the body (a confirmed body feature) raises no
    request; after a request ends, a new one waits request_interval."""
    n = 60
    act, vis = signal(n, (30, 60)), signal(n, (32, 60))

    def run_steps(params, known):
        state = CoincidenceState(1, 1)
        q = 0.0
        for k in range(n):
            q += 0.5 * DT * act[k]
            state = step(state, (k + 1) * DT, np.array([q]), 50.0 * np.array([vis[k]]),
                         params, known)
        return state

    p = CoincidenceParams()
    assert run_steps(p, np.array([False])).request_count == 1
    assert run_steps(p, np.array([True])).request_count == 0
    assert run_steps(p, None).request_count == 1
    waiting = CoincidenceState(1, 1)
    waiting.request_end = np.float64(0.9)      # a request ended just before the coincidence
    q, state = 0.0, waiting
    for k in range(n):
        q += 0.5 * DT * act[k]
        state = step(state, (k + 1) * DT, np.array([q]), 50.0 * np.array([vis[k]]),
                     CoincidenceParams(request_interval=2.0))
    assert state.request_count == 0 and state.eps[0, 0] == 1   # counted, but no request
    with pytest.raises(ValueError, match="known_body"):
        step(CoincidenceState(1, 2), 0.1, np.zeros(1), np.zeros(2), p, np.ones(3, bool))


def test_chance_rate_counts_onsets_outside_actuator_windows_while_the_arm_moves():
    """A cell with onsets every 0.5 s while the arm moves on and on (never still, so λ_j keeps
    its prior) gets a chance rate near 2/s from the onsets outside actuator windows."""
    n = 600
    act = np.zeros(n, bool)
    act[5:] = True                             # one onset at the start, then moving all along
    vis = np.zeros(n, bool)
    for start in range(40, n, 15):
        vis[start:start + 5] = True
    s, p = drive(act[:, None], vis[:, None])[-1], CoincidenceParams()
    assert s.spontaneous_rate(p)[0] == pytest.approx(0.5, rel=0.05)  # ~ the prior: never still
    assert s.chance_rate(p)[0] == pytest.approx(3.0, rel=0.25)   # onsets / quiet-cell time
    assert s.chance_probability(p)[0] > 0.5


def test_cells_of_the_same_move_seen_later_join_the_first_request():
    """The move that raises a request (joint onset at sample 30, cell 0 at 31) shows cell 1 a
    little later (sample 36, within τ_a): cell 1 joins the candidates before the trial."""
    n = 45
    states = drive(signal(n, (30, 45))[:, None],
                   np.stack([signal(n, (31, 45)), signal(n, (36, 45))], axis=1))
    assert states[33].candidates.tolist() == [1.0, 0.0]
    assert states[-1].candidates.tolist() == [1.0, 1.0] and states[-1].request_count == 1
    assert states[-1].cand_act.tolist() == [[1.0, 1.0]]


def _scripted_cycles(params, n_cycles=6):
    """1.5 s cycles: rest at q* = 0, move out for 0.33 s (the body cell responds one frame
    later), hold, jump back to q* (far from q*: not a trial). Returns the final state."""
    n_cycle = 45
    state = CoincidenceState(1, 1)
    for k in range(n_cycle * n_cycles):
        phase = k % n_cycle
        q = 0.5 * DT * (np.clip(phase, 15, 25) - 15) if phase < 40 else 0.0
        state = step(state, (k + 1) * DT, np.array([q]), 50.0 * np.array([16 <= phase < 27]),
                     params)
    return state


def test_max_sequence_trials_ends_a_chain_of_follow_ups():
    # A cell that needs many hits (alpha tiny): without a limit every cycle after the first is
    # a trial of one chain of follow-ups; with a limit of 2, the chain ends after two trials
    # and the next coincidence starts a new one (its move is no trial: one cycle is lost).
    slow = dict(alpha=1e-12)
    free = _scripted_cycles(CoincidenceParams(**slow))
    limited = _scripted_cycles(CoincidenceParams(max_sequence_trials=2, **slow))
    assert free.trial_count == 5 and free.request_count == 6
    assert limited.trial_count == 4 and limited.request_count == 4   # cycles 1, 2 | 3: new | 4, 5
    assert limited.sequence_trials <= 2
    with pytest.raises(ValueError, match="max_sequence_trials"):
        CoincidenceParams(max_sequence_trials=-1)


def test_stop_requests_test_the_cells_the_arm_swept_into_where_it_stops():
    """The arm moves on samples 30-60; a cell starts moving mid-move (sample 45, no actuator
    onset within τ_a before it: no coincidence) and stops with the arm. With stop_requests, a
    request is raised once the arm has been still for quiet_a, at the posture where it rests."""
    n = 75
    act, vis = signal(n, (30, 60))[:, None], signal(n, (45, 61))[:, None]
    plain = drive(act, vis)[-1]
    assert plain.eps.sum() == 0 and plain.request_count == 0
    states = drive(act, vis, CoincidenceParams(stop_requests=True))
    s = states[-1]
    assert s.request_count == 1 and s.candidates.tolist() == [1.0]
    assert s.q_request[0] == pytest.approx(30 * 0.5 * DT)       # where the arm rests
    first = next(k for k, st in enumerate(states) if st.request_count)
    assert 60 + 2 <= first <= 60 + 4                             # quiet_a (0.1 s) after the stop


def test_skip_busy_cells_does_not_count_a_miss_for_a_cell_that_could_not_respond():
    """Both cells respond to the move at sample 30 (one request, two candidates). At the trial
    (a move at sample 60 from rest, near q*), cell 0 responds again but cell 1 has been moving
    since sample 50 (a person walking through it): it cannot have an onset."""
    n = 85                                     # the trial lasts 2 w = 0.6 s (18 samples)
    act = signal(n, (30, 40), (60, 70))[:, None]
    vis = np.stack([signal(n, (31, 40), (61, 70)), signal(n, (31, 40), (50, 85))], axis=1)
    loose = dict(posture_tolerance=0.5)
    plain = drive(act, vis, CoincidenceParams(**loose))[-1]
    assert plain.trial_count == 1 and plain.misses[0].tolist() == [0.0, 1.0]
    skip = drive(act, vis, CoincidenceParams(skip_busy_cells=True, **loose))[-1]
    assert skip.trial_count == 1 and skip.misses[0].tolist() == [0.0, 0.0]
    assert skip.hits[0].tolist() == [1.0, 0.0] and skip.evidence[1] == 0.0
    # The follow-up tests cell 1 again (and cell 0, which hit).
    assert skip.request_active == 1 and skip.candidates.tolist() == [1.0, 1.0]
