r"""Body detection by motion coincidence (paper §3.3.2, Eq. (27)) and the rule that keeps a
self-moving distractor out of the body.

Pure numpy, no pydrake import; ``sustain_drake.systems.motion_coincidence_detector`` wraps it.

Notation (paper): actuator ``i`` with value ``a_i`` (a joint encoder, rad), grid cell ``j`` with
visual change ``ṡ_j`` (sum of optical-flow norms in the cell, px/s), likelihood ``ε_ij`` that cell
``j`` is moved by actuator ``i``.

Eq. (27), implemented by :func:`causal_and` and counted by :func:`step`::

    Δε_ij = ρ_a(ȧ_i) ∩ ρ_s(ṡ_j)

- ``ρ_a`` is 1 while the last onset of actuator ``i`` (its change "rising up from 0": moving
  now after at least ``quiet_a`` s without motion) is at most ``τ_a`` old; ``ρ_s`` likewise for
  the cell with ``τ_s`` (:func:`rho`).
- ``∩`` is 1 when both are 1 and the actuator's remaining time ``τ_a - (t - t_a)`` is not longer
  than the cell's ``τ_s - (t - t_s)``: the actuator's onset came first (visual motion right after
  body motion, the causal order). Onsets seen in the same sample count as actuator first, since
  the encoder difference and the image pair span the same interval.
- ``ε_ij`` increments once per coincident pair of onsets (the pair is remembered).

**The body rule (ours; the paper marks a cell as soon as Σ_i ε_ij > 0).** Counting
coincidences lets a busy distractor through: a cell with visual onsets at 0.5/s falls in a 300 ms
window after an actuator onset ~14 % of the time. So ``ε`` stays the paper's likelihood map, and a
cell is marked *body* only by a sequential likelihood-ratio test between "the cell moves because
of the robot" (it responds to an actuator onset with probability ``p_response``) and "the cell
moves by itself" (it falls in the window by chance with probability ``p0_j``). Its evidence is
``L_j = C_j + S_j``:

1. *Counter-evidence: visual onsets with no actuator onset before them* (``S_j``). While every
   actuator has been still for ``τ_a`` (Eq. (26): no body motion ⇒ no body motion in view), a
   visual onset in cell ``j`` cannot be the robot. Such onsets ``u_j`` are counted with the still
   time ``T_j`` during which the cell was quiet (both forgotten with time constant ``memory``).
   The cell's spontaneous onset rate is ``λ_j = (u_j + prior_onsets) / (T_j + prior_time)``
   (prior: 0.5/s, the busy distractor, until the cell has been watched), and
   ``S_j = u_j ln(λ_b / λ_j) - (λ_b - λ_j) T_j``, the Poisson log-likelihood ratio of a body cell
   (rate ``λ_b = body_onset_rate``, noise) against the cell's own rate: a cell that moves while
   the robot is still loses evidence at once.
2. *Confirming motions (paper §3.3.2, §4.2).* When ``ε_ij`` increments for a cell not yet body and
   no request is pending, the detector requests one: go back to the posture ``q*`` at the onset of
   the actuator motion, hold still (``hold_time``, varied per request so trials never phase-lock
   with a periodic distractor such as a walking person), and move again (every joint, or with
   ``single_joint_confirm`` only the most proximal candidate actuator ``request_joint``). The
   coincidence that raised the request is *not* evidence: it was selected because it
   coincided. A new request waits ``request_interval`` after the last one ended, so the arm
   babbles (and shows more of the image) between confirmations.
3. *Trial* (``C_j``). The first actuator onset within ``posture_tolerance`` of ``q*`` after the
   request, with the whole arm at rest for ``quiet_a`` before it (a new move, not a late
   onset of another joint in the move that raised the request), starts a trial. A candidate
   cell whose visual onset coincides (Eq. (27)) with an actuator onset of the trial, at most
   ``w = response_window`` (default ``τ_s``) after it, is a *hit*:
   ``C_j += ln(p_response / p0_j)`` with ``p0_j = 1 - exp(-λ0_j w)``. ``λ0_j`` is the cell's
   rate of onsets with no actuator onset within ``w`` before them, robot still or not (and at
   least ``λ_j``): a walking person's cell shows its rate while the arm babbles, whereas the
   arm is rarely still long enough to measure ``λ_j``. A candidate cell with no visual
   response although one of its candidate actuators moved again is a *miss* -- the
   counter-evidence *actuator onsets with no visual response*, counted only here, at the same
   posture, where Eq. (26) says a body cell must respond: ``C_j += ln((1-p_response)/(1-p0_j))``.
   The trial ends when every candidate has hit, or after ``2 w``. Cells that hit and are
   not yet body are tested again at once at the same posture. A request with no trial within
   ``confirm_timeout`` expires without evidence. ``C_j`` is floored at ``ln(beta)`` so that a cell
   that held a distractor can still become body later (the arm may move into it).
4. Cell ``j`` is **body** while ``L_j >= ln(1/alpha)``.

*Quick trials (detection latency).* The time to detect a cell is paid in trials, and a trial
costs a return to ``q*``, a hold and the response. Three things make trials follow each other
every ~0.45 s (measured per cell on ``diagrams/body_detection.yaml``: with a return and a full
babbling move per trial, trials came every ~1 s and the cells the arm covers at its first
move were marked 1.5-2 s after their first motion):

- the motion generator answers a request whose ``q*`` is close to where the arm is *in
  place* (it brakes, rests, and moves again by a short step of every joint, out the way it was
  moving and back; ``MotionGenerator`` ``confirm_near``, ``confirm_step``), so a trial needs
  no return, and ``posture_tolerance`` admits the steps' postures;
- pairs of the move that raised a request (its actuator onsets up to the request) that
  coincide while the request waits for its trial join its candidates: slower cells and
  joints of the same move are tested in the same trial instead of waiting for a request of
  their own. Follow-up requests take only the cells that hit (the trial steps' onsets would
  let every busy cell in);
- with ``stop_requests``, a request is also raised where the arm comes to rest (after a
  babbling move), for the cells that moved during the last ``tau_s`` of its motion: the cells
  the arm swept into mid-move had no onset coinciding with an actuator onset, so without it
  they wait for the next move's start (after the rest) to raise a request;
- with ``skip_busy_cells``, a candidate that is moving when the trial starts (a person walking
  through it) is not tested by that trial: it cannot have an onset, so a miss would be
  counter-evidence against a body cell that could not respond; it is tested again by the
  follow-up. The choice is made at the trial's start, from the past, like the candidates;
- ``max_sequence_trials`` ends a chain of follow-ups at one posture (a cell that hits about
  as often as it misses, e.g. one the steps move the arm in and out of, would hold the arm
  there forever), so the arm babbles on and shows the rest of the image.

None of this changes the test: a trial's onset time is set by the robot (its hold), and its
candidates are chosen before that onset, from the past only, so under "the cell moves by
itself" the likelihood ratio of each trial still has expectation 1 given the past, and
``L_j`` stays a supermartingale (a martingale but for the floor ``ln(beta)``, from which a
new run up to ``ln(1/alpha)`` has probability at most ``alpha beta``). What can break it is
the same as before: ``p0_j`` underestimated, e.g. a cell that was quiet until the person
walked in (its rate was measured before); more trials per minute give such a cell more
chances, so the chain limit and the follow-ups-only-for-hits rule also bound the exposure.

Under "the cell moves by itself" each trial's likelihood ratio has expectation 1, so a distractor
cell is marked with probability about ``alpha`` (more if ``λ_j`` is underestimated). With the
defaults (``p_response`` = 0.9, ``alpha`` = 1e-3, ``w`` = 0.3 s) a cell needs four confirming
hits while its rate is the prior, two once it has been watched quiet (robot still) for ~10 s;
the busy distractor (p0 ≈ 0.14) needs about four hits more than its misses take away.

The state is a :class:`CoincidenceState` of plain numpy arrays with an exact flat-vector
round trip (:meth:`CoincidenceState.to_vector`, :meth:`CoincidenceState.from_vector`), so a Drake
system can keep it as discrete state.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

NEVER = -1.0e9
"""Time (s) stored for "no onset yet": far in the past, finite so the state never holds inf."""


@dataclass(frozen=True)
class CoincidenceParams:
    """Parameters of Eq. (27) and of the body rule (see the module docstring)."""

    tau_a: float = 0.3                 # τ_a, s: window of the actuator onset detector ρ_a
    tau_s: float = 0.3                 # τ_s, s: window of the visual onset detector ρ_s
    adot_threshold: float = 0.01       # rad/s: |ȧ_i| above this is actuator motion
    sdot_threshold: float = 1.0        # px/s: ṡ_j above this is visual motion
    quiet_a: float = 0.1               # s without motion before an actuator change "rises from 0"
    quiet_s: float = 0.1               # s without motion before a visual change "rises from 0"
    #                                    (a dropped frame, one sample of 0, is not a new onset)
    p_response: float = 0.9            # P(body cell responds to its actuator's onset)
    prior_onsets: float = 1.0          # prior spontaneous onsets ...
    prior_time: float = 2.0            # ... in this prior still time: 0.5/s, the busy distractor
    body_onset_rate: float = 0.02      # 1/s: spontaneous onsets of a body cell while still (noise)
    memory: float = 30.0               # s: time constant forgetting unexplained onsets/still time
    hold_min: float = 0.25             # s: shortest requested hold at q* before moving again
    hold_spread: float = 0.35          # s: hold varies in [hold_min, hold_min + hold_spread]
    alpha: float = 1e-3                # body when L_j >= ln(1/alpha)
    beta: float = 1e-2                 # L_j floored at ln(beta)
    posture_tolerance: float = 0.05    # rad, max-norm: a confirming trial starts near q*
    confirm_timeout: float = 5.0       # s: an unanswered confirming request expires
    single_joint_confirm: bool = False  # confirm by moving only the most proximal candidate
    #                                    actuator (lowest index) instead of all joints
    request_interval: float = 0.0      # s: a new coincidence raises a request only this long
    #                                    after the last request ended (follow-ups at once), so
    #                                    the babbling explores between confirmations
    skip_busy_cells: bool = False      # a candidate moving when its trial starts (so it cannot
    #                                    have an onset) is not tested: no hit, no miss; it stays
    #                                    a candidate of the follow-up
    stop_requests: bool = False        # also request a confirmation where the arm stops, for
    #                                    the cells that moved during the last tau_s of its motion
    max_sequence_trials: int = 0       # trials in one sequence of follow-ups at a posture, after
    #                                    which the arm babbles on (0: no limit); a cell that
    #                                    hits about as often as it misses would hold it forever
    response_window: float | None = None  # s: a trial hit's visual onset must follow the
    #                                    actuator onset within this; None: τ_s. A window as
    #                                    short as the real sensor latency makes p0_j smaller.

    def __post_init__(self):
        positive = ("tau_a", "tau_s", "p_response", "prior_onsets", "prior_time", "alpha",
                    "beta", "posture_tolerance", "confirm_timeout", "body_onset_rate", "memory",
                    "hold_min")
        for name in positive:
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and positive, got {value}")
        for name in ("adot_threshold", "sdot_threshold", "quiet_a", "quiet_s", "hold_spread",
                     "request_interval", "max_sequence_trials"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if self.response_window is not None and not (
                np.isfinite(self.response_window) and 0 < self.response_window <= self.tau_a):
            raise ValueError(f"response_window must be in (0, tau_a], got {self.response_window}")
        if not (self.p_response < 1 and self.alpha < 1 and self.beta < 1):
            raise ValueError("p_response, alpha and beta must be below 1")

    @property
    def body_threshold(self) -> float:
        return float(np.log(1.0 / self.alpha))

    @property
    def trial_window(self) -> float:
        """Window (s) within which a trial's visual onset must follow its actuator onset."""
        return self.tau_s if self.response_window is None else self.response_window

    @property
    def trial_duration(self) -> float:
        """How long (s) after its first actuator onset a trial counts onsets: ``2 w``, so a
        joint of the same move whose onset is seen a little later still counts."""
        return 2.0 * self.trial_window

    @property
    def evidence_floor(self) -> float:
        return float(np.log(self.beta))


