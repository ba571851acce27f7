"""The payload loop (paper §3.5, §4.4): its settings as the ``kinesthetic`` scenario section, and its
wiring: quasi-static gate -> payload identifier (Eqs. (37)-(38)) <-> its state machine, and the touch
estimator on the held object."""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import dataclasses
from dataclasses import dataclass, field

from pydrake.math import RigidTransform

from sustain_drake.loops.identify_observe import CoordinationConfig, connect_identify_observe
from sustain_drake.systems.coordination_state_machine import CoordinationStateMachine
from sustain_drake.systems.quasi_static_gate import QuasiStaticGate
from sustain_drake.systems.sustainable_identifier_system import (
    PayloadFormulation,
    SustainableIdentifierSystem,
)
from sustain_drake.systems.touch_estimator import TouchEstimator


def _payload_coordination() -> CoordinationConfig:
    # The payload's residual rows are m/s^2 and N m; 0.3 is about 3 % of g.
    return CoordinationConfig(max_expected_rms=0.3)


@dataclasses.dataclass
class QuasiStaticConfig:
    """When a wrench sample is quasi-static enough to identify the payload from, judged from the
    joint encoders and the touch estimator (see ``QuasiStaticGate``)."""

    # rad/s: every joint slower than this is quasi-static (the inertial wrench is below the sensor noise)
    max_joint_speed: float = 0.02
    max_joint_acceleration: float = 0.05  # rad/s^2: every joint accelerating less than this is quasi-static
    window: float = 0.2  # s both joint limits must have held before a sample counts
    touch_holdoff: float = 0.5  # s without a touch before samples count again
    # s: a touch lasting longer counts as a change of the held body (an object stuck to the tool)
    max_touch_duration: float = 20.0


@dataclasses.dataclass
class KinestheticConfig:
    """Payload identification from the wrist wrench and touch estimation on the held object."""

    enabled: bool = False  # run payload identification and touch estimation on the scenario's world
    # convergence and observation; max_expected_rms 0.3 (m/s^2, N m) is about 3 % of g
    coordination: CoordinationConfig = field(default_factory=_payload_coordination)
    period: float = 0.01  # s between identifier and state-machine updates: the wrench sensor's 100 Hz
    # when a wrench sample is quasi-static enough to identify from
    quasi_static: QuasiStaticConfig = field(default_factory=QuasiStaticConfig)
    # N: least residual force of a touch: about twice the largest residual of free motion at
    # 1 rad/s (1.1 N, the payload's inertial wrench in inertia_touch.yaml)
    min_touch_force: float = 2.0
    # N: touch points are scored against the true contacts of at least this force
    eval_min_force: float = 5.0


@dataclass
class PayloadLoop:
    identifier: SustainableIdentifierSystem
    state_machine: CoordinationStateMachine
    gate: QuasiStaticGate
    estimator: TouchEstimator | None


def add_payload_loop(builder, num_joints: int, config: KinestheticConfig, shape=None,
                     X_KG: RigidTransform | None = None) -> PayloadLoop:  # fmt: skip
    """Adds the payload identifier, its state machine, the quasi-static gate and (if ``shape``, the
    held object's ``pydrake.geometry`` shape at ``X_KG`` in the sensor frame) the touch estimator,
    connected to each other. Left for the caller: ``wrench`` and ``X_WK`` of the identifier and
    the estimator, the gate's ``joint_velocities``, the use of ``state_machine.pause``."""
    c, qs = config.coordination, config.quasi_static
    ident = builder.AddSystem(SustainableIdentifierSystem(
        PayloadFormulation(criteria=c.criteria(has_rotation=False), forgetting_factor=c.forgetting_factor),
        period=config.period))  # fmt: skip
    ident.set_name("payload_identifier")
    sm = builder.AddSystem(CoordinationStateMachine(PayloadFormulation.num_unknowns, c.rule(), config.period))
    sm.set_name("payload_coordination")
    gate = builder.AddSystem(QuasiStaticGate(
        num_joints, config.period, qs.max_joint_speed, qs.max_joint_acceleration, qs.window, qs.touch_holdoff,
        qs.max_touch_duration))  # fmt: skip
    gate.set_name("quasi_static_gate")
    estimator = None
    if shape is not None:
        estimator = builder.AddSystem(TouchEstimator(shape, X_KG, min_force=config.min_touch_force))
        estimator.set_name("touch_estimator")
        # A touch keeps its samples out of the identifier (see QuasiStaticGate).
        builder.Connect(estimator.GetOutputPort("touch"), gate.GetInputPort("touch"))
        builder.Connect(sm.GetOutputPort("adopted_solution"), estimator.GetInputPort("payload"))
        builder.Connect(sm.GetOutputPort("allowable_error"), estimator.GetInputPort("allowable_error"))
    builder.Connect(gate.GetOutputPort("sample_valid"), ident.GetInputPort("sample_valid"))
    connect_identify_observe(builder, ident, sm)
    return PayloadLoop(ident, sm, gate, estimator)
