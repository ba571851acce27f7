"""Candidate tracked points for eye-to-hand identification (paper Fig. 7, §4.3), pure numpy.

The paper runs one sustainable identifier per candidate corner that the coincidence detector
marks as body, and adopts the first one to converge. A corner on another link than the hand
does not satisfy Eq. (30) (its point is not fixed in H), so its residual stays large and its
verdict never says converged: the hand formulation is itself a filter.

This module is the bookkeeping, as a pure function of a ``CandidateBank`` (held by a Drake
system in an abstract state):

- admission: body features with a valid 3-D point become candidates, oldest track first, at most
  ``max_candidates`` at a time (a bounded cost per frame);
- feeding: each frame, each candidate's identifier gets the feature's ``p_CP`` and the hand pose
  ``X_WH`` at the frame's capture time (``PoseHistory``: the image is older than the encoders by
  a frame or two, and at 0.4 m/s a frame is 1.3 cm);
- a motion gate: a point fixed within ``max_hand_radius`` of the hand origin cannot move in the
  camera frame (a fixed camera) by more than the hand's translation plus its rotation angle times
  that radius; a sample that does (a depth value taken from the background at a silhouette, a
  track that jumped) is skipped;
- loss: a feature no longer tracked (the tracker never reuses an id) or without a valid depth
  (occluded) stops feeding its identifier; after ``max_lost_time`` s without a sample its slot is
  freed; a candidate still not converged after ``max_unconverged_time`` s is rejected (another
  link, a sliding silhouette corner) and its slot freed;
- the leader: the first candidate whose verdict says converged (the smallest expected error if
  several converge on the same frame) is the leader until the next reset; its solution is refined
  (Gauss-Newton) and it is what a ``CoordinationStateMachine`` adopts;
- observation: once there is a leader, its feature (the *observed* feature) gives one ``s_t`` per
  frame under the reference (adopted) estimate. When the observed feature is lost, the body
  feature nearest to where the adopted estimate puts the tracked point (within
  ``reacquire_radius``) takes its place, so a re-seeded track of the same point keeps the
  observation going;
- reset: a new reset value (a change was detected: the tool slipped or the camera moved) drops
  every candidate; identification starts again from the body features seen then.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from sustain_drake.identification.eye_to_hand import EyeToHandIdentifier, EyeToHandSolution, build_A
from sustain_drake.identification.rotation import rotation_angle
from sustain_drake.identification.sustainable_identifier import ConvergenceCriteria, SustainableIdentifier


@dataclass(frozen=True)
class CandidateParams:
    """Bookkeeping thresholds (SI units).

    Attributes:
        max_candidates: identifiers run at a time.
        max_hand_radius: m, the farthest a tracked point on the hand or its tool can be from the
            hand origin (the motion gate).
        gate_margin: m, added to the motion gate's bound (depth noise of two frames).
        max_lost_time: s without a sample before a candidate's slot is freed.
        max_unconverged_time: s after admission before a candidate that has not converged is
            rejected (until the next reset).
        reacquire_radius: m, how near the adopted estimate's prediction a body feature must be to
            take over the observation of a lost observed feature.
        pose_tolerance: s, how far the nearest hand pose may be from a frame's capture time.
    """

    max_candidates: int = 8
    max_hand_radius: float = 0.6
    gate_margin: float = 0.01
    max_lost_time: float = 2.0
    max_unconverged_time: float = 30.0
    reacquire_radius: float = 0.01
    pose_tolerance: float = 0.01

    def __post_init__(self):
        if not self.max_candidates >= 1:
            raise ValueError(f"max_candidates must be >= 1, got {self.max_candidates}")
        for name in ("max_hand_radius", "gate_margin", "max_lost_time", "max_unconverged_time",
                     "reacquire_radius", "pose_tolerance"):
            value = getattr(self, name)
            if not (value > 0 and math.isfinite(value)):
                raise ValueError(f"{name} must be a positive number, got {value}")


@dataclass(frozen=True)
class Candidate:
    """One candidate tracked point: its feature id, its identifier's statistic and solution."""

    feature_id: int
    statistic: np.ndarray
    solution: EyeToHandSolution
    admitted: float  # s
    last_sample: float  # s, time of the last sample fed (admission time before any)
    last_p_CP: np.ndarray | None = None  # the last measured point (accepted or not), for the gate
    last_X_WH: np.ndarray | None = None