# (name, shape as a function of (n_a, n_c)). Order fixes the flat-vector layout.
_FIELDS = (
    ("t_prev", lambda na, nc: ()),            # time of the previous step; NEVER before the first
    ("request_active", lambda na, nc: ()),    # 1 while a confirming motion is requested
    ("request_count", lambda na, nc: ()),     # number of requests raised so far
    ("request_time", lambda na, nc: ()),
    ("request_joint", lambda na, nc: ()),     # joint to move again (-1: any/all)
    ("trial_active", lambda na, nc: ()),
    ("trial_t0", lambda na, nc: ()),
    ("trial_count", lambda na, nc: ()),       # trials started so far
    ("trial_until", lambda na, nc: ()),       # end of the latest trial's response window
    ("request_end", lambda na, nc: ()),       # when the latest request was cleared
    ("sequence_trials", lambda na, nc: ()),   # trials since the latest request raised by a
    #                                           coincidence (its follow-ups included)
    ("a_prev", lambda na, nc: (na,)),         # previous actuator values a_i
    ("last_motion_a", lambda na, nc: (na,)),  # last time actuator i moved
    ("t_onset_a", lambda na, nc: (na,)),      # last onset time of actuator i
    ("q_request", lambda na, nc: (na,)),      # q*: the posture to return to
    ("trial_moved", lambda na, nc: (na,)),    # actuators with an onset during the trial
    ("q_onset", lambda na, nc: (na, na)),     # row i: posture at actuator i's last onset
    ("last_motion_s", lambda na, nc: (nc,)),
    ("t_onset_s", lambda na, nc: (nc,)),
    ("unexplained", lambda na, nc: (nc,)),    # visual onsets while the robot was still
    ("t_still", lambda na, nc: (nc,)),        # T_still,j: still time the cell could have onset, s
    ("free_onsets", lambda na, nc: (nc,)),    # visual onsets with no actuator onset within w
    ("t_free", lambda na, nc: (nc,)),         # quiet-cell time with no actuator onset within w, s
    ("evidence", lambda na, nc: (nc,)),       # L_j
    ("candidates", lambda na, nc: (nc,)),     # cells under test by the pending request
    ("trial_cells", lambda na, nc: (nc,)),    # cells tested by the latest trial (kept after it)
    ("trial_testable", lambda na, nc: (nc,)),  # its candidates quiet at its start (could respond)
    ("eps", lambda na, nc: (na, nc)),         # ε_ij, Eq. (27)
    ("counted_ta", lambda na, nc: (na, nc)),  # onset pair last counted into ε_ij
    ("counted_ts", lambda na, nc: (na, nc)),
    ("hits", lambda na, nc: (na, nc)),        # confirming hits per pair
    ("misses", lambda na, nc: (na, nc)),      # confirming misses per pair
    ("cand_act", lambda na, nc: (na, nc)),    # pairs that raised the pending request
    ("trial_hit", lambda na, nc: (na, nc)),   # pairs that coincided during the trial
)


