"""The hand-eye run's figures of the model in use, from its logs (pure functions of arrays: no
simulation; ``hand_eye.evaluate`` reads the logs and calls these).

The logged ``adopted_x`` packs ``[R_WC (9, column-major), p_WC, p_HP, 1]``: the camera and the tool
point the robot works with. The camera's truth is the logged ``true_X_WC``. The tool point's truth
is the physical point the adopted model follows (``FollowedPoint``): found at each adoption, kept in
the frame of the body it is on (the held tool T or the hand H), and carried through the logged
``true_X_HT`` over the run, so a tool that slips in the grasp moves it away from the model's
``p_HP``.

A change makes the model stale from its disturbance until the loop detects it: those windows are
excused (``excused_windows``), but an undetected change only for the detection target's time, so
it cannot hide what follows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sustain_drake.identification.rotation import rotation_angle

# A point this close to the held tool's geometry is on the tool (the estimate of a surface point,
# whose depth is measured on the near surface, lies within a few mm of it; a point of the hand a
# tool is pressed against is ambiguous at their junction).
ON_TOOL_MARGIN_M = 5e-3
# A wrong adoption (issue 27): a camera or a tool point this far from the truth.
WRONG_CAMERA_POSITION_MM = 5.0
WRONG_CAMERA_ROTATION_DEG = 0.5
WRONG_TOOL_POINT_MM = 5.0
TOOL, HAND = "tool", "hand"


@dataclass(frozen=True)
class Box:
    """An oriented box fixed in the tool frame T: its pose ``X_TB`` (4x4) and half widths (m)."""

    X_TB: np.ndarray
    half_width: np.ndarray


def distance_to_boxes(p_T: np.ndarray, boxes) -> float:
    """The distance (m) from ``p_T`` (in T) to the nearest box (0 inside; inf without boxes)."""
    distances = []
    for box in boxes:
        X = np.asarray(box.X_TB, dtype=float)
        p_B = X[:3, :3].T @ (np.asarray(p_T, dtype=float) - X[:3, 3])
        distances.append(float(np.linalg.norm(np.maximum(np.abs(p_B) - box.half_width, 0.0))))
    return min(distances, default=math.inf)


@dataclass(frozen=True)
class FollowedPoint:
    """The physical point an adoption follows: on ``body`` (``"tool"`` or ``"hand"``) at ``p_BP``
    in that body's frame (``p_TP`` on the tool, ``p_HP`` on the hand), adopted at ``time``."""

    time: float
    body: str
    p_BP: np.ndarray
    distance_to_tool: float  # m, from the held tool's geometry at the adoption (inf: no tool)

    def p_HP(self, X_HT: np.ndarray) -> np.ndarray:
        """Where the point is in H when the tool is at ``X_HT`` (4x4) in the hand."""
        if self.body == HAND:
            return self.p_BP
        X_HT = np.asarray(X_HT, dtype=float)
        return X_HT[:3, :3] @ self.p_BP + X_HT[:3, 3]


def followed_point(time: float, p_HP: np.ndarray, X_HT: np.ndarray, tool_boxes,
                   margin: float = ON_TOOL_MARGIN_M) -> FollowedPoint:
    """The point at ``p_HP`` (in H, at ``time``, the tool at ``X_HT``) kept on the body it is on: the
    held tool if it is within ``margin`` of the tool's geometry ``tool_boxes`` (in T), else the
    hand."""
    X_HT = np.asarray(X_HT, dtype=float)
    p_HP = np.asarray(p_HP, dtype=float)
    p_TP = X_HT[:3, :3].T @ (p_HP - X_HT[:3, 3])
    distance = distance_to_boxes(p_TP, tool_boxes)
    if distance <= margin:
        return FollowedPoint(float(time), TOOL, p_TP, distance)
    return FollowedPoint(float(time), HAND, p_HP.copy(), distance)


def at(times: np.ndarray, data: np.ndarray, t: float):
    """The logged row at ``t`` (the first sample at or after it; the last one after the log)."""
    return data[min(int(np.searchsorted(times, t - 1e-9)), len(times) - 1)]


def camera_errors(t_x, x_log, t_pose, X_WC_log, t: float) -> dict | None:
    """The camera error of the adopted ``x`` logged at ``t`` (None before any adoption)."""
    x = at(t_x, x_log, t)
    if not np.any(x):
        return None
    X_WC = at(t_pose, X_WC_log, t).reshape(4, 4)
    R_WC, p_WC = x[0:9].reshape(3, 3, order="F"), x[9:12]
    return {"time_s": t, "camera_position_error_mm": 1e3 * float(np.linalg.norm(p_WC - X_WC[:3, 3])),
            "camera_rotation_error_deg": math.degrees(rotation_angle(R_WC.T @ X_WC[:3, :3]))}


def excused_windows(disturbances: list[dict], detection_target: float) -> list[tuple[float, float]]:
    """Per disturbance (``time_s``, ``detected_s``), the window where the model in use is stale by
    definition: to its detection, or, never detected, only to ``detection_target`` s after it
    (the rest of the run counts)."""
    return [(d["time_s"], d["time_s"] + detection_target if d["detected_s"] is None else d["detected_s"])
            for d in disturbances]


