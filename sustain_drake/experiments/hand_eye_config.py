"""The ``hand_eye`` scenario section (paper §4.3). No pydrake systems imported here."""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import dataclasses
from dataclasses import field

from sustain_drake.experiments.coordination_config import CoordinationConfig


@dataclasses.dataclass
class HandEyeConfig:
    """Sustainable marker-free hand-eye coordination: identifiers per candidate body feature and
    the identify <-> observe state machine."""

    enabled: bool = False
    coordination: CoordinationConfig = field(default_factory=CoordinationConfig)