@functools.cache
def _layout(n_a: int, n_c: int) -> tuple[tuple, int]:
    """The flat-vector layout of ``_FIELDS``: ``((name, start, stop, shape), ...)`` and the size."""
    layout, k = [], 0
    for name, shape in _FIELDS:
        shp = shape(n_a, n_c)
        n = int(np.prod(shp, dtype=int))
        layout.append((name, k, k + n, shp))
        k += n
    return tuple(layout), k


class CoincidenceState:
    """Per-actuator / per-cell state of the detector: plain float arrays, one per field.

    ``n_a`` actuators, ``n_c`` cells. Booleans are stored as 0/1 and times in seconds, with
    :data:`NEVER` for "not yet". ``copy()`` is deep; ``to_vector``/``from_vector`` round-trip.
    """

    __slots__ = ("n_a", "n_c") + tuple(name for name, _ in _FIELDS)

    def __init__(self, n_a: int, n_c: int):
        if n_a <= 0 or n_c <= 0:
            raise ValueError(f"need at least one actuator and one cell, got {n_a}, {n_c}")
        self.n_a, self.n_c = int(n_a), int(n_c)
        for name, shape in _FIELDS:
            setattr(self, name, np.zeros(shape(self.n_a, self.n_c)))
        for name in ("t_prev", "last_motion_a", "t_onset_a", "last_motion_s", "t_onset_s",
                     "counted_ta", "counted_ts", "request_time", "trial_t0", "trial_until",
                     "request_end"):
            getattr(self, name)[...] = NEVER

    @staticmethod
    def size(n_a: int, n_c: int) -> int:
        return _layout(n_a, n_c)[1]

    def to_vector(self) -> np.ndarray:
        return np.concatenate([np.ravel(getattr(self, name)) for name, _ in _FIELDS])

    @staticmethod
    def from_vector(vector: np.ndarray, n_a: int, n_c: int) -> CoincidenceState:
        v = np.asarray(vector, dtype=float).ravel()
        layout, size = _layout(n_a, n_c)
        if v.size != size:
            raise ValueError(f"state vector has {v.size} entries, expected "
                             f"{size} for {n_a} actuators, {n_c} cells")
        if n_a <= 0 or n_c <= 0:
            raise ValueError(f"need at least one actuator and one cell, got {n_a}, {n_c}")
        # Every field set from the vector: no zero-filled arrays first (a Drake system decodes
        # its state several times per frame).
        s = object.__new__(CoincidenceState)
        s.n_a, s.n_c = int(n_a), int(n_c)
        for name, start, stop, shape in layout:
            setattr(s, name, v[start:stop].reshape(shape).copy())
        return s

    def copy(self) -> CoincidenceState:
        return CoincidenceState.from_vector(self.to_vector(), self.n_a, self.n_c)

    def __deepcopy__(self, memo):
        return self.copy()

    def spontaneous_rate(self, params: CoincidenceParams) -> np.ndarray:
        """``λ_j``, 1/s: cell j's rate of visual onsets while the robot is still."""
        return (self.unexplained + params.prior_onsets) / (self.t_still + params.prior_time)

    def still_evidence(self, params: CoincidenceParams) -> np.ndarray:
        """Poisson log-likelihood ratio of the still-time onsets: body (rate ``body_onset_rate``)
        against the cell's own rate ``λ_j`` (≤ 0 once a cell moves while the robot is still)."""
        rate = self.spontaneous_rate(params)
        return (self.unexplained * np.log(params.body_onset_rate / rate)
                - (params.body_onset_rate - rate) * self.t_still)

    def total_evidence(self, params: CoincidenceParams) -> np.ndarray:
        """``L_j``: confirming-motion evidence plus still-time evidence (n_c)."""
        return self.evidence + self.still_evidence(params)

    def body(self, params: CoincidenceParams) -> np.ndarray:
        """Body-cell mask (bool, n_c): ``L_j >= ln(1/alpha)``."""
        return self.total_evidence(params) >= params.body_threshold

    def moves(self, params: CoincidenceParams) -> np.ndarray:
        """Which actuator moves which cell (bool, n_a x n_c): body cell, more hits than misses."""
        return self.body(params)[None, :] & (self.hits > self.misses)

    def chance_rate(self, params: CoincidenceParams) -> np.ndarray:
        """``λ0_j``, 1/s: cell j's rate of visual onsets with no actuator onset within ``w``
        before them (robot still or not), with the same prior as ``λ_j``. If the cell moves by
        itself, independently of the robot, this is its rate at any time, so also inside a
        trial's window; if it is body, onsets of the arm sweeping in make it an overestimate
        (hits count less), never an underestimate."""
        return np.maximum(self.spontaneous_rate(params),
                          (self.free_onsets + params.prior_onsets)
                          / (self.t_free + params.prior_time))

    def chance_probability(self, params: CoincidenceParams) -> np.ndarray:
        """``p0_j``: probability that cell j's own onsets fall in a trial's window by chance."""
        return -np.expm1(-self.chance_rate(params) * params.trial_window)

    def hold_time(self, params: CoincidenceParams) -> float:
        """Requested hold at q* (s), varied per request by a golden-ratio sequence so the
        confirming trials never phase-lock with a periodic distractor (a walking person)."""
        phase = (float(self.request_count) * 0.6180339887498949) % 1.0
        return params.hold_min + phase * params.hold_spread


