"""The ``hand_eye`` scenario section (paper §4.3). No pydrake systems imported here."""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import dataclasses
import typing
from dataclasses import field

from sustain_drake.experiments.coordination_config import CoordinationConfig
from sustain_drake.identification.candidates import CandidateParams
from sustain_drake.perception.camera_motion import CameraMotionParams
from sustain_drake.perception.point_refinement import RefinementParams


def _scenario_mirror(params_class, name: str, doc: str, extra: tuple = ()):
    """A mutable dataclass with the fields, defaults and (resolved) types of the frozen
    ``params_class``, for a scenario section (yaml_load_typed needs real types and a mutable
    dataclass), and ``params()`` to make the params. One list of fields: no defaults to drift.
    ``extra``: more ``(name, type, field)`` fields first (the section's own, not the params')."""
    hints = typing.get_type_hints(params_class)
    names = [f.name for f in dataclasses.fields(params_class)]
    fields = list(extra) + [(n, hints[n], field(default=f.default))
                            for n, f in zip(names, dataclasses.fields(params_class), strict=True)]

    def params(self):
        return params_class(**{n: getattr(self, n) for n in names})

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


CameraMotionConfig = _scenario_mirror(
    CameraMotionParams,
    "CameraMotionConfig",
    "The camera notices its own motion from the static scene (beyond the paper): ``enabled`` adds "
    "a ``CameraMotionDetector`` whose camera moves are change detections; the thresholds: see "
    "``perception.camera_motion.CameraMotionParams`` (px, s, rad/s).",
    extra=(("enabled", bool, field(default=False)),),
)


@dataclasses.dataclass
class HandEyeConfig:
    """Sustainable marker-free hand-eye coordination: identifiers per candidate body feature and
    the identify <-> observe state machine.

    ``camera_motion``: the camera-motion detector (off by default: the paper's observation rule
    alone). ``identifying_motion_interval``: s; > 0: while identifying, ask the babbling for a far
    posture when no confirming request came for that long (``systems.identifying_motion``); 0: off.
    ``identifying_motion_max_hold``: s (at least the interval); after a first convergence, while
    identifying again, the far posture also comes when the arm has stayed within 0.2 rad of one
    posture that long, however often the detector asks. ``identifying_motion_reach``: rad; > 0: the
    postures asked for while the candidates ask for more motion (``candidates.motion_min_samples``,
    ``min_rotation_lever``, ``min_adopt_rotation_spread``) lie within this (max-norm) of the arm's
    posture when the ask began and come after one interval near a posture (0: the far postures of
    the whole ranges, after ``identifying_motion_max_hold``).
    ``refine_points``: feed the candidates the refined points (``FeatureRefiner``: sub-pixel corner
    and robust depth, ``refinement``) instead of the tracker's. ``false_alarm_window``: s, a
    detection with no disturbance in that long before it is a false alarm (evaluation only).
    ``log_rate``: samples per second of the logged signals (plots)."""

    enabled: bool = False
    coordination: CoordinationConfig = field(default_factory=CoordinationConfig)
    candidates: CandidatesConfig = field(default_factory=CandidatesConfig)
    camera_motion: CameraMotionConfig = field(default_factory=CameraMotionConfig)
    identifying_motion_interval: float = 0.0
    identifying_motion_max_hold: float = 3.0
    identifying_motion_reach: float = 0.0
    refine_points: bool = True
    refinement: RefinementConfig = field(default_factory=RefinementConfig)
    false_alarm_window: float = 2.0
    log_rate: float = 30.0