@dataclass(frozen=True)
class Adoption:
    """A leader chosen (what the state machine adopts): when, which feature, its statistic."""

    time: float
    feature_id: int
    statistic: np.ndarray
    admitted: float  # s, when this candidate was admitted
    round_start: float  # s, when the first candidate of this identification round was admitted


@dataclass(frozen=True)
class CandidateBank:
    """Everything the candidates carry from frame to frame (immutable: ``step`` returns a new one,
    so a Drake context holding it clones safely).

    Attributes:
        candidates: in admission order.
        leader: feature id of the first candidate to converge since the last reset (-1: none).
        observed: feature id feeding the observation (the leader's, or a re-acquired one; -1).
        rejected: ids rejected since the last reset (only ids still tracked are kept).
        sample_count: samples since construction (never reset): frames that fed an identifier
            while there is no leader, then observations of the observed feature.
        sample_error: ``s_t`` of the newest observation sample, m^2.
        last_reset: the last reset value seen.
        last_frame: capture time of the last frame used, s.
        poses: recent hand poses ``(time, X_WH)``.
        adoptions: every leader chosen, in order.
        round_start: when the first candidate since the last reset was admitted (NaN: none yet).
    """

    candidates: tuple = ()
    leader: int = -1
    observed: int = -1
    rejected: frozenset = frozenset()
    sample_count: int = 0
    sample_error: float = math.inf
    last_reset: float = 0.0
    last_frame: float = -math.inf
    poses: tuple = ()
    adoptions: tuple = ()
    round_start: float = math.nan

    def find(self, feature_id: int) -> Candidate | None:
        for c in self.candidates:
            if c.feature_id == feature_id:
                return c
        return None

    @property
    def shown(self) -> Candidate | None:
        """The candidate to report: the leader, else the one with the most samples."""
        if not self.candidates:
            return None
        leader = self.find(self.leader)
        if leader is not None:
            return leader
        return max(self.candidates, key=lambda c: c.solution.num_samples)


POSE_HISTORY = 8  # frames of hand poses kept (the image lags the encoders by one or two)


def empty_solution(criteria: ConvergenceCriteria | None = None) -> EyeToHandSolution:
    return EyeToHandIdentifier(criteria=criteria).solve(refine_estimate=False)


def record_pose(bank: CandidateBank, time: float, X_WH: np.ndarray) -> CandidateBank:
    """Adds the hand pose at ``time`` to the short history."""
    poses = (bank.poses + ((float(time), np.array(X_WH, dtype=float)),))[-POSE_HISTORY:]
    return replace(bank, poses=poses)


def pose_at(bank: CandidateBank, time: float, tolerance: float) -> np.ndarray | None:
    """The recorded hand pose nearest ``time`` if within ``tolerance`` s, else None."""
    best, best_dt = None, tolerance
    for t, X in bank.poses:
        dt = abs(t - time)
        if dt <= best_dt:
            best, best_dt = X, dt
    return best


def within_motion_gate(p_prev, X_prev, p, X, params: CandidateParams) -> bool:
    """Whether a point fixed on the hand could have moved from ``p_prev`` to ``p`` (camera frame)
    while the hand moved from ``X_prev`` to ``X`` (a fixed camera: camera-frame distances are
    world distances)."""
    if p_prev is None or X_prev is None:
        return True
    bound = (np.linalg.norm(X[:3, 3] - X_prev[:3, 3])
             + rotation_angle(X_prev[:3, :3].T @ X[:3, :3]) * params.max_hand_radius
             + params.gate_margin)
    return float(np.linalg.norm(p - p_prev)) <= bound


def x_is_set(x: np.ndarray | None) -> bool:
    return x is not None and np.all(np.isfinite(x)) and bool(np.any(x))


def predicted_p_CP(x: np.ndarray, X_WH: np.ndarray) -> np.ndarray:
    """Where estimate ``x`` (Eq. (36)) puts the tracked point in the camera frame (Eq. (30))."""
    R_WC = x[0:9].reshape(3, 3, order="F")
    return R_WC.T @ (X_WH[:3, :3] @ x[12:15] + X_WH[:3, 3] - x[9:12])


