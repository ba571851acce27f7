"""What the coordination shows of itself (issue 28, item 4) and the check of its inputs (item 1):
``AdoptedEstimates`` (each estimate beside its validity flag and its 1-sd uncertainty),
``FollowedPoint`` (the tracked point the hand-eye loop follows, the candidates' states) and
``InputsConnected`` (an unconnected input named before the first update)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import EventStatus, LeafSystem

from sustain_drake.identification import coordination, observability
from sustain_drake.identification.candidates import CandidateBank
from sustain_drake.identification.candidates.fitting import S_of
from sustain_drake.identification.errors import IdentificationError
from sustain_drake.perception.optical_flow import TrackedFeatures

_BANK = AbstractValue.Make(CandidateBank())


def _observing(mode_port, context) -> bool:
    return mode_port.Eval(context)[0] == coordination.OBSERVE


def _sd(covariance) -> np.ndarray | None:
    """The 1-sd (square roots of the diagonal) of a covariance, None without one."""
    return None if covariance is None else np.sqrt(np.maximum(np.diagonal(covariance), 0.0))


class AdoptedEstimates(LeafSystem):
    """The adopted estimates of the hand-eye and payload state machines as plain ports, each with a
    validity flag and its uncertainty.

    .. pydrake_system::

        name: AdoptedEstimates
        input_ports:
        - hand_eye_solution (with hand_eye)
        - hand_eye_mode (with hand_eye)
        - candidates (with hand_eye)
        - payload_solution (with payload)
        - payload_mode (with payload)
        output_ports:
        - X_WC (with hand_eye)
        - X_WC_valid (with hand_eye)
        - X_WC_sd (with hand_eye)
        - p_HP (with hand_eye)
        - p_HP_valid (with hand_eye)
        - p_HP_sd (with hand_eye)
        - payload_mass (with payload)
        - p_KCm (with payload)
        - payload_valid (with payload)
        - payload_sd (with payload)

    Inputs: a ``CoordinationStateMachine``'s ``adopted_solution`` and ``mode`` per loop; the
    ``CandidateIdentifiers``' ``candidates`` (the last adoption's statistic gives the camera's
    uncertainty).

    Outputs: ``X_WC`` (RigidTransform, the camera pose in the world), ``p_HP`` (3, m, the tool
    point in the hand frame), ``payload_mass`` (1, kg), ``p_KCm`` (3, m, the payload's centre of
    mass in the sensor frame K). Each ``*_valid`` (1) is 1 when its estimate is one to use, 0 when
    the value means nothing (it is then the identity or zeros, or the last estimate before a
    change; never NaN):

    - ``X_WC_valid``: a camera is adopted (from the first hand-eye convergence; a camera move
      drops it until the next; an observation failure keeps it: the body changed, not the camera).
    - ``p_HP_valid``: a tool point is adopted and observed (``hand_eye_mode`` 1; after an
      observation failure the tool point is stale until the next convergence).
    - ``payload_valid``: a payload is adopted and observed (``payload_mode`` 1).

    Uncertainty, 1 sd from Gauss-Newton's covariance at the adoption
    (``identification.observability``), ``inf`` when not known (no valid estimate, or the fit
    does not determine it): ``X_WC_sd`` (6: the camera's rotation about its own x, y, z axes in
    rad, then its position in the world's x, y, z in m), ``p_HP_sd`` (3, m), ``payload_sd`` (4: the
    mass in kg, then ``p_KCm`` in m). The camera's are those of the adopted leader's own points
    (``CandidateBank.adoptions``); a model refined with other points while observing is at least
    as certain.
    """

    def __init__(self, hand_eye: bool = True, payload: bool = True):
        super().__init__()
        if hand_eye:
            self._hand_eye = self.DeclareAbstractInputPort("hand_eye_solution", AbstractValue.Make(object()))
            self._hand_eye_mode = self.DeclareVectorInputPort("hand_eye_mode", 1)
            self._candidates = self.DeclareAbstractInputPort("candidates", _BANK)
            self.DeclareAbstractOutputPort("X_WC", lambda: AbstractValue.Make(RigidTransform()),
                                           self._calc_X_WC)
            self.DeclareVectorOutputPort("X_WC_valid", 1,
                                         lambda c, o: o.SetAtIndex(0, self._camera(c) is not None))
            self.DeclareVectorOutputPort("X_WC_sd", 6, lambda c, o: o.SetFromVector(self._hand_eye_sd(c)[:6]))
            self.DeclareVectorOutputPort("p_HP", 3, self._calc_p_HP)
            self.DeclareVectorOutputPort("p_HP_valid", 1, lambda c, o: o.SetAtIndex(0, self._p_HP_valid(c)))
            self.DeclareVectorOutputPort("p_HP_sd", 3, self._calc_p_HP_sd)
        if payload:
            self._payload = self.DeclareAbstractInputPort("payload_solution", AbstractValue.Make(object()))
            self._payload_mode = self.DeclareVectorInputPort("payload_mode", 1)
            self.DeclareVectorOutputPort("payload_mass", 1, self._calc_mass)
            self.DeclareVectorOutputPort("p_KCm", 3, self._calc_p_KCm)
            self.DeclareVectorOutputPort("payload_valid", 1,
                                         lambda c, o: o.SetAtIndex(0, self._payload_valid(c)))
            self.DeclareVectorOutputPort("payload_sd", 4, self._calc_payload_sd)

    # ---- hand-eye ----
    def _camera(self, context):
        """The adopted eye-to-hand estimate, None without one."""
        return getattr(self._hand_eye.Eval(context), "estimate", None)

    def _p_HP_valid(self, context) -> bool:
        return self._camera(context) is not None and _observing(self._hand_eye_mode, context)

    def _calc_X_WC(self, context, output) -> None:
        est = self._camera(context)
        output.set_value(RigidTransform() if est is None else RigidTransform(est.X_WC))

    def _calc_p_HP(self, context, output) -> None:
        est = self._camera(context)
        output.SetFromVector(np.zeros(3) if est is None else est.p_HP)

    def _hand_eye_sd(self, context) -> np.ndarray:
        """1 sd of ``(omega, p_WC, p_HP)`` (9), inf where not known."""
        est, adoptions = self._camera(context), self._candidates.Eval(context).adoptions
        sd = None
        if est is not None and adoptions:
            try:
                sd = _sd(observability.eye_to_hand_covariance(S_of(adoptions[-1].statistic), est.R_WC))
            except IdentificationError:
                sd = None
        return np.full(9, math.inf) if sd is None else sd

    def _calc_p_HP_sd(self, context, output) -> None:
        valid = self._p_HP_valid(context)
        output.SetFromVector(self._hand_eye_sd(context)[6:] if valid else np.full(3, math.inf))

    # ---- payload ----
    def _payload_solution(self, context):
        return self._payload.Eval(context)

    def _payload_valid(self, context) -> bool:
        return self._payload_solution(context) is not None and _observing(self._payload_mode, context)

    def _calc_mass(self, context, output) -> None:
        solution = self._payload_solution(context)
        output.SetAtIndex(0, 0.0 if solution is None else solution.mass)

    def _calc_p_KCm(self, context, output) -> None:
        solution = self._payload_solution(context)
        output.SetFromVector(np.zeros(3) if solution is None else solution.p_KCm)

    def _calc_payload_sd(self, context, output) -> None:
        solution = self._payload_solution(context)
        sd = _sd(solution.mass_com_covariance) if self._payload_valid(context) else None
        output.SetFromVector(np.full(4, math.inf) if sd is None else sd)


# Candidate states (``FollowedPoint``'s ``candidate_states``).
EMPTY = -1  # no candidate in this slot
IDENTIFYING = 0  # its identifier gathers samples
CONVERGED = 1  # its verdict says converged; not (yet) chosen as the leader
LEADER = 2  # the first to converge since the last reset: its estimate is the one adopted
CANDIDATE_STATE_NAMES = {EMPTY: "empty", IDENTIFYING: "identifying", CONVERGED: "converged", LEADER: "leader"}
FOLLOWED_POINT_SIZE = 9  # [feature_id, u, v, p_CP (3), p_HP (3)]


class FollowedPoint(LeafSystem):
    """The tracked point the hand-eye loop follows, and the state of each candidate.

    .. pydrake_system::

        name: FollowedPoint
        input_ports:
        - candidates
        - tracked_features
        - reference_x
        output_ports:
        - followed_point
        - followed_point_valid
        - candidate_states

    Inputs: ``candidates`` (a ``CandidateIdentifiers``' ``CandidateBank``), ``tracked_features``
    (the features the candidates are fed: ``TrackedFeatures``), ``reference_x`` (16, the adopted
    estimate: the state machine's ``adopted_x``).

    Outputs: ``followed_point`` (9: ``[feature_id, u, v, p_CP, p_HP]``: the observed feature's
    track id, its pixel in this frame (px, u right, v down), its measured point in the camera frame
    (3, m) and its point in the hand frame under the adopted model (3, m; the adopted ``p_HP``, or
    the re-acquired point's own)); ``followed_point_valid`` (1): 1 while a model is adopted and its
    observed feature is tracked with a measured point in this frame, else 0 (the values then mean
    nothing: id -1, zeros). ``candidate_states`` (``3 * max_candidates``: per candidate, the
    leader first, then in admission order, ``[feature_id, num_samples, state]`` with state
    ``IDENTIFYING`` 0, ``CONVERGED`` 1, ``LEADER`` 2; an empty slot is ``[-1, 0, EMPTY]``).
    No state: the outputs are functions of the inputs.
    """

    def __init__(self, max_candidates: int):
        super().__init__()
        self._n = int(max_candidates)
        self._bank = self.DeclareAbstractInputPort("candidates", _BANK)
        self._features = self.DeclareAbstractInputPort("tracked_features",
                                                       AbstractValue.Make(TrackedFeatures()))
        self._reference = self.DeclareVectorInputPort("reference_x", 16)
        self.DeclareVectorOutputPort("followed_point", FOLLOWED_POINT_SIZE,
                                     lambda c, o: o.SetFromVector(self._followed(c)[0]))
        self.DeclareVectorOutputPort("followed_point_valid", 1,
                                     lambda c, o: o.SetAtIndex(0, self._followed(c)[1]))
        self.DeclareVectorOutputPort("candidate_states", 3 * self._n, self._calc_states)

    def _followed(self, context) -> tuple[np.ndarray, bool]:
        bank, x = self._bank.Eval(context), self._reference.Eval(context)
        none = np.concatenate([[-1.0], np.zeros(FOLLOWED_POINT_SIZE - 1)])
        if bank.observed < 0 or not np.any(x):
            return none, False
        features = self._features.Eval(context)
        rows = np.flatnonzero(features.ids == bank.observed)
        if rows.size == 0 or not features.valid[rows[0]]:
            return none, False
        k = rows[0]
        p_HP = bank.observed_p_HP if bank.observed_p_HP is not None else x[12:15]
        point = np.concatenate([[bank.observed], features.p_px[k], features.p_CP[k], p_HP])
        return (point, True) if np.isfinite(point).all() else (none, False)

    def _calc_states(self, context, output) -> None:
        bank = self._bank.Eval(context)
        ordered = sorted(bank.candidates, key=lambda c: c.feature_id != bank.leader)[: self._n]
        states = np.tile([-1.0, 0.0, EMPTY], self._n)
        for i, c in enumerate(ordered):
            state = (LEADER if c.feature_id == bank.leader
                     else CONVERGED if c.solution.verdict.converged else IDENTIFYING)
            states[3 * i:3 * i + 3] = (c.feature_id, c.solution.num_samples, state)
        output.SetFromVector(states)


@dataclass(frozen=True)
class RequiredInput:
    """An input a diagram needs: its port's name, its model value (an ``AbstractValue``) or vector
    size, and what to connect to it (the error's advice)."""

    name: str
    model: object
    advice: str


class InputsConnected(LeafSystem):
    """Raises, before the first update of a simulation, a one-line ``RuntimeError`` naming the first
    of ``inputs`` (``RequiredInput``) that is not connected and what to connect: Drake's own error
    comes later, at the first evaluation, and names an inner system's port. Connect each of its
    input ports to the diagram's exported input of the same name (``DiagramBuilder.ConnectInput``).

    .. pydrake_system::

        name: InputsConnected
        input_ports:
        - <one per RequiredInput>

    ``owner`` starts the message (e.g. ``make_sustainable_coordination``). An initialization
    event (a no-op unrestricted update) checks; no state, no output.
    """

    def __init__(self, owner: str, inputs: tuple[RequiredInput, ...]):
        super().__init__()
        self._owner = owner
        self._ports = []
        for required in inputs:
            if isinstance(required.model, AbstractValue):
                port = self.DeclareAbstractInputPort(required.name, required.model)
            else:
                port = self.DeclareVectorInputPort(required.name, int(required.model))
            self._ports.append((port, required.advice))
        self.DeclareInitializationUnrestrictedUpdateEvent(self._check)

    def _check(self, context, state) -> EventStatus:
        for port, advice in self._ports:
            if not port.HasValue(context):
                name = port.get_name()
                raise RuntimeError(f"{self._owner}: input port '{name}' is not connected; {advice}")
        return EventStatus.DidNothing()
