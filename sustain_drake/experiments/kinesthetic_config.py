"""The ``kinesthetic`` scenario section (paper §4.4). No pydrake systems imported here."""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import dataclasses
from dataclasses import field

from sustain_drake.experiments.coordination_config import CoordinationConfig


def _payload_coordination() -> CoordinationConfig:
    # The payload's residual rows are m/s^2 and N m; 0.3 is about 3 % of g.
    return CoordinationConfig(max_expected_rms=0.3)


@dataclasses.dataclass
class KinestheticConfig:
    """Payload identification from the wrist wrench and touch estimation on the held object."""

    enabled: bool = False
    coordination: CoordinationConfig = field(default_factory=_payload_coordination)