def step(
    bank: CandidateBank,
    params: CandidateParams,
    criteria: ConvergenceCriteria,
    time: float,
    reset: float,
    X_WH: np.ndarray,
    frame_time: float,
    ids: np.ndarray,
    p_CP: np.ndarray,
    valid: np.ndarray,
    on_body: np.ndarray,
    reference_x: np.ndarray | None = None,
    forgetting_factor: float = 1.0,
) -> CandidateBank:
    """One tick at ``time``: the reset, the hand pose, then (on a new frame) admission, feeding,
    loss, the leader and the observation. Returns the new bank.

    Args:
        reset: the reset input; a value different from the last one seen drops every candidate.
        X_WH: the hand pose now (4 x 4).
        frame_time: the capture time of the features below (s).
        ids, p_CP, valid, on_body: per tracked feature (same order): id, point in the camera frame
            (m), whether the point is measured, whether the feature is body.
        reference_x: the adopted estimate (Eq. (36)); zeros or None before one. ``s_t`` of the
            observed feature is computed under it (under the leader's own estimate if unset).
    """
    if reset != bank.last_reset:
        bank = replace(bank, candidates=(), leader=-1, observed=-1, rejected=frozenset(),
                       last_reset=float(reset), round_start=math.nan)
    bank = record_pose(bank, time, X_WH)
    if not frame_time > bank.last_frame:
        return bank  # no new frame (or none yet)
    X_frame = pose_at(bank, frame_time, params.pose_tolerance)
    if X_frame is None:
        return replace(bank, last_frame=float(frame_time))  # no pose for that frame: skip it
    ids = np.asarray(ids, np.int64).ravel()
    p_CP = np.asarray(p_CP, dtype=float).reshape(-1, 3)
    usable = np.asarray(valid, bool).ravel() & np.all(np.isfinite(p_CP), axis=1)
    on_body = np.asarray(on_body, bool).ravel()
    row = {int(i): k for k, i in enumerate(ids)}
    rejected = frozenset(i for i in bank.rejected if i in row)

    # Feed (only before a leader exists: then the leader alone keeps feeding), drop lost ones.
    kept, fed = [], False
    for c in bank.candidates:
        k = row.get(c.feature_id)
        is_leader = c.feature_id == bank.leader
        if k is None and not is_leader:
            continue  # no longer tracked: gone for good (ids are never reused)
        if k is not None and usable[k] and (bank.leader < 0 or is_leader):
            num = c.solution.num_samples
            c = _feed(c, params, criteria, frame_time, p_CP[k], X_frame, forgetting_factor,
                      refine=is_leader)
            fed = fed or c.solution.num_samples > num
        if bank.leader < 0:  # with a leader, the others are frozen until the next reset
            if frame_time - c.last_sample > params.max_lost_time:
                continue  # occluded too long: the slot is freed
            if frame_time - c.admitted > params.max_unconverged_time and not c.solution.verdict.converged:
                rejected = rejected | {c.feature_id}
                continue
        kept.append(c)

    # Admit new candidates: body features with a point, oldest track first.
    leader, adoptions, round_start = bank.leader, bank.adoptions, bank.round_start
    if leader < 0:
        present = {c.feature_id for c in kept}
        for k in np.argsort(ids, kind="stable"):
            if len(kept) >= params.max_candidates:
                break
            i = int(ids[k])
            if on_body[k] and usable[k] and i not in present and i not in rejected:
                kept.append(_admit(i, criteria, frame_time, p_CP[k], X_frame))
                fed = True
                if math.isnan(round_start):
                    round_start = float(frame_time)
        # The first to converge leads (the smallest expected error among simultaneous ones).
        converged = [c for c in kept if c.solution.verdict.converged]
        if converged:
            best = min(converged, key=lambda c: c.solution.expected_mse)
            best = _solve(best, criteria, forgetting_factor, refine=True)
            if best.solution.verdict.converged:
                kept = [best if c.feature_id == best.feature_id else c for c in kept]
                leader = best.feature_id
                adoptions = adoptions + (Adoption(float(frame_time), leader, best.statistic.copy(),
                                                  best.admitted, round_start),)
    # Before a leader, a frame that fed any identifier counts as a sample (the state machine
    # checks a solution's samples against the count since a reset); after, observations count.
    count = bank.sample_count + (1 if fed and bank.leader < 0 else 0)
    bank = replace(bank, candidates=tuple(kept), leader=leader, rejected=rejected, round_start=round_start,
                   sample_count=count,
                   last_frame=float(frame_time), adoptions=adoptions,
                   observed=bank.observed if leader == bank.leader else leader)
    return _observe(bank, params, frame_time, X_frame, ids, p_CP, usable, on_body, row, reference_x)