def onset(moving: np.ndarray, last_motion: np.ndarray, t: float, quiet: float) -> np.ndarray:
    """"Rises up from 0": moving now, and not moving at any sample in the last ``quiet`` s."""
    return np.asarray(moving, bool) & (t - np.asarray(last_motion) > quiet)


def rho(t: float, t_onset: np.ndarray, tau: float) -> np.ndarray:
    """ρ of Eq. (27): 1 while the last onset is at most ``tau`` old."""
    age = t - np.asarray(t_onset, dtype=float)
    return (age >= 0.0) & (age <= tau)


def causal_and(t: float, t_onset_a: np.ndarray, tau_a: float, t_onset_s: np.ndarray,
               tau_s: float) -> np.ndarray:
    """The ∩ of Eq. (27) for every pair (n_a x n_c bool): both ρ are 1 and the actuator's
    remaining time is not longer than the cell's (the actuator's onset came first)."""
    t_a = np.asarray(t_onset_a, dtype=float)
    t_s = np.asarray(t_onset_s, dtype=float)
    remaining_a = tau_a - (t - t_a)
    remaining_s = tau_s - (t - t_s)
    both = rho(t, t_a, tau_a)[:, None] & rho(t, t_s, tau_s)[None, :]
    return both & (remaining_a[:, None] <= remaining_s[None, :])


