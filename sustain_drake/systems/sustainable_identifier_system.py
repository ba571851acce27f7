"""The sustainable identifier (paper §3.1) as a Drake system, for any formulation.

A formulation (``EyeToHandFormulation``, ``PayloadFormulation``, ``DynamicPayloadFormulation``) says
which sample input ports the system has and how a sample becomes ``A_t``; the statistic and the
latest solution live in the context, so contexts can be cloned and simulations run in parallel.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector, LeafSystem, ValueProducer

from sustain_drake.identification import (
    dynamic_observability,
    eye_to_hand,
    observability,
    payload,
    payload_dynamic,
)
from sustain_drake.identification.sustainable_identifier import ConvergenceCriteria, SustainableIdentifier


class EyeToHandFormulation:
    """Eye-to-hand (§3.4, N = 16). Sample ports: ``p_CP`` (3, m: the body feature's point in the
    camera frame) and ``X_WH`` (RigidTransform: the hand pose). Extra outputs: ``X_WC``
    (RigidTransform) and ``p_HP`` (3, m) of the current best estimate (identity / zeros before
    there is one).

    Args:
        criteria: convergence criteria (``eye_to_hand.default_criteria()`` if None).
        forgetting_factor: see ``SustainableIdentifier``.
        refine: run the Gauss-Newton refinement at every solve (about 80 us), so the estimate is
            always the least-squares one.
    """

    num_unknowns = eye_to_hand.N_UNKNOWNS

    def __init__(self, criteria: ConvergenceCriteria | None = None, forgetting_factor: float = 1.0,
                 refine: bool = True):  # fmt: skip
        self.criteria = criteria or eye_to_hand.default_criteria()
        self.forgetting_factor = forgetting_factor
        self.refine = refine

    def make_identifier(self) -> eye_to_hand.EyeToHandIdentifier:
        return eye_to_hand.EyeToHandIdentifier(self.forgetting_factor, self.criteria)

    def declare_sample_inputs(self, system: LeafSystem) -> tuple:
        return (
            system.DeclareVectorInputPort("p_CP", 3),
            system.DeclareAbstractInputPort("X_WH", AbstractValue.Make(RigidTransform())),
        )

    def read_sample(self, ports, context):
        p_CP = ports[0].Eval(context)
        X_WH = ports[1].Eval(context)
        R_WH, p_WH = X_WH.rotation().matrix(), X_WH.translation()
        if not math.isfinite(p_CP.sum() + R_WH.sum() + p_WH.sum()):
            return None
        return (np.array(p_CP), R_WH, p_WH)

    def add(self, identifier, sample) -> None:
        identifier.add(*sample)

    def build_A(self, sample) -> np.ndarray:
        return eye_to_hand.build_A(*sample)

    def solve(self, identifier):
        return identifier.solve(refine_estimate=self.refine)

    def declare_outputs(self, system: LeafSystem, solution_of) -> None:
        def calc_X_WC(context, output):
            est = solution_of(context).estimate
            output.set_value(RigidTransform() if est is None else RigidTransform(est.X_WC))

        def calc_p_HP(context, output):
            est = solution_of(context).estimate
            output.SetFromVector(np.zeros(3) if est is None else est.p_HP)

        system.DeclareAbstractOutputPort(
            "X_WC", lambda: AbstractValue.Make(RigidTransform()), calc_X_WC,
            prerequisites_of_calc={system.all_state_ticket()},
        )  # fmt: skip
        system.DeclareVectorOutputPort(
            "p_HP", 3, calc_p_HP, prerequisites_of_calc={system.all_state_ticket()}
        )


class PayloadFormulation:
    """Static payload (§4.4, N = 5). Sample ports: ``wrench`` (6: ``[tau_K; f_K]``, N m and N, the
    sign convention of ``identification.payload``) and ``X_WK`` (RigidTransform: the sensor
    pose; only its rotation is used). Extra outputs: ``mass`` (1, kg) and ``p_KCm`` (3, m).

    Args:
        gravity_W: gravity in the world, m/s^2.
        criteria: convergence criteria (``payload.default_criteria()`` if None).
        forgetting_factor: see ``SustainableIdentifier``.
    """

    num_unknowns = payload.N_UNKNOWNS

    def __init__(self, gravity_W=payload.STANDARD_GRAVITY_W, criteria: ConvergenceCriteria | None = None,
                 forgetting_factor: float = 1.0):  # fmt: skip
        self.gravity_W = np.asarray(gravity_W, dtype=float)
        self.criteria = criteria or payload.default_criteria()
        self.forgetting_factor = forgetting_factor

    def make_identifier(self) -> payload.PayloadIdentifier:
        return payload.PayloadIdentifier(self.gravity_W, self.forgetting_factor, self.criteria)

    def declare_sample_inputs(self, system: LeafSystem) -> tuple:
        return (
            system.DeclareVectorInputPort("wrench", 6),
            system.DeclareAbstractInputPort("X_WK", AbstractValue.Make(RigidTransform())),
        )

    def read_sample(self, ports, context):
        wrench = ports[0].Eval(context)
        R_WK = ports[1].Eval(context).rotation().matrix()
        if not math.isfinite(wrench.sum() + R_WK.sum()):
            return None
        return (np.array(wrench), R_WK)

    def add(self, identifier, sample) -> None:
        identifier.add(*sample)

    def build_A(self, sample) -> np.ndarray:
        return payload.build_A(sample[0], sample[1], self.gravity_W)

    def solve(self, identifier):
        """The identifier's solution, with its covariance attached when converged (the adopted
        payload's uncertainty, ``observability.payload_covariance``)."""
        solution = identifier.solve()
        if not solution.verdict.converged:
            return solution
        core = identifier.core
        covariance = observability.payload_covariance(core.S_view, core.weight, solution.x, self.gravity_W)
        return dataclasses.replace(solution, covariance=covariance)

    def declare_outputs(self, system: LeafSystem, solution_of) -> None:
        _declare_mass_and_com(system, solution_of)