def _admit(feature_id, criteria, time, p_CP, X_WH) -> Candidate:
    identifier = EyeToHandIdentifier(criteria=criteria)
    identifier.add(p_CP, X_WH[:3, :3], X_WH[:3, 3])
    return Candidate(feature_id, identifier.state, identifier.solve(refine_estimate=False), float(time),
                     float(time), np.array(p_CP), np.array(X_WH))


def _identifier(c: Candidate, criteria, forgetting_factor) -> EyeToHandIdentifier:
    identifier = EyeToHandIdentifier(forgetting_factor, criteria)
    identifier.set_state(c.statistic)
    return identifier


def _solve(c: Candidate, criteria, forgetting_factor, refine: bool) -> Candidate:
    solution = _identifier(c, criteria, forgetting_factor).solve(refine_estimate=refine)
    return replace(c, solution=solution)


def _feed(c: Candidate, params, criteria, time, p_CP, X_WH, forgetting_factor, refine) -> Candidate:
    gated = within_motion_gate(c.last_p_CP, c.last_X_WH, p_CP, X_WH, params)
    c = replace(c, last_p_CP=np.array(p_CP), last_X_WH=np.array(X_WH))
    if not gated:
        return c
    identifier = _identifier(c, criteria, forgetting_factor)
    identifier.add(p_CP, X_WH[:3, :3], X_WH[:3, 3])
    return replace(c, statistic=identifier.state, last_sample=float(time),
                   solution=identifier.solve(refine_estimate=refine))


def _observe(bank, params, time, X_WH, ids, p_CP, usable, on_body, row, reference_x) -> CandidateBank:
    """The observed feature's ``s_t`` (Eq. (2)) under the reference estimate, with re-acquisition."""
    if bank.leader < 0:
        return bank
    x = reference_x if x_is_set(reference_x) else bank.find(bank.leader).solution.x
    if not x_is_set(x):
        return bank
    observed = bank.observed
    k = row.get(observed)
    if k is None:
        # Lost: the body feature nearest to where the estimate puts the tracked point takes over.
        candidates = np.flatnonzero(usable & on_body)
        if candidates.size == 0:
            return bank
        distance = np.linalg.norm(p_CP[candidates] - predicted_p_CP(x, X_WH), axis=1)
        best = int(np.argmin(distance))
        if distance[best] > params.reacquire_radius:
            return bank
        k = int(candidates[best])
        return replace(bank, observed=int(ids[k]))  # observed from the next frame on (no gate yet)
    if not usable[k]:
        return bank
    error = SustainableIdentifier.sample_error(build_A(p_CP[k], X_WH[:3, :3], X_WH[:3, 3]), x)
    return replace(bank, sample_count=bank.sample_count + 1,
                   sample_error=error if math.isfinite(error) else math.inf)


@dataclass(frozen=True)
class BankSummary:
    """A small view of the bank for outputs and logs."""

    num_candidates: int
    leader: int
    observed: int
    feature_ids: tuple = field(default_factory=tuple)


def summary(bank: CandidateBank) -> BankSummary:
    return BankSummary(len(bank.candidates), bank.leader, bank.observed,
                       tuple(c.feature_id for c in bank.candidates))


def best_p_HP_given_camera(statistic: np.ndarray, R_WC: np.ndarray, p_WC: np.ndarray) -> np.ndarray:
    """The tracked point in H that best explains a candidate's samples when the camera pose is
    known (least squares from the statistic alone: ``x^T S x`` is quadratic in ``p_HP``).

    Used for evaluation: with the true camera pose it gives the true position of the image
    feature the identifier tracked (a corner on a silhouette is not a fixed mark on the tool)."""
    n = EyeToHandIdentifier().core.num_unknowns
    S = np.asarray(statistic, dtype=float)[: n * n].reshape(n, n)
    x = np.concatenate([np.asarray(R_WC).reshape(9, order="F"), p_WC, np.zeros(3), [1.0]])
    H = S[12:15, 12:15]
    g = S[12:15, :] @ x
    return -np.linalg.lstsq(H, g, rcond=None)[0]