def _excused(t: float, windows) -> bool:
    return any(a <= t <= b for a, b in windows)


def worst_model_in_use(t_x, x_log, observing, t_pose, X_WC_log, windows: list) -> dict | None:
    """The largest camera position and rotation errors of the adopted ``x`` over the log, where
    one is adopted, the loop observes (``observing``, per sample: after a detected change it
    identifies and vouches for no model, as ``tool_point_errors``) and outside the ``windows``
    ``(from, to)``, with their times (None: never adopted there)."""
    errors = [camera_errors(t_x, x_log, t_pose, X_WC_log, float(t))
              for t, o in zip(t_x, observing, strict=True) if o and not _excused(t, windows)]
    errors = [e for e in errors if e is not None]
    if not errors:
        return None
    position = max(errors, key=lambda e: e["camera_position_error_mm"])
    rotation = max(errors, key=lambda e: e["camera_rotation_error_deg"])
    return {"camera_position_error_mm": position["camera_position_error_mm"],
            "position_at_s": position["time_s"],
            "camera_rotation_error_deg": rotation["camera_rotation_error_deg"],
            "rotation_at_s": rotation["time_s"]}


def tool_point_errors(t_x, x_log, observing, t_pose, X_HT_log, points: list[FollowedPoint]) -> np.ndarray:
    """Per sample of ``x_log`` (times ``t_x``), the distance (m) from the model's ``p_HP`` to the
    point the latest adoption before the sample follows, where it is; NaN where no tool point is
    in use (nothing adopted, or ``observing`` False: after a detected change the loop identifies
    and vouches for no model). A publish at an adoption's own time sees the state before it, so an
    adoption counts from the next sample on."""
    starts = np.array([p.time for p in points])
    errors = np.full(len(t_x), np.nan)
    for i, t in enumerate(t_x):
        k = int(np.searchsorted(starts, t, side="left")) - 1  # the latest adoption strictly before t
        if k < 0 or not observing[i] or not np.any(x_log[i]):
            continue
        X_HT = at(t_pose, X_HT_log, float(t)).reshape(4, 4)
        errors[i] = float(np.linalg.norm(x_log[i][12:15] - points[k].p_HP(X_HT)))
    return errors


def worst_tool_point(times, errors, windows: list) -> dict | None:
    """The largest tool point error (mm) where a tool point is in use, outside the ``windows``,
    with its time (None: none in use there)."""
    keep = np.isfinite(errors) & np.array([not _excused(t, windows) for t in times], dtype=bool)
    if not keep.any():
        return None
    i = int(np.flatnonzero(keep)[np.argmax(errors[keep])])
    return {"error_mm": 1e3 * float(errors[i]), "at_s": float(times[i])}


def tool_point_at(times, errors, t: float) -> dict | None:
    """The tool point in use's error (mm) at ``t`` (None: no tool point in use then)."""
    error = at(times, errors, t)
    return None if not np.isfinite(error) else {"time_s": float(t), "error_mm": 1e3 * float(error)}


def before_next(times, errors, disturbances: list[dict], end: float, lead: float = 1.0) -> list[dict | None]:
    """Per disturbance, the tool point in use ``lead`` s before the next disturbance (or ``end``):
    what the loop settled on after the change (None: no tool point in use then)."""
    starts = [d["time_s"] for d in disturbances] + [end]
    return [tool_point_at(times, errors, max(starts[k + 1] - lead, starts[k]))
            for k in range(len(disturbances))]


def adopted_after(disturbances: list[dict], adopted: list[dict]) -> list[dict | None]:
    """Per disturbance, the model adopted at its re-convergence (``reconverged_s``): its camera's
    position (mm) and rotation (deg) errors and its tool point's (mm); None when it never re-converged
    (or no adoption is logged at that time)."""
    keys = ("time_s", "camera_position_error_mm", "camera_rotation_error_deg", "tool_point_error_mm")
    by_time = {a["time_s"]: a for a in adopted}
    return [None if d.get("reconverged_s") not in by_time
            else {k: by_time[d["reconverged_s"]].get(k) for k in keys} for d in disturbances]


def wrong_adoptions(adopted: list[dict]) -> list[dict]:
    """The adoptions whose camera is more than ``WRONG_CAMERA_POSITION_MM`` or
    ``WRONG_CAMERA_ROTATION_DEG`` off, or whose tool point (``true_point_error_mm``) is more than
    ``WRONG_TOOL_POINT_MM`` off."""
    keys = ("time_s", "feature_id", "kind", "body", "camera_position_error_mm", "camera_rotation_error_deg",
            "true_point_error_mm")
    return [{k: a.get(k) for k in keys} for a in adopted
            if a["camera_position_error_mm"] > WRONG_CAMERA_POSITION_MM
            or a["camera_rotation_error_deg"] > WRONG_CAMERA_ROTATION_DEG
            or a["true_point_error_mm"] > WRONG_TOOL_POINT_MM]