class DynamicPayloadFormulation:
    """Dynamic payload (issue 26, N = 17: ``identification.payload_dynamic``). Sample ports:
    ``wrench`` (6: ``[tau_K; f_K]``, N m and N, the sign convention of ``identification.payload``)
    and ``kinematics_K`` (9: ``[w_WK_K; alpha_WK_K; a_WKo_K - g_K]``, rad/s, rad/s^2, m/s^2, at the
    wrench's instant; ``systems.sensor_kinematics``). Extra outputs: ``mass`` (1, kg), ``p_KCm`` (3,
    m), ``I_BBcm`` (6, kg m^2: the rotational inertia about the centre of mass in K, ``[I_xx, I_yy,
    I_zz, I_xy, I_xz, I_yz]``) and ``wrench_bias`` (6, N m and N).

    Args:
        criteria: convergence criteria (``payload_dynamic.default_criteria()`` if None).
        forgetting_factor: see ``SustainableIdentifier``.
        torque_length: m, see ``DynamicPayloadIdentifier``.
    """

    num_unknowns = payload_dynamic.N_UNKNOWNS

    def __init__(self, criteria: ConvergenceCriteria | None = None, forgetting_factor: float = 1.0,
                 torque_length: float = payload_dynamic.DEFAULT_TORQUE_LENGTH):  # fmt: skip
        self.criteria = criteria or payload_dynamic.default_criteria()
        self.forgetting_factor = forgetting_factor
        self.torque_length = torque_length

    def make_identifier(self) -> payload_dynamic.DynamicPayloadIdentifier:
        return payload_dynamic.DynamicPayloadIdentifier(self.forgetting_factor, self.criteria,
                                                        self.torque_length)  # fmt: skip

    def declare_sample_inputs(self, system: LeafSystem) -> tuple:
        return (
            system.DeclareVectorInputPort("wrench", 6),
            system.DeclareVectorInputPort("kinematics_K", payload_dynamic.KINEMATICS),
        )

    def read_sample(self, ports, context):
        wrench, kinematics = ports[0].Eval(context), ports[1].Eval(context)
        if not math.isfinite(wrench.sum() + kinematics.sum()):
            return None
        return (np.array(wrench), np.array(kinematics))

    def add(self, identifier, sample) -> None:
        identifier.add(*sample)

    def build_A(self, sample) -> np.ndarray:
        return payload_dynamic.build_A(sample[0], sample[1], self.torque_length)

    def solve(self, identifier):
        """The identifier's solution, with its covariance attached when converged
        (``dynamic_observability.dynamic_payload_covariance``)."""
        solution = identifier.solve()
        if not solution.verdict.converged:
            return solution
        core = identifier.core
        covariance = dynamic_observability.dynamic_payload_covariance(core.S_view, core.weight, solution.x)
        return dataclasses.replace(solution, covariance=covariance)

    def declare_outputs(self, system: LeafSystem, solution_of) -> None:
        _declare_mass_and_com(system, solution_of)
        for name, calc in (("I_BBcm", lambda s: s.I_BBcm), ("wrench_bias", lambda s: s.bias)):
            system.DeclareVectorOutputPort(
                name, 6, lambda context, out, calc=calc: out.SetFromVector(calc(solution_of(context))),
                prerequisites_of_calc={system.all_state_ticket()},
            )  # fmt: skip


