"""The payload loop (paper §3.5, §4.4): its settings as the ``kinesthetic`` scenario section, and its
wiring: quasi-static gate -> payload identifier (static: Eqs. (37)-(38); dynamic: the Newton-Euler
regressor of ``identification.payload_dynamic``) <-> its state machine, and the touch estimator on
the held object."""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import dataclasses
from dataclasses import dataclass, field

from pydrake.math import RigidTransform
from pydrake.systems.primitives import ConstantVectorSource

from sustain_drake.identification import payload_dynamic
from sustain_drake.loops.identify_observe import CoordinationConfig, connect_identify_observe
from sustain_drake.systems.coordination_state_machine import CoordinationStateMachine
from sustain_drake.systems.quasi_static_gate import QuasiStaticGate
from sustain_drake.systems.sustainable_identifier_system import (
    DynamicPayloadFormulation,
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


# The payload identification's modes (``KinestheticConfig.mode``).
PAYLOAD_MODES = ("static", "dynamic")


@dataclasses.dataclass
class DynamicPayloadConfig:
    """The dynamic payload mode's settings (``identification.payload_dynamic``)."""

    # m: the torque rows are divided by it: the sensor's torque noise over its force noise (ATI Mini40)
    torque_length: float = 0.025
    # samples (odd) of the Savitzky-Golay filter that differentiates the joint encoders (hardware)
    encoder_window: int = 11
    encoder_order: int = 3  # degree of that filter's polynomial (2 or more, less than the window)
    # s: how much earlier than the joint positions read with it the wrench was measured (hardware)
    wrench_delay: float = 0.0


@dataclasses.dataclass
class KinestheticConfig:
    """Payload identification from the wrist wrench and touch estimation on the held object."""

    enabled: bool = False  # run payload identification and touch estimation on the scenario's world
    # static: mass and centre of mass from quasi-static samples (Eqs. (37)-(38)); dynamic: mass,
    # centre of mass, rotational inertia and the wrench sensor's bias from every sample, moving or not
    mode: str = "static"
    # the dynamic mode's settings
    dynamic: DynamicPayloadConfig = field(default_factory=DynamicPayloadConfig)
    # convergence and observation; max_expected_rms 0.3 (static: m/s^2 and N m, about 3 % of g; dynamic: N);
    # min_gap_ratio is the static mode's (the dynamic mode's precision is its 95 % regions')
    coordination: CoordinationConfig = field(default_factory=_payload_coordination)
    period: float = 0.01  # s between identifier and state-machine updates: the wrench sensor's 100 Hz
    # when a wrench sample is quasi-static enough to identify from
    quasi_static: QuasiStaticConfig = field(default_factory=QuasiStaticConfig)
    # N: least residual force of a touch: three times the largest residual of free motion at 1 rad/s
    # (0.65 N in inertia_touch.yaml: the gripper's inertial force, which a static compensation keeps)
    min_touch_force: float = 2.0
    # N: touch points are scored against the true contacts of at least this force
    eval_min_force: float = 5.0
    # each babbling move goes to the posture, of 16 drawn, whose rest (static mode) or move and rest
    # (dynamic) add the most information per second on what the statistic determines least
    excite: bool = True


@dataclass
class PayloadLoop:
    identifier: SustainableIdentifierSystem
    state_machine: CoordinationStateMachine
    gate: QuasiStaticGate
    estimator: TouchEstimator | None


def payload_formulation(config: KinestheticConfig):
    """The identifier's formulation of ``config.mode``: ``PayloadFormulation`` (static) or
    ``DynamicPayloadFormulation``, with the criteria of ``config.coordination`` (the dynamic mode with
    its own gap, ``payload_dynamic.MIN_GAP_RATIO``). ValueError for an unknown mode."""
    c = config.coordination
    criteria = c.criteria(has_rotation=False)
    if config.mode == "static":
        return PayloadFormulation(criteria=criteria, forgetting_factor=c.forgetting_factor)
    if config.mode == "dynamic":  # its gap is only (b)'s; its 95 % regions judge the precision
        criteria = dataclasses.replace(criteria, min_gap_ratio=payload_dynamic.MIN_GAP_RATIO)
        return DynamicPayloadFormulation(criteria, c.forgetting_factor, config.dynamic.torque_length)
    raise ValueError(f"kinesthetic.mode must be one of {', '.join(PAYLOAD_MODES)}, got {config.mode!r}")


def add_payload_loop(builder, num_joints: int, config: KinestheticConfig, shape=None,
                     X_KG: RigidTransform | None = None) -> PayloadLoop:  # fmt: skip
    """Adds the payload identifier, its state machine, the quasi-static gate and (if ``shape``, the
    held object's ``pydrake.geometry`` shape at ``X_KG`` in the sensor frame) the touch estimator,
    connected to each other. Left for the caller: ``wrench`` and ``X_WK`` (static mode) or
    ``wrench`` and ``kinematics_K`` (dynamic mode) of the identifier, ``wrench`` and ``X_WK`` of the
    estimator, the gate's ``joint_velocities``, the use of ``state_machine.pause``.

    In the dynamic mode the gate keeps only touched samples out (moving samples count), and the
    touch estimator, whose prediction stays quasi-static, declares a touch on its residual force
    alone (``min_touch_force``): its allowable error is 0, since the identification's is in the
    dynamic formulation's units."""
    c, qs = config.coordination, config.quasi_static
    formulation = payload_formulation(config)
    ident = builder.AddSystem(SustainableIdentifierSystem(formulation, period=config.period))
    ident.set_name("payload_identifier")
    sm = builder.AddSystem(CoordinationStateMachine(formulation.num_unknowns, c.rule(), config.period))
    sm.set_name("payload_coordination")
    static = config.mode == "static"
    gate = builder.AddSystem(QuasiStaticGate(
        num_joints, config.period, qs.max_joint_speed, qs.max_joint_acceleration, qs.window, qs.touch_holdoff,
        qs.max_touch_duration, require_still=static))  # fmt: skip
    gate.set_name("quasi_static_gate")
    estimator = None
    if shape is not None:
        estimator = builder.AddSystem(TouchEstimator(shape, X_KG, min_force=config.min_touch_force))
        estimator.set_name("touch_estimator")
        # A touch keeps its samples out of the identifier (see QuasiStaticGate).
        builder.Connect(estimator.GetOutputPort("touch"), gate.GetInputPort("touch"))
        builder.Connect(sm.GetOutputPort("adopted_solution"), estimator.GetInputPort("payload"))
        sigma = sm.GetOutputPort("allowable_error")
        if not static:
            sigma = builder.AddSystem(ConstantVectorSource([0.0])).get_output_port()
        builder.Connect(sigma, estimator.GetInputPort("allowable_error"))
    builder.Connect(gate.GetOutputPort("sample_valid"), ident.GetInputPort("sample_valid"))
    connect_identify_observe(builder, ident, sm)
    return PayloadLoop(ident, sm, gate, estimator)
