"""The ``hand_eye`` scenario section (paper §4.3). No pydrake systems imported here."""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import dataclasses
from dataclasses import field

from sustain_drake.experiments.coordination_config import CoordinationConfig
from sustain_drake.identification.candidates import CandidateParams


@dataclasses.dataclass
class CandidatesConfig:
    """Candidate tracked points (paper Fig. 7): see ``identification.candidates.CandidateParams``
    (SI units)."""

    max_candidates: int = 8
    max_hand_radius: float = 0.6
    gate_margin: float = 0.01
    max_lost_time: float = 2.0
    max_unconverged_time: float = 30.0
    reacquire_radius: float = 0.01
    reject_rms: float = 0.02
    use_body_cells: bool = True
    observation_jump: float = 0.15
    observe_min_samples: int = 100
    observe_consistency: float = 3.0
    primary_failures: int = 10
    keep_camera: bool = True
    confirm_with_witness: bool = True
    min_rotation_spread: float = 0.15

    def params(self) -> CandidateParams:
        return CandidateParams(**dataclasses.asdict(self))


@dataclasses.dataclass
class HandEyeConfig:
    """Sustainable marker-free hand-eye coordination: identifiers per candidate body feature and
    the identify <-> observe state machine.

    ``false_alarm_window``: s, a detection with no disturbance in that long before it is a false
    alarm (evaluation only). ``log_rate``: samples per second of the logged signals (plots)."""

    enabled: bool = False
    coordination: CoordinationConfig = field(default_factory=CoordinationConfig)
    candidates: CandidatesConfig = field(default_factory=CandidatesConfig)
    false_alarm_window: float = 2.0
    log_rate: float = 30.0
