"""The identify <-> observe state machine of sustainable coordination as a Drake system."""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from sustain_drake.identification import coordination
from sustain_drake.identification.coordination import CoordinationRule


class CoordinationStateMachine(LeafSystem):
    """Modes IDENTIFY and OBSERVE with the paper's rule (``identification.coordination``).

    .. pydrake_system::

        name: CoordinationStateMachine
        input_ports:
        - solution
        - observation
        - camera_motion (optional)
        - body_changes (optional)
        - camera_move_start (optional)
        output_ports:
        - mode
        - adopted_x
        - adopted_solution
        - allowable_error
        - reset
        - reset_reason
        - pause
        - events

    Inputs come from a ``SustainableIdentifierSystem``: ``solution`` (its abstract solution, with
    the verdict and ``a^2 lambda_N``) and ``observation`` (``[sample_count, s_t]``, where ``s_t``
    is the newest sample's error under ``adopted_x``: connect ``adopted_x`` to the identifier's
    ``reference_x``). ``camera_motion`` (optional, 2: ``[moving, moves]`` of a
    ``CameraMotionDetector``; beyond the paper): a new camera move is a change detection, the
    identifier is kept reset while the camera moves (``coordination.step``), and the adopted model
    is dropped (a moved camera's model is no longer a model of anything); unconnected, the paper's
    rule alone. ``body_changes`` (optional, 1: a count of the held body's changes detected by another
    sensor; connect a payload loop's state machine's ``reset``, which counts the wrist wrench's change
    detections; beyond the paper): a new one in OBSERVE is a change detection for a slip, the camera
    kept, unless the observation rule detects the change itself within its window
    (``coordination.step``); unconnected, none. ``camera_move_start`` (optional, 1, s: when the
    detector's last declared move began: connect a ``CameraMotionDetector``'s ``move_start``): a move
    found after the observation rule's reset for it is that reset's change, not a new one
    (``coordination.step``); unconnected, every new move is a change detection.

    Outputs: ``mode`` (1: 0 IDENTIFY, 1 OBSERVE); ``adopted_x`` (N, the adopted estimate; zeros
    while there is none: before the first convergence and from a camera move to the next
    convergence; after an observation failure it stays the abandoned model); ``adopted_solution``
    (the identifier's solution at adoption, or None);
    ``allowable_error`` (1, ``sigma = factor * a^2 lambda_N`` at adoption, in the formulation's
    squared residual units; 0 before); ``reset`` (1, a counter: connect to the identifier's
    ``reset``, which clears its statistic when the count changes); ``pause`` (2,
    ``[request_id, seconds]``: connect to the motion generator's ``pause``); ``events`` (a tuple
    of ``coordination.Event``: every convergence, change detection and, with the rule's
    ``adopt_refinements``, adopted refinement, with its time).

    Every ``period`` seconds (a periodic unrestricted update, at the identifier's rate) it applies
    ``coordination.step``, with the solution's ``num_samples``; it reads ``solution`` only while
    identifying or with the rule's ``adopt_refinements`` (observing, the rule needs the observation
    alone, so a lazily solving identifier solves nothing): after a change detection, a solution
    with more samples than arrived since (the identifier's reset takes effect one update later) is
    stale and not adopted. State: the rule's vector and the adopted ``x`` (discrete), the adopted
    solution and the event log (abstract).
    """

    def __init__(self, num_unknowns: int, rule: CoordinationRule | None = None, period: float = 1.0 / 30.0):
        super().__init__()
        if not period > 0:
            raise ValueError(f"period must be > 0, got {period}")
        self._rule = rule or CoordinationRule()
        self._solution_in = self.DeclareAbstractInputPort("solution", AbstractValue.Make(object()))
        self._observation = self.DeclareVectorInputPort("observation", 2)
        self._camera_motion = self.DeclareVectorInputPort("camera_motion", 2)
        self._body_changes = self.DeclareVectorInputPort("body_changes", 1)
        self._camera_move_start = self.DeclareVectorInputPort("camera_move_start", 1)
        self._state = self.DeclareDiscreteState(coordination.initial_state())
        self._adopted_x = self.DeclareDiscreteState(np.zeros(num_unknowns))
        self._adopted_x_size = int(num_unknowns)
        self._adopted = self.DeclareAbstractState(AbstractValue.Make(None))
        self._events = self.DeclareAbstractState(AbstractValue.Make(()))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

        state = {self.all_state_ticket()}
        self.DeclareVectorOutputPort(
            "mode", 1, lambda c, o: o.SetAtIndex(0, self._vector(c)[coordination.MODE]),
            prerequisites_of_calc=state,
        )  # fmt: skip
        self.DeclareStateOutputPort("adopted_x", self._adopted_x)
        self.DeclareStateOutputPort("adopted_solution", self._adopted)
        self.DeclareVectorOutputPort(
            "allowable_error", 1, lambda c, o: o.SetAtIndex(0, self._vector(c)[coordination.SIGMA]),
            prerequisites_of_calc=state,
        )  # fmt: skip
        self.DeclareVectorOutputPort(
            "reset", 1, lambda c, o: o.SetAtIndex(0, self._vector(c)[coordination.RESET_COUNT]),
            prerequisites_of_calc=state,
        )  # fmt: skip
        self.DeclareVectorOutputPort(
            "reset_reason", 1, lambda c, o: o.SetAtIndex(0, self._vector(c)[coordination.RESET_REASON]),
            prerequisites_of_calc=state,
        )  # fmt: skip
        self.DeclareVectorOutputPort(
            "pause", 2,
            lambda c, o: o.SetFromVector(
                [self._vector(c)[coordination.PAUSE_ID], self._rule.pause_after_convergence]
            ),
            prerequisites_of_calc=state,
        )  # fmt: skip
        self.DeclareStateOutputPort("events", self._events)

    @property
    def rule(self) -> CoordinationRule:
        return self._rule

    def _vector(self, context) -> np.ndarray:
        return context.get_discrete_state(self._state).value()

    def mode(self, context) -> int:
        return int(self._vector(context)[coordination.MODE])

    def events(self, context) -> tuple:
        return context.get_abstract_state(self._events).get_value()

    def _update(self, context, state) -> None:
        sample_count, sample_error = self._observation.Eval(context)
        optional = {}  # the connected optional inputs, as ``coordination.step``'s keyword arguments
        if self._camera_motion.HasValue(context):
            moving, moves = self._camera_motion.Eval(context)
            optional = {"camera_moving": bool(moving > 0.5), "camera_moves": int(moves)}
        if self._body_changes.HasValue(context):
            optional["body_changes"] = int(self._body_changes.Eval(context)[0])
        if self._camera_move_start.HasValue(context):
            optional["camera_move_start"] = float(self._camera_move_start.Eval(context)[0])
        solution = None
        if self.mode(context) == coordination.OBSERVE and not self._rule.adopt_refinements:
            # Observing without refinements, the rule reads only the observation: nothing is solved.
            verdict = dict(converged=False, expected_mse=math.inf, num_samples=None, refinement=0)
        else:
            solution = self._solution_in.Eval(context)
            verdict = dict(converged=solution.verdict.converged, expected_mse=solution.expected_mse,
                           num_samples=int(solution.num_samples),
                           refinement=int(getattr(solution, "refinement", 0)))
        report = coordination.IdentifierReport(sample_count=int(sample_count),
                                               sample_error=float(sample_error), **verdict)
        new, event = coordination.step(self._vector(context), self._rule, context.get_time(), report,
                                       **optional)
        old_reason = self._vector(context)[coordination.RESET_REASON]
        state.get_mutable_discrete_state(self._state).set_value(new)
        if event is not None:
            state.get_mutable_abstract_state(self._events).set_value(self.events(context) + (event,))
            if event.kind in (coordination.CONVERGED, coordination.REFINED):
                state.get_mutable_abstract_state(self._adopted).set_value(solution)
                state.get_mutable_discrete_state(self._adopted_x).set_value(solution.x)
        # A camera move detected now, or the last reset found to have been one.
        detected = event is not None and event.kind == coordination.CHANGE_DETECTED
        if new[coordination.RESET_REASON] == coordination.CAMERA_MOVED and (
                detected or old_reason != coordination.CAMERA_MOVED):
            # The camera is known to have moved: its model is dropped, not offered again as the
            # "previous camera" that a slipped tool would leave in place.
            state.get_mutable_abstract_state(self._adopted).set_value(None)
            state.get_mutable_discrete_state(self._adopted_x).set_value(np.zeros(self._adopted_x_size))