def _declare_mass_and_com(system: LeafSystem, solution_of) -> None:
    """The payload formulations' ``mass`` (1, kg) and ``p_KCm`` (3, m) outputs."""
    system.DeclareVectorOutputPort(
        "mass", 1, lambda context, out: out.SetAtIndex(0, solution_of(context).mass),
        prerequisites_of_calc={system.all_state_ticket()},
    )  # fmt: skip
    system.DeclareVectorOutputPort(
        "p_KCm", 3, lambda context, out: out.SetFromVector(solution_of(context).p_KCm),
        prerequisites_of_calc={system.all_state_ticket()},
    )  # fmt: skip


# Layout of the bookkeeping discrete state.
_LAST_RESET, _SAMPLE_COUNT, _SAMPLE_ERROR = range(3)


class SustainableIdentifierSystem(LeafSystem):
    """Accumulates samples in the constant-memory statistic of §3.1 and solves it when read.

    .. pydrake_system::

        name: SustainableIdentifierSystem
        input_ports:
        - <sample ports of the formulation> (eye-to-hand: p_CP, X_WH; payload: wrench, X_WK;
          dynamic payload: wrench, kinematics_K)
        - sample_valid (optional)
        - reset (optional)
        - reference_x (optional)
        output_ports:
        - eigenvalues
        - x
        - ssd
        - verdict
        - expected_mse
        - observation
        - solution
        - statistic
        - <outputs of the formulation> (eye-to-hand: X_WC, p_HP; payload: mass, p_KCm; dynamic
          payload: mass, p_KCm, I_BBcm, wrench_bias)

    Every ``period`` seconds (a periodic unrestricted update) it reads one sample, adds it unless
    ``sample_valid`` (1: > 0.5 is valid; unconnected = always valid) says not or it is not
    finite. The solution (every output but ``observation`` and ``statistic``) is solved from the
    statistic when first read after a change, so a sample nobody reads a solution of costs no solve.

    - ``reset`` (1) is edge-triggered: whenever its value differs from the last one seen, the
      statistic is cleared before the sample is added (a state machine counts resets up).
    - ``reference_x`` (N): when connected and non-zero, ``observation``'s error is computed under
      this estimate (the adopted one) instead of the identifier's own.
    - ``eigenvalues`` (N, descending), ``x`` (N, the best estimate, zeros before one), ``ssd``
      (1), ``expected_mse`` (1, ``a^2 lambda_N``), ``verdict`` (2: ``[converged 0/1,
      num_samples]``), ``observation`` (2: ``[sample_count, s_t]``: valid samples seen since
      construction, never reset, and ``s_t = ||A_t x||^2`` of the latest one under the reference
      estimate, before it was added), ``solution`` (the formulation's solution object, with the
      verdict's reason), ``statistic`` (N^2 + 2: the statistic's state ``[S | n_eff | count]``,
      e.g. for an ``ExcitingPostures``).

    State: discrete group 0 is the statistic (N^2 + 2), group 1 ``[last reset value,
    sample_count, s_t]``; the solution is a cache entry of the statistic.
    """

    def __init__(self, formulation, period: float = 1.0 / 30.0):
        super().__init__()
        if not period > 0:
            raise ValueError(f"period must be > 0, got {period}")
        self._formulation = formulation
        n = formulation.num_unknowns
        self._n = n
        self._sample_ports = formulation.declare_sample_inputs(self)
        self._valid = self.DeclareVectorInputPort("sample_valid", 1)
        self._reset = self.DeclareVectorInputPort("reset", 1)
        self._reference = self.DeclareVectorInputPort("reference_x", n)
        empty = formulation.make_identifier()
        blank = formulation.solve(empty)  # immutable: every context's first value shares it
        self._statistic = self.DeclareDiscreteState(empty.state)
        self._book = self.DeclareDiscreteState(np.zeros(3))
        # The solution is a function of the statistic, solved when a reader asks for it (an
        # observing state machine with a reference estimate never does).
        self._solution = self.DeclareCacheEntry(
            "solution", ValueProducer(allocate=lambda: AbstractValue.Make(blank), calc=self._solve),
            {self.discrete_state_ticket(self._statistic)},
        )
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

        declare_solution_outputs(self, n, self.solution)
        self.DeclareVectorOutputPort(
            "observation", 2,
            lambda c, o: o.SetFromVector(c.get_discrete_state(self._book).value()[_SAMPLE_COUNT:]),
            prerequisites_of_calc={self.all_state_ticket()},
        )  # fmt: skip
        self.DeclareAbstractOutputPort(
            "solution", lambda: AbstractValue.Make(blank),
            lambda c, o: o.set_value(self.solution(c)), prerequisites_of_calc={self._solution.ticket()},
        )  # fmt: skip
        self.DeclareStateOutputPort("statistic", self._statistic)
        formulation.declare_outputs(self, self.solution)

    @property
    def formulation(self):
        return self._formulation

    def solution(self, context):
        """The solution of the statistic held in ``context`` (solved on the first call after a change)."""
        return self._solution.Eval(context)

    def _solve(self, context, value) -> None:
        identifier = self._formulation.make_identifier()
        identifier.set_state(context.get_discrete_state(self._statistic).value())
        value.set_value(self._formulation.solve(identifier))

    def _update(self, context, state) -> None:
        book = context.get_discrete_state(self._book).value().copy()
        identifier = self._formulation.make_identifier()
        identifier.set_state(context.get_discrete_state(self._statistic).value())
        if self._reset.HasValue(context):
            reset = float(self._reset.Eval(context)[0])
            if reset != book[_LAST_RESET]:
                identifier.reset()
                book[_LAST_RESET] = reset
        valid = not self._valid.HasValue(context) or self._valid.Eval(context)[0] > 0.5
        sample = self._formulation.read_sample(self._sample_ports, context) if valid else None
        if sample is not None:
            reference = self._reference.Eval(context) if self._reference.HasValue(context) else None
            if reference is None or not np.any(reference):
                reference = self.solution(context).x
            error = SustainableIdentifier.sample_error(self._formulation.build_A(sample), reference)
            try:
                self._formulation.add(identifier, sample)
            except ValueError:
                sample = None  # not finite once squared (absurd magnitudes): skipped like NaN
            else:
                book[_SAMPLE_COUNT] += 1
                book[_SAMPLE_ERROR] = _finite(error)
        state.get_mutable_discrete_state(self._statistic).set_value(identifier.state)
        state.get_mutable_discrete_state(self._book).set_value(book)



