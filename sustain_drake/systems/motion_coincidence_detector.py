"""``MotionCoincidenceDetector``: which cells of the image are the robot's body (paper §3.3.2,
Eq. (27)), and which actuator moves them, with confirming motions against distractors.

A thin Drake wrapper around :func:`sustain_drake.perception.coincidence.step`; its whole state
(:class:`~sustain_drake.perception.coincidence.CoincidenceState`) is one discrete-state vector
in the context. The rule is documented in :mod:`sustain_drake.perception.coincidence`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from sustain_drake.perception.body_features import (
    FeatureMemory,
    FeatureParams,
    body_feature_cells,
    features_on_body,
    update_feature_memory,
)
from sustain_drake.perception.coincidence import (
    CoincidenceParams,
    CoincidenceState,
    step,
)
from sustain_drake.perception.optical_flow import TrackedFeatures


@dataclass
class FeatureBodyFlags:
    """Per tracked feature (same order as the ``tracked_features`` input): its id, whether it
    is on the body (its own confirming-trial hits, :mod:`sustain_drake.perception.body_features`),
    whether it lies in a body cell, and the actuator that moves its cell most (-1 if none)."""

    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    on_body: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    in_body_cell: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    actuator: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))


class MotionCoincidenceDetector(LeafSystem):
    """Eq. (27) per (actuator, cell) pair at a fixed period, and the body rule.

    .. pydrake_system::

        name: MotionCoincidenceDetector
        input_ports:
        - actuator_positions
        - visual_change
        - tracked_features
        output_ports:
        - likelihood
        - body_cells
        - actuator_cells
        - body_evidence
        - feature_on_body
        - body_feature_cells
        - confirm_posture
        - confirm_request
        - confirm

    Input ports:

    - ``actuator_positions``: the actuator values ``a_i`` (joint encoders, rad), size ``n_a``.
    - ``visual_change``: ``ṡ_j`` (px/s) per grid cell, size ``n_c`` (``OpticalFlowTracker``).
    - ``tracked_features`` (optional): ``TrackedFeatures``, for the per-feature outputs.

    Output ports (all but ``feature_on_body`` depend on state only):

    - ``likelihood``: ``ε_ij``, the paper's likelihood map, ``n_a x n_c`` row-major (actuator i,
      cell j at ``i * n_c + j``), a count of coincident onset pairs.
    - ``body_cells``: 1 for body cells, else 0 (size ``n_c``): evidence ``L_j >= ln(1/alpha)``.
    - ``actuator_cells``: ``n_a x n_c`` row-major 0/1, actuator i moves body cell j (more
      confirming hits than misses for the pair).
    - ``body_evidence``: ``L_j`` (log-likelihood ratio, dimensionless), size ``n_c``.
    - ``feature_on_body``: :class:`FeatureBodyFlags` for the features on the input.
    - ``body_feature_cells``: 1 for cells that hold at least one body feature now (size
      ``n_c``): the body where it is now, as the arm carries its confirmed features around.
      With ``FeatureParams.skip_known_cells`` these cells raise no confirming request (their
      body is already known), so the confirming motions go to cells still in question.
    - ``confirm_posture``: ``q*`` (rad, size ``n_a``): the posture at the onset of the actuator
      motion that raised the current confirming request; the last one when none is active.
    - ``confirm_request``: ``[active (0/1), count, hold (s)]``. When ``count`` increases, the
      motion generator should interrupt its motion, go back to ``confirm_posture``, hold still
      there for ``hold`` seconds, then move again (the paper's confirmative motion). A request
      not answered within ``CoincidenceParams.confirm_timeout`` expires.
    - ``confirm``: ``[count, joint, q*_1, ..., q*_n]``, the same request in the format of
      ``MotionGenerator``'s edge-triggered ``confirm`` input (a new id is a new request; ``joint``
      is the one joint to move again, -1 for a usual move of all joints; see
      ``CoincidenceParams.single_joint_confirm``).

    The detector reads ``visual_change`` as it was before its own update; with the tracker
    updating at the same instants that is the previous frame's flow, one frame after the
    encoders, which keeps the causal order of Eq. (27).
    """

    def __init__(self, num_actuators: int, num_cells: int, period: float = 1.0 / 30.0,
                 offset: float = 0.0, params: CoincidenceParams | None = None,
                 feature_params: FeatureParams | None = None):
        super().__init__()
        if not (np.isfinite(period) and period > 0):
            raise ValueError(f"period must be positive, got {period}")
        self._n_a, self._n_c = int(num_actuators), int(num_cells)
        self._params = CoincidenceParams() if params is None else params
        self._feature_params = FeatureParams() if feature_params is None else feature_params
        initial = CoincidenceState(self._n_a, self._n_c)   # raises on a bad size

        self._a = self.DeclareVectorInputPort("actuator_positions", self._n_a)
        self._sdot = self.DeclareVectorInputPort("visual_change", self._n_c)
        self._features = self.DeclareAbstractInputPort(
            "tracked_features", AbstractValue.Make(TrackedFeatures()))
        self._state_index = self.DeclareDiscreteState(initial.to_vector())
        self._memory_index = self.DeclareAbstractState(AbstractValue.Make(FeatureMemory()))
        # Unrestricted: one event updates the cell state (discrete) and the features' (abstract).
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, offset, self._update)

        state_only = {self.discrete_state_ticket(self._state_index)}
        n_a, n_c = self._n_a, self._n_c
        for name, size, calc in (
                ("likelihood", n_a * n_c, lambda s: s.eps.ravel()),
                ("body_cells", n_c, lambda s: s.body(self._params).astype(float)),
                ("actuator_cells", n_a * n_c, lambda s: s.moves(self._params).astype(float).ravel()),
                ("body_evidence", n_c, lambda s: s.total_evidence(self._params)),
                ("confirm_posture", n_a, lambda s: s.q_request),
                ("confirm_request", 3, lambda s: np.array(
                    [s.request_active, s.request_count, s.hold_time(self._params)])),
                ("confirm", 2 + n_a, lambda s: np.concatenate(
                    [[s.request_count, s.request_joint], s.q_request]))):
            self.DeclareVectorOutputPort(
                name, BasicVector(size), self._vector_calc(calc), prerequisites_of_calc=state_only)
        with_features = {self.all_state_ticket(), self._features.ticket()}
        self.DeclareAbstractOutputPort(
            "feature_on_body", lambda: AbstractValue.Make(FeatureBodyFlags()),
            self._calc_feature_on_body, prerequisites_of_calc=with_features)
        self.DeclareVectorOutputPort(
            "body_feature_cells", BasicVector(n_c), self._calc_body_feature_cells,
            prerequisites_of_calc=with_features)

    @property
    def params(self) -> CoincidenceParams:
        return self._params

    def detector_state(self, context) -> CoincidenceState:
        """A copy of the detector's state in ``context``."""
        return CoincidenceState.from_vector(
            context.get_discrete_state(self._state_index).value(), self._n_a, self._n_c)

    def _vector_calc(self, fn):
        def calc(context, output):
            output.SetFromVector(fn(self.detector_state(context)))
        return calc

    def feature_memory(self, context) -> FeatureMemory:
        """The per-feature memory in ``context`` (read only)."""
        return context.get_abstract_state(self._memory_index).get_value()

    def _update(self, context, state):
        t = context.get_time()
        has_features = self._features.HasValue(context)
        known = None
        if has_features and self._feature_params.skip_known_cells:
            f = self._features.Eval(context)
            known = body_feature_cells(self.feature_memory(context), f.ids, f.cell, self._n_c,
                                       self._feature_params)
        new = step(self.detector_state(context), t, self._a.Eval(context),
                   self._sdot.Eval(context), self._params, known)
        state.get_mutable_discrete_state().get_mutable_vector(self._state_index).SetFromVector(
            new.to_vector())
        if has_features:
            f = self._features.Eval(context)
            memory = update_feature_memory(self.feature_memory(context), new, t, f.ids, f.cell,
                                           f.flow_px, self._feature_params)
            state.get_mutable_abstract_state(self._memory_index).set_value(memory)

    def _calc_body_feature_cells(self, context, output):
        cells = np.zeros(self._n_c)
        if self._features.HasValue(context):
            f = self._features.Eval(context)
            cells = body_feature_cells(self.feature_memory(context), f.ids, f.cell, self._n_c,
                                       self._feature_params).astype(float)
        output.SetFromVector(cells)

    def _calc_feature_on_body(self, context, output):
        if not self._features.HasValue(context):
            output.set_value(FeatureBodyFlags())
            return
        features = self._features.Eval(context)
        s = self.detector_state(context)
        cell = np.asarray(features.cell, np.int64)
        if cell.size and cell.max() >= self._n_c:
            raise ValueError(f"feature cell index {cell.max()} out of range for {self._n_c} "
                             "cells: tracker and detector grids differ")
        body = s.body(self._params)
        moves = s.moves(self._params)
        inside = cell >= 0
        in_body_cell = np.zeros(cell.size, bool)
        in_body_cell[inside] = body[cell[inside]]
        actuator = np.full(cell.size, -1, np.int64)
        strength = np.where(moves, s.hits - s.misses, -np.inf)
        best = np.argmax(strength, axis=0)
        has = moves.any(axis=0)
        actuator[inside] = np.where(has[cell[inside]], best[cell[inside]], -1)
        on_body = features_on_body(self.feature_memory(context), features.ids,
                                   self._feature_params)
        output.set_value(FeatureBodyFlags(ids=np.array(features.ids, np.int64), on_body=on_body,
                                          in_body_cell=in_body_cell, actuator=actuator))
