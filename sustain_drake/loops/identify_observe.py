"""The identify <-> observe loop (paper §3.1, §4.3): its thresholds as a scenario section, and the
wiring between an identifier system and its state machine."""

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

    Errors are in the formulation's residual units: m for eye-to-hand; m/s^2 and N m together for
    the payload.
    """

    # (a) most expected per-sample RMS error sqrt(a^2 lambda_N): 10 mm for eye-to-hand
    max_expected_rms: float = _CRITERIA.max_expected_rms
    # (b) least lambda_{N-1} / lambda_N: a one-dimensional null space, rich enough motion
    min_gap_ratio: float = _CRITERIA.min_gap_ratio
    # (c) most Challis SSD of the rotation (paper: 0.1); formulations without a rotation ignore it
    max_ssd: float = _CRITERIA.max_ssd
    # count: fewer samples never converge (as many equations as unknowns fit exactly)
    min_samples: int = _CRITERIA.min_samples
    # in (0, 1]: each new sample first scales the statistic by this; 1: the paper's mean
    forgetting_factor: float = 1.0
    # allowable error sigma = factor * max(a^2 lambda_N, noise_rms^2) (paper: 100)
    allowable_error_factor: float = _RULE.allowable_error_factor
    # count: consecutive samples over sigma that are a change (paper: 10)
    max_consecutive_violations: int = _RULE.max_consecutive_violations
    # s the motion pauses after a convergence (paper: 3 s)
    pause_after_convergence: float = _RULE.pause_after_convergence
    # per-sample RMS residual of the sensor's noise alone, a floor under the expected error; 0: none
    noise_rms: float = _RULE.noise_rms
    # in OBSERVE, adopt the identifier's refinements of the model; False: the paper's fixed model
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


def connect_identify_observe(builder, identifier, machine) -> None:
    """Closes the identify <-> observe loop (§3.1, §4.3) between an identifier system
    (``SustainableIdentifierSystem`` or ``CandidateIdentifiers``) and a
    ``CoordinationStateMachine``: the solution and each sample's error go to the machine; the
    adopted estimate (under which the errors are computed), the reset count and, where the identifier
    takes it, the reset's reason come back."""
    builder.Connect(identifier.GetOutputPort("solution"), machine.GetInputPort("solution"))
    builder.Connect(identifier.GetOutputPort("observation"), machine.GetInputPort("observation"))
    builder.Connect(machine.GetOutputPort("adopted_x"), identifier.GetInputPort("reference_x"))
    builder.Connect(machine.GetOutputPort("reset"), identifier.GetInputPort("reset"))
    if identifier.HasInputPort("reset_reason"):  # the candidates keep a camera the body changed under
        builder.Connect(machine.GetOutputPort("reset_reason"), identifier.GetInputPort("reset_reason"))
