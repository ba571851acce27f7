"""The thresholds of an identify <-> observe loop, as a scenario section (no pydrake here)."""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import dataclasses

from sustain_drake.identification.coordination import CoordinationRule
from sustain_drake.identification.eye_to_hand import default_criteria
from sustain_drake.identification.sustainable_identifier import ConvergenceCriteria

# The defaults are the math layer's (eye-to-hand criteria, the paper's rule): one place each.
_CRITERIA = default_criteria()
_RULE = CoordinationRule()


@dataclasses.dataclass
class CoordinationConfig:
    """Convergence criteria (paper §3.1 (a)-(c)) and the observation rule (§4.3).

    ``max_expected_rms`` and ``noise_rms`` (the sensor noise's per-sample RMS residual, a floor
    under the expected error that the allowable error is made of; 0: the paper's rule) are in the
    formulation's residual units (metres for eye-to-hand; m/s^2 and N m together for the payload);
    ``max_ssd`` is ignored by formulations without a rotation.
    """

    max_expected_rms: float = _CRITERIA.max_expected_rms
    min_gap_ratio: float = _CRITERIA.min_gap_ratio
    max_ssd: float = _CRITERIA.max_ssd
    min_samples: int = _CRITERIA.min_samples
    forgetting_factor: float = 1.0
    allowable_error_factor: float = _RULE.allowable_error_factor
    max_consecutive_violations: int = _RULE.max_consecutive_violations
    pause_after_convergence: float = _RULE.pause_after_convergence
    noise_rms: float = _RULE.noise_rms
    adopt_refinements: bool = _RULE.adopt_refinements

    def criteria(self, has_rotation: bool = True) -> ConvergenceCriteria:
        return ConvergenceCriteria(
            max_expected_rms=self.max_expected_rms, min_gap_ratio=self.min_gap_ratio,
            max_ssd=self.max_ssd if has_rotation else None, min_samples=self.min_samples,
        )  # fmt: skip

    def rule(self) -> CoordinationRule:
        return CoordinationRule(
            allowable_error_factor=self.allowable_error_factor,
            max_consecutive_violations=self.max_consecutive_violations,
            pause_after_convergence=self.pause_after_convergence,
            noise_rms=self.noise_rms,
            adopt_refinements=self.adopt_refinements,
        )
