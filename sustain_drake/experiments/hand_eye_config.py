"""The ``hand_eye`` scenario section (paper §4.3). No pydrake systems imported here."""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import dataclasses
import typing
from dataclasses import field

from sustain_drake.experiments.coordination_config import CoordinationConfig
from sustain_drake.identification.candidates import CandidateParams
from sustain_drake.perception.point_refinement import RefinementParams


def _scenario_mirror(params_class, name: str, doc: str):
    """A mutable dataclass with the fields, defaults and (resolved) types of the frozen
    ``params_class``, for a scenario section (yaml_load_typed needs real types and a mutable
    dataclass), and ``params()`` to make the params. One list of fields: no defaults to drift."""
    hints = typing.get_type_hints(params_class)
    fields = [(f.name, hints[f.name], field(default=f.default)) for f in dataclasses.fields(params_class)]

    def params(self):
        return params_class(**dataclasses.asdict(self))

    return dataclasses.make_dataclass(name, fields, namespace={"params": params, "__doc__": doc})


CandidatesConfig = _scenario_mirror(
    CandidateParams,
    "CandidatesConfig",
    "Candidate tracked points (paper Fig. 7): see ``identification.candidates.CandidateParams`` "
    "(SI units).",
)


RefinementConfig = _scenario_mirror(
    RefinementParams,
    "RefinementConfig",
    "Drift-free points of the tracked features (sub-pixel corner, robust depth): see "
    "``perception.point_refinement.RefinementParams`` (px, m).",
)


@dataclasses.dataclass
class HandEyeConfig:
    """Sustainable marker-free hand-eye coordination: identifiers per candidate body feature and
    the identify <-> observe state machine.

    ``refine_points``: feed the candidates the refined points (``FeatureRefiner``: sub-pixel
    corner and robust depth, ``refinement``) instead of the tracker's. ``false_alarm_window``: s, a
    detection with no disturbance in that long before it is a false alarm (evaluation only).
    ``log_rate``: samples per second of the logged signals (plots)."""

    enabled: bool = False
    coordination: CoordinationConfig = field(default_factory=CoordinationConfig)
    candidates: CandidatesConfig = field(default_factory=CandidatesConfig)
    refine_points: bool = True
    refinement: RefinementConfig = field(default_factory=RefinementConfig)
    false_alarm_window: float = 2.0
    log_rate: float = 30.0