def declare_solution_outputs(system: LeafSystem, n: int, solution_of) -> None:
    """Declares ``eigenvalues`` (n), ``x`` (n), ``ssd`` (1), ``verdict`` (2: ``[converged 0/1,
    num_samples]``) and ``expected_mse`` (1) on ``system``, computed from ``solution_of(context)``
    (a solution held in the system's state). Shared by the identifier systems."""
    state = {system.all_state_ticket()}

    def calc_verdict(context, output: BasicVector) -> None:
        solution = solution_of(context)
        output.SetFromVector([1.0 if solution.verdict.converged else 0.0, solution.num_samples])

    system.DeclareVectorOutputPort(
        "eigenvalues", n, lambda c, o: o.SetFromVector(solution_of(c).eigenvalues),
        prerequisites_of_calc=state,
    )  # fmt: skip
    system.DeclareVectorOutputPort(
        "x", n, lambda c, o: o.SetFromVector(solution_of(c).x), prerequisites_of_calc=state
    )
    system.DeclareVectorOutputPort(
        "ssd", 1, lambda c, o: o.SetAtIndex(0, _finite(solution_of(c).ssd)), prerequisites_of_calc=state
    )
    system.DeclareVectorOutputPort("verdict", 2, calc_verdict, prerequisites_of_calc=state)
    system.DeclareVectorOutputPort(
        "expected_mse", 1, lambda c, o: o.SetAtIndex(0, _finite(solution_of(c).expected_mse)),
        prerequisites_of_calc=state,
    )  # fmt: skip


def _finite(value: float) -> float:
    """Outputs never carry NaN: an undefined error, SSD or MSE (no estimate yet) is +inf."""
    return math.inf if math.isnan(value) else float(value)
