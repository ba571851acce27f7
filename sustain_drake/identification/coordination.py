"""The identify <-> observe rule of sustainable coordination (paper §3.1 end, §4.3), pure python.

IDENTIFY: samples accumulate in the identifier; when its verdict says converged, the estimate is
adopted together with an allowable error derived from the identification itself,
``sigma = allowable_error_factor * max(a^2 lambda_N, noise_rms^2)`` (the paper: 100 lambda_16), the
motion pauses (the paper: 3 s) and the mode becomes OBSERVE.

The floor ``noise_rms`` (beyond the paper) is the per-sample RMS residual that the sensor's noise
alone gives (the formulation's residual units; 0: no floor, the paper's rule). No model explains
new samples better than the noise in them, so an identification's ``a^2 lambda_N`` below it is
over-fitting or round-off: on near noise-free data it would make round-off count as violations.

OBSERVE: each new sample's error under the adopted estimate, ``s_t = ||A_t x||^2`` (Eq. (2)), is
compared with ``sigma``; after ``max_consecutive_violations`` consecutive samples over it (the
paper: 10) a change of the body is declared, the identifier's statistic is reset and the mode
goes back to IDENTIFY. A sample within the limit clears the count.

Beyond the paper (``adopt_refinements``): in OBSERVE, an identifier may offer a refinement of the
adopted model (its solution's ``refinement`` counter goes up: more samples of the same body, each
within the allowable error of the adopted model); it is adopted in place, with the allowable error
recomputed, and the mode stays OBSERVE. The paper fixes the model until a change is detected.

Beyond the paper (``camera_moves``, from ``perception.camera_motion``): the camera notices its own
motion from the static scene. A new camera move is a change detection like the rule's (the same
event, with its time: the mode goes to IDENTIFY and the identifier is reset), in either mode (a
half-identified model is as stale as an adopted one); while that camera is still moving the
identifier is kept reset (each tick bumps the reset count), since samples taken while the camera
moves fit no camera. A move found late (``camera_move_start``, when the declared move began: the
detector's tracks lost it, and its still reference matched into the frame once the scene was still
again) that began no later than the last reset, an observation failure with no convergence since,
is the change that reset was for: the samples over the limit were the moved camera's. It is no new
change detection (the identification under way is of the moved camera, its samples all taken
since): the reset's reason becomes ``CAMERA_MOVED`` in place, the reset count unchanged, so the
identifier drops the camera it kept and uses the move's turn. Without these inputs (None) the rule
is the one above, unchanged.

Beyond the paper (``body_changes``, e.g. the wrist wrench's payload identification): a count of the
held body's changes that another sensor detected. A new one in OBSERVE is a change of the body that
the camera may not see (the tool out of view, or every point on it lost and new points, which fit
the kept camera with their own ``p_HP``, observing). The observation rule is given the time it
needs to confirm a change it sees, ``max_consecutive_violations`` ticks, and the camera's evidence
comes first: ticks with a new sample over the limit do not count, so a slip the camera sees is
detected by the rule as without this input. After that many other ticks, the report is a change
detection for a slip (the reason ``OBSERVATION_FAILED``: the camera is kept). In IDENTIFY a report
is only counted, as no model is adopted to drop. Without the input (None) the rule is unchanged.

The state is a small flat vector (``CoordinationState``) so that a Drake system can hold it in its
context; ``step`` is a pure function of it.

Every public function raises ``IdentificationError`` (a ``ValueError``, see ``errors``) with a
one-line message for an argument of the wrong type, shape or value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sustain_drake.identification.errors import (
    F64,
    IdentificationError,
    flag,
    instance,
    integer,
    real_array,
    real_number,
)

IDENTIFY = 0
OBSERVE = 1
MODE_NAMES = {IDENTIFY: "IDENTIFY", OBSERVE: "OBSERVE"}

CONVERGED = "converged"
CHANGE_DETECTED = "change_detected"
REFINED = "refined"


@dataclass(frozen=True)
class CoordinationRule:
    """The thresholds of the rule (all settable from a scenario file).

    Attributes:
        allowable_error_factor: ``sigma = factor * max(a^2 lambda_N, noise_rms^2)`` (paper: 100).
        noise_rms: the per-sample RMS residual of the sensor's noise alone, in the formulation's
            residual units (m for eye-to-hand); the floor under the expected mean squared error
            (0: none, the paper's rule).
        adopt_refinements: in OBSERVE, adopt the identifier's refinements of the adopted model
            (see the module docstring; False: the paper's fixed model).
        max_consecutive_violations: this many consecutive samples over ``sigma`` is a change
            (paper: 10; so 9 do nothing).
        pause_after_convergence: seconds the motion pauses after a convergence (paper: 3 s).

    Raises IdentificationError for a setting of the wrong type or out of its range.
    """

    allowable_error_factor: float = 100.0
    max_consecutive_violations: int = 10
    pause_after_convergence: float = 3.0
    noise_rms: float = 0.0
    adopt_refinements: bool = False

    def __post_init__(self):
        noise = real_number("noise_rms", self.noise_rms, what="a number >= 0")
        if not noise >= 0:
            raise IdentificationError(f"noise_rms must be >= 0, got {noise}")
        factor = real_number("allowable_error_factor", self.allowable_error_factor, what="a positive number")
        if not factor > 0:
            raise IdentificationError(f"allowable_error_factor must be positive, got {factor}")
        integer("max_consecutive_violations", self.max_consecutive_violations, 1)
        pause = real_number("pause_after_convergence", self.pause_after_convergence, what="a number >= 0")
        if not pause >= 0:
            raise IdentificationError(f"pause_after_convergence must be >= 0, got {pause}")
        flag("adopt_refinements", self.adopt_refinements)


# Layout of the state vector.
(MODE, VIOLATIONS, SIGMA, RESET_COUNT, PAUSE_ID, LAST_SAMPLE, CONVERGENCES, DETECTIONS, RESET_SAMPLE,
 REFINEMENT, CAMERA_MOVES, CAMERA_MOVING, RESET_REASON, BODY_CHANGES, BODY_PENDING, RESET_TIME) = range(16)
STATE_SIZE = 16
# BODY_PENDING: the ticks counted since a body change was reported in OBSERVE (-1: none pending)
# RESET_TIME: s, when the identifier was last reset (-inf: not yet)

# Why the identifier was last reset (the state's RESET_REASON; the state machine's reset_reason port).
NO_RESET = 0  # not reset yet
OBSERVATION_FAILED = 1  # samples over the allowable error (the paper's rule): the body changed (a slip)
CAMERA_MOVED = 2  # the camera noticed its own motion: the camera's model is stale, the body's is not
RESET_REASON_NAMES = {NO_RESET: "none", OBSERVATION_FAILED: "observation failed",
                      CAMERA_MOVED: "camera moved"}


def allowable_error(rule: CoordinationRule, expected_mse: float) -> float:
    """``sigma = factor * max(a^2 lambda_N, noise_rms^2)``: the paper's allowable error (§3.1, §4.3:
    100 lambda_16) with the sensor's noise as a floor under the identification's expected error.
    IdentificationError unless ``rule`` is a CoordinationRule and ``expected_mse`` a finite number."""
    instance("rule", rule, CoordinationRule, "a CoordinationRule")
    expected_mse = real_number("expected_mse", expected_mse)
    return _allowable_error(rule, expected_mse)


def _allowable_error(rule: CoordinationRule, expected_mse: float) -> float:
    return rule.allowable_error_factor * max(expected_mse, rule.noise_rms**2, 0.0)


def initial_state() -> np.ndarray:
    """IDENTIFY, no violations, no adopted model, no requests yet, no sample seen (-1), no body
    change pending (-1)."""
    state = np.zeros(STATE_SIZE)
    state[LAST_SAMPLE] = -1.0
    state[BODY_PENDING] = -1.0
    state[RESET_TIME] = -math.inf
    return state


@dataclass(frozen=True)
class Event:
    """Something the rule decided, at a time in seconds."""

    time: float
    kind: str  # CONVERGED, CHANGE_DETECTED or REFINED
    detail: str = ""


CAMERA_MOVED_DETAIL = "the camera moved"  # the detail of a change detected from the camera's own motion
# the detail of a change of the held body reported by another sensor (``body_changes``)
BODY_CHANGED_DETAIL = "the held body changed (another sensor)"


@dataclass(frozen=True)
class IdentifierReport:
    """What the identifier reports at one tick: its current solution's verdict and its newest sample.

    Attributes:
        converged: the identifier's current verdict.
        expected_mse: the identifier's current ``a^2 lambda_N`` (NaN or inf: not converged).
        sample_count: how many valid samples the identifier has seen in all (a new sample is a
            change of this count).
        sample_error: ``s_t`` of the newest sample under the ADOPTED estimate (OBSERVE only; NaN or
            inf: a violation).
        num_samples: the samples behind the identifier's solution, if known. After a change
            detection the identifier applies the reset one update later, so for a tick or two it
            still shows the old (converged) solution; a solution is only taken as the new
            identification when it has no more samples than arrived since the detection.
        refinement: the solution's refinement counter (``adopt_refinements``): in OBSERVE, a
            converged solution with a higher counter than the adopted one is a refinement of it.

    Raises IdentificationError naming the first field of the wrong type or value: ``converged``
    not a bool, the errors not numbers, the counts not integers >= 0.
    """

    converged: bool
    expected_mse: float
    sample_count: int
    sample_error: float
    num_samples: int | None = None
    refinement: int = 0

    def __post_init__(self):
        flag("converged", self.converged)
        object.__setattr__(self, "expected_mse", real_number("expected_mse", self.expected_mse, finite=False))
        integer("sample_count", self.sample_count, 0)
        object.__setattr__(self, "sample_error", real_number("sample_error", self.sample_error, finite=False))
        if self.num_samples is not None:
            integer("num_samples", self.num_samples, 0)
        integer("refinement", self.refinement, 0)


def step(
    state: np.ndarray,
    rule: CoordinationRule,
    time: float,
    report: IdentifierReport,
    camera_moving: bool = False,
    camera_moves: int | None = None,
    body_changes: int | None = None,
    camera_move_start: float | None = None,
) -> tuple[np.ndarray, Event | None]:
    """One tick of the rule. Returns the new state (a copy) and the event it decided, if any.

    Args:
        state: the current state vector.
        rule: the thresholds.
        time: now, seconds (for the event).
        report: the identifier's solution and newest sample (``IdentifierReport``).
        camera_moving, camera_moves: the camera-motion detector's ``[moving, moves]`` (None: no
            detector, the paper's rule alone): a count above the last one seen is a new camera move.
        body_changes: how many changes of the held body another sensor has detected (None: none
            reports them): a count above the last one seen, in OBSERVE, becomes a change detection
            with the reason ``OBSERVATION_FAILED`` (a slip, the camera kept) after
            ``max_consecutive_violations`` ticks without a new sample over the limit, unless the
            rule detects the change first (see the module docstring).
        camera_move_start: when the camera move of ``camera_moves`` began (s; None: not known): a new
            move that began no later than the last reset, an observation failure in IDENTIFY, and no
            longer moving, is that reset's change (the reason becomes ``CAMERA_MOVED``, no event).

    Raises IdentificationError for an argument of the wrong type or value: ``state`` not a real
    vector of STATE_SIZE, ``rule`` not a CoordinationRule, ``report`` not an IdentifierReport,
    ``time`` not finite, ``camera_moving`` not a bool, the counts not integers >= 0.
    """
    state = _checked_step_arguments(state, rule, time, report, camera_moving, camera_moves, body_changes,
                                    camera_move_start)
    converged, expected_mse, sample_count = report.converged, report.expected_mse, report.sample_count
    new = state.copy()
    new_sample = sample_count != int(state[LAST_SAMPLE])
    new[LAST_SAMPLE] = sample_count
    if camera_moves is not None:
        new[CAMERA_MOVES] = camera_moves
        if camera_moves > state[CAMERA_MOVES]:
            if (camera_move_start is not None and not camera_moving and int(state[MODE]) == IDENTIFY
                    and state[RESET_REASON] == OBSERVATION_FAILED and camera_move_start <= state[RESET_TIME]):
                new[RESET_REASON] = CAMERA_MOVED  # the change the last reset was for (module docstring)
                return new, None
            new[CAMERA_MOVING] = 1.0
            event = Event(time, CHANGE_DETECTED, CAMERA_MOVED_DETAIL)
            return _detect_change(new, sample_count, CAMERA_MOVED, time), event
        if state[CAMERA_MOVING]:
            if camera_moving:  # keep the identifier reset: these samples fit no camera
                new[RESET_COUNT] += 1
                new[RESET_SAMPLE] = sample_count
                new[RESET_TIME] = time
                return new, None
            new[CAMERA_MOVING] = 0.0
    if body_changes is not None:
        new[BODY_CHANGES] = body_changes
        if body_changes > state[BODY_CHANGES] and int(state[MODE]) == OBSERVE and state[BODY_PENDING] < 0:
            new[BODY_PENDING] = 0.0
    if int(state[MODE]) == IDENTIFY:
        stale = report.num_samples is not None and report.num_samples > sample_count - state[RESET_SAMPLE]
        if converged and math.isfinite(expected_mse) and not stale:
            new[MODE] = OBSERVE
            new[VIOLATIONS] = 0
            new[SIGMA] = _allowable_error(rule, expected_mse)
            new[PAUSE_ID] += 1
            new[CONVERGENCES] += 1
            new[REFINEMENT] = report.refinement
            return new, Event(time, CONVERGED, f"allowable error {new[SIGMA]:.3g}")
        return new, None
    refined = report.refinement > state[REFINEMENT] and converged and math.isfinite(expected_mse)
    if rule.adopt_refinements and refined:
        new[REFINEMENT] = report.refinement
        new[SIGMA] = _allowable_error(rule, expected_mse)
        new[VIOLATIONS] = 0
        return new, Event(time, REFINED, f"allowable error {new[SIGMA]:.3g}")
    sample_error = report.sample_error
    violation = new_sample and (sample_error > state[SIGMA] or not math.isfinite(sample_error))
    if new_sample:
        new[VIOLATIONS] = new[VIOLATIONS] + 1 if violation else 0
    if new[VIOLATIONS] >= rule.max_consecutive_violations:
        return _detect_change(new, sample_count, OBSERVATION_FAILED, time), Event(
            time, CHANGE_DETECTED, f"{rule.max_consecutive_violations} samples over the limit")
    if new[BODY_PENDING] >= 0 and not violation:  # a tick the camera shows nothing against the model
        new[BODY_PENDING] += 1
        if new[BODY_PENDING] >= rule.max_consecutive_violations:
            return _detect_change(new, sample_count, OBSERVATION_FAILED, time), Event(
                time, CHANGE_DETECTED, BODY_CHANGED_DETAIL)
    return new, None


def _checked_step_arguments(state, rule, time, report, camera_moving, camera_moves, body_changes,
                            camera_move_start):
    """``step``'s arguments checked (IdentificationError naming the first bad one); returns the state
    as a float64 vector."""
    if not (type(state) is np.ndarray and state.dtype is F64 and state.shape == (STATE_SIZE,)):
        state = real_array("state", state, (STATE_SIZE,), finite=False)
    if not (np.isfinite(state[MODE]) and np.isfinite(state[LAST_SAMPLE])):
        raise IdentificationError(f"state: its mode and sample count must be finite, got {state[MODE]} "
                                  f"and {state[LAST_SAMPLE]} (a state from initial_state and step)")
    instance("rule", rule, CoordinationRule, "a CoordinationRule")
    real_number("time", time)
    instance("report", report, IdentifierReport, "an IdentifierReport")
    flag("camera_moving", camera_moving)
    for name, count in (("camera_moves", camera_moves), ("body_changes", body_changes)):
        if count is not None:
            integer(name, count, 0)
    if camera_move_start is not None:
        start = real_number("camera_move_start", camera_move_start, finite=False)
        if math.isnan(start) or start == math.inf:
            raise IdentificationError(f"camera_move_start must be a time in s or -inf (none), got {start}")
    return state


def _detect_change(new: np.ndarray, sample_count: int, reason: int, time: float) -> np.ndarray:
    """A change detection (in place on ``new``) for ``reason``: back to IDENTIFY, the identifier
    reset (its solutions with more samples than arrive from now on are stale)."""
    new[RESET_REASON] = reason
    new[BODY_PENDING] = -1.0  # a change detected for any reason answers a pending report
    new[MODE] = IDENTIFY
    new[VIOLATIONS] = 0
    new[RESET_COUNT] += 1
    new[DETECTIONS] += 1
    new[RESET_SAMPLE] = sample_count
    new[RESET_TIME] = time
    return new