def _check_inputs(state: CoincidenceState, t: float, a: np.ndarray, sdot: np.ndarray):
    if a.shape != (state.n_a,) or sdot.shape != (state.n_c,):
        raise ValueError(f"expected {state.n_a} actuator values and {state.n_c} cell values, "
                         f"got shapes {a.shape} and {sdot.shape}")
    if not (np.isfinite(t) and np.isfinite(a).all() and np.isfinite(sdot).all()):
        raise ValueError("actuator values, visual change and time must be finite")
    if t <= state.t_prev:
        raise ValueError(f"time must increase: {t} after {state.t_prev}")


def step(state: CoincidenceState, t: float, a: np.ndarray, sdot: np.ndarray,
         params: CoincidenceParams = CoincidenceParams(),
         known_body: np.ndarray | None = None) -> CoincidenceState:
    """One sample of the detector at time ``t`` (s): actuator values ``a`` (rad) and per-cell
    visual change ``sdot`` (px/s). Returns the new state; ``state`` is not modified.

    ``known_body`` (optional, n_c bool): cells already known to hold the body by other
    evidence (confirmed body features, :mod:`.body_features`); like body cells, they raise no
    confirming request, so the robot's time goes to cells still in question."""
    a = np.asarray(a, dtype=float).ravel()
    sdot = np.asarray(sdot, dtype=float).ravel()
    _check_inputs(state, t, a, sdot)
    known = np.zeros(state.n_c, bool) if known_body is None else np.asarray(known_body, bool)
    if known.shape != (state.n_c,):
        raise ValueError(f"known_body needs {state.n_c} cells, got shape {known.shape}")
    s = state.copy()
    first = state.t_prev <= NEVER
    s.t_prev = np.float64(t)
    if first:
        # No previous sample: no ȧ yet. Record the posture only.
        s.a_prev = a.copy()
        return s

    # Onset detectors ρ_a, ρ_s ("rises up from 0").
    adot = (a - state.a_prev) / (t - state.t_prev)
    moving_a = np.abs(adot) > params.adot_threshold
    onset_a = onset(moving_a, state.last_motion_a, t, params.quiet_a)
    moving_s = sdot > params.sdot_threshold
    onset_s = onset(moving_s, state.last_motion_s, t, params.quiet_s)
    s.last_motion_a[moving_a] = t
    s.last_motion_s[moving_s] = t
    s.t_onset_a[onset_a] = t
    s.t_onset_s[onset_s] = t
    s.q_onset[onset_a] = state.a_prev        # the posture the motion started from
    s.a_prev = a.copy()

    # Counter-evidence 1: visual onsets while the robot has been still for τ_a, with
    # exponential forgetting so a cell a person left behind can become body later.
    dt = t - state.t_prev
    keep = np.exp(-dt / params.memory)
    s.t_still *= keep
    s.unexplained *= keep
    if not moving_a.any() and t - state.last_motion_a.max() > params.tau_a:
        # Exposure counts only while the cell was quiet (able to have an onset), so λ_j is the
        # rate at which a quiet cell starts moving: the chance it starts inside a trial window.
        s.t_still += dt * (t - state.last_motion_s > params.quiet_s)
        s.unexplained += onset_s
    # The chance rate of a trial hit: onsets outside every actuator onset's window w.
    s.t_free *= keep
    s.free_onsets *= keep
    if t - s.t_onset_a.max() > params.trial_window:
        s.t_free += dt * (t - state.last_motion_s > params.quiet_s)
        s.free_onsets += onset_s

    # Eq. (27), once per coincident pair of onsets.
    fired = causal_and(t, s.t_onset_a, params.tau_a, s.t_onset_s, params.tau_s)
    already = (s.counted_ta == s.t_onset_a[:, None]) & (s.counted_ts == s.t_onset_s[None, :])
    new = fired & ~already
    s.eps += new
    s.counted_ta = np.where(new, s.t_onset_a[:, None], s.counted_ta)
    s.counted_ts = np.where(new, s.t_onset_s[None, :], s.counted_ts)

    # A confirming trial is a new motion of the arm from rest: every actuator was still for
    # quiet_a before this sample (another joint's late onset in the same move is no trial).
    arm_rested = t - state.last_motion_a.max() > params.quiet_a
    # The arm has just come to rest (still for quiet_a now, not at the previous sample).
    stopped = bool(t - s.last_motion_a.max() > params.quiet_a) and not bool(
        state.t_prev - state.last_motion_a.max() > params.quiet_a)
    _confirm(s, t, onset_a & arm_rested, new, params, known, stopped)
    return s


