"""The ``kinesthetic`` scenario section (paper §4.4). No pydrake systems imported here."""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import dataclasses
from dataclasses import field

from sustain_drake.experiments.coordination_config import CoordinationConfig


def _payload_coordination() -> CoordinationConfig:
    # The payload's residual rows are m/s^2 and N m; 0.3 is about 3 % of g.
    return CoordinationConfig(max_expected_rms=0.3)


@dataclasses.dataclass
class QuasiStaticConfig:
    """When a wrench sample is quasi-static (see ``QuasiStaticGate``): joint speeds and
    accelerations below the limits for ``window`` s, and no touch for ``touch_holdoff`` s (a
    touch lasting over ``max_touch_duration`` s counts as a change of the body)."""

    max_joint_speed: float = 0.02  # rad/s
    max_joint_acceleration: float = 0.05  # rad/s^2
    window: float = 0.2  # s
    touch_holdoff: float = 0.5  # s
    max_touch_duration: float = 20.0  # s


@dataclasses.dataclass
class KinestheticConfig:
    """Payload identification from the wrist wrench and touch estimation on the held object."""

    enabled: bool = False
    coordination: CoordinationConfig = field(default_factory=_payload_coordination)
    # s between identifier / state-machine updates (the sensor's 100 Hz).
    period: float = 0.01
    quasi_static: QuasiStaticConfig = field(default_factory=QuasiStaticConfig)
    # A touch also needs a residual force of at least this (N): about twice the largest residual
    # of free motion at 1 rad/s in inertia_touch.yaml (1.1 N, the payload's inertial wrench), so
    # free motion is not a touch.
    min_touch_force: float = 2.0
    # Touch points are scored against the true contacts whose force is at least this (N).
    eval_min_force: float = 5.0
