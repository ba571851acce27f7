"""Which tracked features are on the body: the confirming trials of
:mod:`sustain_drake.perception.coincidence` applied to each feature (paper Fig. 7: "detection
of corners on body" feeds the hand-eye identifier). Pure numpy, no pydrake import.

A cell-level body mask is coarse: a body cell also holds background corners, and the arm leaves
the cell. A feature keeps its track id while the arm carries it, so evidence gathered on the
feature follows the body. A feature gets a *hit* when, during a confirming trial, it lies in a
cell under test and its own flow rises up from 0 (moving after ``quiet`` s without motion)
within the trial's response window after the actuator onset; at most one hit per trial. A
feature must have been tracked at rest for ``quiet`` s before its flow can rise from 0. A
feature that moves while every actuator has been still for ``still_after`` s is not the body
(Eq. (26): a track that slid off the arm onto a passing person) and loses its hits. A
feature is on the body once it has ``hits`` hits (default 2), from different trials.

A distractor's feature rarely qualifies: while it keeps moving (a person walking) it has no
onset, and a chance onset in two trials is needed. Lost tracks are forgotten (ids are never
reused), so the memory stays as large as the tracker's feature set.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .coincidence import NEVER, CoincidenceState


@dataclass(frozen=True)
class FeatureParams:
    flow_threshold_px: float = 0.2   # per-frame flow at or above this is feature motion
    quiet: float = 0.1               # s without motion before the feature's flow "rises from 0"
    hits: int = 2                    # trial hits that make a feature body
    skip_known_cells: bool = True    # cells holding a body feature raise no confirming request
    still_after: float = 0.3         # s: a feature moving when every actuator has been still this
    #                                  long is not the body (Eq. (26)): it loses its hits

    def __post_init__(self):
        if not (self.flow_threshold_px > 0 and self.quiet >= 0 and self.hits >= 1
                and self.still_after > 0):
            raise ValueError(f"invalid feature parameters {self}")


@dataclass
class FeatureMemory:
    """Per tracked feature (sorted by id): last motion time (s), hits, trial of the last hit."""

    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    last_motion: np.ndarray = field(default_factory=lambda: np.zeros(0))
    hits: np.ndarray = field(default_factory=lambda: np.zeros(0))
    last_trial: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def copy(self) -> FeatureMemory:
        return FeatureMemory(self.ids.copy(), self.last_motion.copy(), self.hits.copy(),
                             self.last_trial.copy())

    def __deepcopy__(self, memo):
        return self.copy()


def _aligned(mem: FeatureMemory, ids: np.ndarray) -> FeatureMemory:
    """The memory rows for ``ids`` (in that order); new ids start empty, missing ids are lost."""
    pos = np.searchsorted(mem.ids, ids)
    pos = np.minimum(pos, max(mem.ids.size - 1, 0))
    known = (mem.ids.size > 0) & (mem.ids[pos] == ids) if mem.ids.size else np.zeros(
        ids.size, bool)
    out = FeatureMemory(ids.copy(), np.full(ids.size, NEVER), np.zeros(ids.size),
                        np.full(ids.size, -1.0))
    out.last_motion[known] = mem.last_motion[pos[known]]
    out.hits[known] = mem.hits[pos[known]]
    out.last_trial[known] = mem.last_trial[pos[known]]
    return out


def update_feature_memory(mem: FeatureMemory, state: CoincidenceState, t: float,
                          ids: np.ndarray, cell: np.ndarray, flow_px: np.ndarray,
                          params: FeatureParams = FeatureParams()) -> FeatureMemory:
    """One sample: ``state`` is the detector's state after its step at time ``t``; ``ids``,
    ``cell``, ``flow_px`` describe the tracked features. Returns the new memory (sorted)."""
    ids = np.asarray(ids, np.int64).ravel()
    cell = np.asarray(cell, np.int64).ravel()
    flow = np.asarray(flow_px, dtype=float).reshape(-1, 2)
    if not (ids.size == cell.size == flow.shape[0]):
        raise ValueError(f"feature arrays disagree: {ids.size} ids, {cell.size} cells, "
                         f"{flow.shape[0]} flows")
    if cell.size and cell.max() >= state.n_c:
        raise ValueError(f"feature cell index {cell.max()} out of range for {state.n_c} cells: "
                         "tracker and detector grids differ")
    order = np.argsort(ids, kind="stable")
    ids, cell, flow = ids[order], cell[order], flow[order]
    out = _aligned(mem, ids)
    # A feature first seen now has not been seen at rest: its flow can only "rise up from 0"
    # after it has been tracked still for ``quiet`` s (a corner seeded on a walking person
    # would otherwise have an onset on its second frame).
    new = ~np.isin(ids, mem.ids)
    out.last_motion[new] = t
    moving = np.linalg.norm(flow, axis=1) >= params.flow_threshold_px
    onset = moving & (t - out.last_motion > params.quiet)
    out.last_motion[moving] = t
    # Counter-evidence (Eq. (26)): the body does not move while every actuator is still. A
    # track that does (one that slid off the arm onto a passing person) loses its hits.
    if t - state.last_motion_a.max() > params.still_after:
        out.hits[moving] = 0
    in_window = state.trial_t0 < t <= state.trial_until + 1e-9
    if in_window:
        tested = np.zeros(cell.size, bool)
        inside = cell >= 0
        tested[inside] = state.trial_cells[cell[inside]] > 0
        hit = onset & tested & (out.last_trial != state.trial_count)
        out.hits[hit] += 1
        out.last_trial[hit] = state.trial_count
    return out


def body_feature_cells(mem: FeatureMemory, ids: np.ndarray, cell: np.ndarray, n_c: int,
                       params: FeatureParams = FeatureParams()) -> np.ndarray:
    """Bool per cell (n_c): the cell holds at least one body feature now."""
    cells = np.zeros(n_c, bool)
    cell = np.asarray(cell, np.int64).ravel()[features_on_body(mem, ids, params)]
    cells[cell[(cell >= 0) & (cell < n_c)]] = True
    return cells


def features_on_body(mem: FeatureMemory, ids: np.ndarray,
                     params: FeatureParams = FeatureParams()) -> np.ndarray:
    """Bool per id in ``ids`` (any order): the feature has ``params.hits`` trial hits."""
    return _aligned(mem, np.asarray(ids, np.int64).ravel()).hits >= params.hits
