"""The ``body_detection`` scenario section (paper §4.2). No pydrake systems imported here."""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import dataclasses


@dataclasses.dataclass
class BodyDetectionConfig:
    """Body detection by motion coincidence: the tracker, the detector and their evaluation."""

    enabled: bool = False