def _add_evidence(s: CoincidenceState, cells: np.ndarray, hit: bool, params: CoincidenceParams):
    p0 = s.chance_probability(params)
    if hit:
        term = np.log(params.p_response / p0)
    else:
        term = np.log((1.0 - params.p_response) / (1.0 - p0))
    s.evidence = np.where(cells, np.maximum(s.evidence + term, params.evidence_floor), s.evidence)


def _confirm(s: CoincidenceState, t: float, onset_a: np.ndarray, new: np.ndarray,
             params: CoincidenceParams, known: np.ndarray, stopped: bool = False):
    """Confirming motions: raise a request, recognise its trial, score hits and misses."""
    if s.request_active and not s.trial_active:
        # Pairs of the move that raised the request (its actuator onsets, up to the request),
        # seen a little later (slower cells and joints), join its candidates while it waits for
        # its trial: chosen before the trial, like the first ones, so the trial's evidence stays
        # unbiased. Not for follow-ups: the trial steps' onsets would let every busy cell in.
        late = new & ~(s.body(params) | known)[None, :] & (s.sequence_trials == 0) & (
            s.t_onset_a <= s.request_time)[:, None]
        s.cand_act = np.maximum(s.cand_act, late)
        s.candidates = np.maximum(s.candidates, late.any(axis=0))
        # Rows of q_onset for this sample's onsets all hold the posture the motion started from.
        started_near = onset_a.any() and np.max(
            np.abs(s.q_onset[np.argmax(onset_a)] - s.q_request)) <= params.posture_tolerance
        if started_near:
            s.trial_active = np.float64(1)
            s.trial_t0 = np.float64(t)
            s.trial_count += 1
            s.sequence_trials += 1
            s.trial_until = np.float64(t + params.trial_window)
            s.trial_cells = s.candidates.copy()
            quiet = (s.t_onset_s == t) | (t - s.last_motion_s > params.quiet_s)
            s.trial_testable = (s.candidates > 0) & (quiet | (not params.skip_busy_cells))
            s.trial_moved[:] = 0
            s.trial_hit[:] = 0
        elif t - s.request_time > params.confirm_timeout:
            _clear_request(s, t)
            return

    if s.trial_active:
        cand = (s.candidates > 0) & (s.trial_testable > 0)
        s.trial_moved = np.maximum(s.trial_moved, onset_a)
        trial_new = new & ((s.t_onset_a >= s.trial_t0)
                           & (t - s.t_onset_a <= params.trial_window + 1e-9))[:, None]
        # A hit is scored at once (detection latency); a miss only when the window has closed.
        first_hit = cand & trial_new.any(axis=0) & ~(s.trial_hit.max(axis=0) > 0)
        _add_evidence(s, first_hit, True, params)
        s.hits += trial_new & ~(s.trial_hit > 0) & cand[None, :]
        s.trial_hit = np.maximum(s.trial_hit, trial_new)
        hit = s.trial_hit.max(axis=0) > 0
        # The trial ends when every candidate has responded, or when the window of the latest
        # actuator onset it can count has closed (joints of one move start within ~w).
        if (hit | ~cand).all() or t - s.trial_t0 > params.trial_duration:
            tested_pairs = (s.cand_act > 0) & (s.trial_moved[:, None] > 0)
            miss = cand & ~hit & tested_pairs.any(axis=0)
            _add_evidence(s, miss, False, params)
            s.misses += tested_pairs & miss[None, :]
            # Cells that responded here and are not yet body are tested again at once, at the
            # same posture (a fast sequence of unselected trials).
            untested = (s.cand_act > 0) & ~(s.trial_testable > 0)[None, :]
            follow = ((s.trial_hit > 0) | untested) & ~(s.body(params) | known)[None, :]
            q = s.q_request.copy()
            _clear_request(s, t)
            limit = params.max_sequence_trials
            if follow.any() and (limit == 0 or s.sequence_trials < limit):
                _raise_request(s, t, follow, q, params)
        return

    if not s.request_active and t - s.request_end >= params.request_interval:
        trigger = new & ~(s.body(params) | known)[None, :]
        if trigger.any():
            acts = np.flatnonzero(trigger.any(axis=1))
            latest = acts[np.argmax(s.t_onset_a[acts])]
            s.sequence_trials = np.float64(0)
            _raise_request(s, t, trigger, s.q_onset[latest], params)
        elif stopped and params.stop_requests:
            # Where the arm stops: the cells that moved during the end of its motion (the
            # arm's place now; their onsets, mid-move, coincided with no actuator onset),
            # with the joints that were moving then, tested at the posture where it rests.
            t_stop = s.last_motion_a.max()
            cells = (s.last_motion_s >= t_stop - params.tau_s) & ~(s.body(params) | known)
            acts = s.last_motion_a >= t_stop - params.tau_a
            if cells.any():
                s.sequence_trials = np.float64(0)
                _raise_request(s, t, acts[:, None] & cells[None, :], s.a_prev, params)


def _raise_request(s: CoincidenceState, t: float, pairs: np.ndarray, q: np.ndarray,
                   params: CoincidenceParams):
    # The coincidence that raises a request is not evidence: it was selected because it
    # coincided, and a busy distractor coincides often. Only the trials that follow count.
    s.request_active = np.float64(1)
    s.request_count += 1
    s.request_time = np.float64(t)
    s.q_request = np.array(q, dtype=float)
    # Actuators are ordered from the base: the most proximal one moves every candidate cell
    # that any more distal candidate actuator moves.
    s.request_joint = np.float64(np.flatnonzero(pairs.any(axis=1))[0]
                                 if params.single_joint_confirm else -1)
    s.cand_act = pairs.astype(float)
    s.candidates = pairs.any(axis=0).astype(float)


def _clear_request(s: CoincidenceState, t: float):
    s.request_end = np.float64(t)
    s.request_active = np.float64(0)
    s.trial_active = np.float64(0)
    s.candidates[:] = 0
    s.cand_act[:] = 0
    s.trial_hit[:] = 0
    s.trial_moved[:] = 0
