"""The experiments' targets (docs/results.md), checked on a run's ``metrics.json``.

A target reads one figure from an experiment's metrics section; a figure that is a list (one value
per adoption, per disturbance) meets the target when every item does, and an empty list or a
missing figure (never converged, a change never detected) does not. The benches and
``sustain-drake sweep`` check runs with these, so a target is written once.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

OPS = {"<=": lambda v, b: v <= b, ">=": lambda v, b: v >= b, "==": lambda v, b: v == b}


@dataclass(frozen=True)
class Target:
    name: str  # the figure's name, with its unit as a suffix (``_mm``, ``_deg``, ``_s``)
    op: str  # "<=", ">=" or "=="
    bound: float
    read: Callable[[dict], object]  # the experiment's metrics section -> a number, a list or None

    def values(self, section: dict) -> list | None:
        """The figure's values in a run (None: not measured)."""
        value = self.read(section)
        if value is None:
            return None
        return list(value) if isinstance(value, list) else [value]

    def met(self, section: dict) -> bool:
        values = self.values(section)
        return bool(values) and all(v is not None and OPS[self.op](v, self.bound) for v in values)

    def worst(self, section: dict) -> float | None:
        """The value that decides the target (the largest for ``<=``, the smallest for ``>=``, the
        one farthest from the bound for ``==``); None when nothing was measured."""
        values = self.values(section)
        if not values or any(v is None for v in values):
            return None
        if self.op == "<=":
            return float(max(values))
        if self.op == ">=":
            return float(min(values))
        return float(max(values, key=lambda v: abs(v - self.bound)))

    @property
    def text(self) -> str:
        return f"{self.name} {self.op} {self.bound:g}"


def _each(key: str, field: str) -> Callable[[dict], list | None]:
    """One figure per item of the list ``section[key]`` (None where it was not measured)."""
    return lambda section: [item.get(field) for item in section.get(key, [])]


def _field(*keys: str) -> Callable[[dict], object]:
    """``section[k1][k2]...``; None where any level is missing or None."""
    def read(section: dict):
        value = section
        for key in keys:
            if not isinstance(value, dict) or value.get(key) is None:
                return None
            value = value[key]
        return value
    return read


TARGETS: dict[str, tuple[Target, ...]] = {
    # Paper §4.3 and issue 5: every adopted model, the model the robot worked with, the latencies.
    "hand_eye": (
        Target("camera_position_mm", "<=", 2.0, _each("adopted", "camera_position_error_mm")),
        Target("camera_rotation_deg", "<=", 0.2, _each("adopted", "camera_rotation_error_deg")),
        Target("tool_point_mm", "<=", 2.0, _each("adopted", "tool_point_error_mm")),
        # The worst camera in use while a model is adopted, outside a change's disturbance-to-
        # detection window (an undetected change's: to its disturbance + the detection target).
        Target("camera_in_use_position_mm", "<=", 2.0,
               _field("model_in_use_worst", "camera_position_error_mm")),
        Target("camera_in_use_rotation_deg", "<=", 0.2,
               _field("model_in_use_worst", "camera_rotation_error_deg")),
        # The worst tool point in use (the adopted p_HP against the physical point it follows), outside
        # those windows; an undetected change excuses only the detection target's time.
        Target("tool_point_in_use_mm", "<=", 2.0, _field("tool_point_in_use_worst", "error_mm")),
        # Adoptions with a camera > 5 mm or 0.5 deg off, or a tool point > 5 mm off.
        Target("wrong_adoptions", "==", 0, _field("num_wrong_adoptions")),
        Target("first_convergence_after_found_s", "<=", 15.0,
               _field("first_convergence_after_found_s")),
        Target("detection_latency_s", "<=", 1.0, _each("disturbances", "detection_latency_s")),
        Target("reconvergence_after_detection_s", "<=", 15.0,
               _each("disturbances", "reconvergence_after_detection_s")),
        Target("false_alarms", "==", 0, _field("num_false_alarms")),
    ),
    # Paper §4.2 and issue 4.
    "body_detection": (
        Target("precision", ">=", 0.95, _field("precision")),
        Target("recall", ">=", 0.8, _field("recall")),
        Target("distractor_cells_marked", "==", 0, _field("distractor_cells_marked")),
        Target("latency_median_s", "<=", 1.0, _field("latency_median_s")),
    ),
    # Paper §4.4 and issue 6 (a scenario without a payload change: no re-identification).
    "kinesthetic": (
        Target("mass_error_percent", "<=", 1.0, _field("mass_error_percent")),
        Target("com_error_mm", "<=", 2.0, _field("com_error_mm")),
        Target("touch_median_mm", "<=", 5.0, _field("touch", "median_mm")),
        Target("false_touch_samples", "==", 0, _field("touch", "false_touch_samples")),
        Target("change_detections", "==", 0, _field("change_detections")),
    ),
}


def target_bound(experiment: str, name: str) -> float:
    """The bound of ``experiment``'s target ``name`` (e.g. the detection latency that excuses the
    time after an undetected change)."""
    return next(t.bound for t in TARGETS[experiment] if t.name == name)


def check_targets(metrics: dict) -> dict[str, dict]:
    """For each experiment in a run's ``metrics`` (the whole ``metrics.json``) and each of its
    targets: ``{"<experiment>.<target>": {"met": bool, "worst": float | None}}``."""
    out = {}
    for experiment, targets in TARGETS.items():
        section = metrics.get(experiment)
        if not isinstance(section, dict):
            continue
        for target in targets:
            out[f"{experiment}.{target.name}"] = {"met": target.met(section),
                                                  "worst": target.worst(section)}
    return out
