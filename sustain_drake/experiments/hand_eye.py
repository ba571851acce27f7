"""Sustainable marker-free hand-eye coordination (paper §3.4, §4.3, Figs. 7 and 9).

The loop, from images only (no ground truth inside it)::

    station color/depth -> OpticalFlowTracker -> MotionCoincidenceDetector (confirm -> motion_confirm)
        tracked_features + feature_on_body + X_WH -> CandidateIdentifiers -> CoordinationStateMachine
        state machine: adopted_x -> reference_x, reset -> reset, pause -> motion_pause
        (camera_motion.enabled) tracked_features + feature_on_body + joints -> CameraMotionDetector
            -> state machine camera_motion (a camera move is a change detection), and its
            feature_on_body (the static scene's features cleared) -> CandidateIdentifiers
        (slip_from_wrench) station wrench + sensor_kinematics -> payload loop (dynamic mode) reset
            -> state machine body_changes (the payload's change detection is a slip)

``finish`` evaluates against the station's ground truth (``true_X_WC``, ``true_p_HP``,
``true_X_HT``, logged beside the loop): the time of each convergence and each detection, the error
of each adopted estimate, the latencies after each disturbance, false alarms, the camera and the
tool point in use over time and the wrong adoptions (``hand_eye_metrics``); it draws Fig. 9-like
plots.
"""

from __future__ import annotations

import dataclasses
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.systems.primitives import LogVectorOutput

from sustain_drake.experiments import hand_eye_metrics as m
from sustain_drake.experiments.targets import target_bound
from sustain_drake.files import write_atomically
from sustain_drake.identification import coordination
from sustain_drake.identification.candidates import best_p_HP_given_camera
from sustain_drake.identification.candidates.fitting import REGION_95
from sustain_drake.identification.eye_to_hand import EyeToHandIdentifier
from sustain_drake.identification.rotation import rotation_angle
from sustain_drake.loops.hand_eye import (
    HandEyeParts,
    add_hand_eye_loop,
    connect_wrench_watch,
    hand_eye_parts,
    wrench_watch_config,
)
from sustain_drake.loops.inspection import add_estimate_overlay, add_inspection
from sustain_drake.loops.payload import PayloadLoop, add_payload_loop
from sustain_drake.station import ScenarioError, babbling_joints, camera_info, hand_frame
from sustain_drake.station.scenario import HeadMove, ToolSlip, arm_motion, arm_of, timeline
from sustain_drake.systems.camera_motion_detector import CameraMotionDetector
from sustain_drake.systems.candidate_identifiers import CandidateIdentifiers
from sustain_drake.systems.coordination_state_machine import CoordinationStateMachine
from sustain_drake.systems.depth_noise import DepthNoiseModel
from sustain_drake.systems.exciting_postures import HandKinematics
from sustain_drake.systems.ground_truth import PoseToVector
from sustain_drake.systems.motion_coincidence_detector import MotionCoincidenceDetector
from sustain_drake.systems.motion_generator import Pace
from sustain_drake.systems.optical_flow_tracker import OpticalFlowTracker

# Logged signals: (system key, output port).
_LOGGED = (("candidates", "eigenvalues"), ("candidates", "ssd"), ("candidates", "observation"),
           ("candidates", "expected_mse"), ("state_machine", "mode"), ("state_machine", "allowable_error"),
           ("state_machine", "adopted_x"), ("station", "true_p_HP"))
_POSES = ("true_X_WC", "X_WH", "true_X_HT")


@dataclass
class HandEyeHandle:
    scenario: object
    tracker: OpticalFlowTracker
    detector: MotionCoincidenceDetector
    candidates: CandidateIdentifiers
    state_machine: CoordinationStateMachine
    loggers: dict
    camera_motion: CameraMotionDetector | None = None
    tool_boxes: tuple = ()  # the held tool's geometry in its frame T (``hand_eye_metrics.Box``)
    wrench_watch: PayloadLoop | None = None  # the payload loop watching the held tool (``slip_from_wrench``)


def build_loop(builder, station, scenario, parts: HandEyeParts | None = None):
    """Adds tracker, detector, candidates, state machine (and, if enabled, the camera-motion
    detector) wired to ``station`` (its image, encoder, ``X_WH`` outputs and
    ``motion_confirm``/``motion_pause`` inputs), with the scenario's ``hand_eye`` settings, or with
    ``parts`` as given (a study of the loop's constants). Returns the ``HandEyeLoop``."""
    config, perception = scenario.hand_eye, scenario.body_detection
    if scenario.depth_noise.enabled:  # the loop's sensor model is the station's depth noise
        noise = scenario.depth_noise
        config = dataclasses.replace(config, depth_noise=DepthNoiseModel(noise.a, noise.b, noise.z0))
    settings = hand_eye_parts(config) if parts is None else parts
    if not (station.HasOutputPort("color_image") and station.HasOutputPort("depth_image")):
        raise ScenarioError("hand_eye needs the camera's color and depth images (camera.rgb, camera.depth)")
    try:
        motion = arm_motion(scenario)
        kinematics = None if not config.excite else HandKinematics(
            station.GetSubsystemByName("plant"), hand_frame(station), babbling_joints(station, scenario),
            Pace(motion.max_speed, motion.min_duration, motion.dwell))  # fmt: skip
        loop = add_hand_eye_loop(builder, camera_info(scenario), len(arm_of(scenario).joints),
                                 scenario.camera.fps, settings, perception, motion.joint_ranges,
                                 scenario.motion.seed, kinematics=kinematics)  # fmt: skip
    except ValueError as e:
        raise ScenarioError(f"hand_eye: {e}") from None
    candidates, machine = loop.candidates, loop.state_machine
    for name in ("color_image", "depth_image", "image_time"):
        for port in loop.image_inputs(name):
            builder.Connect(station.GetOutputPort(name), port)
    for port in loop.actuator_inputs():
        builder.Connect(station.GetOutputPort("joint_positions"), port)
    if perception.confirm or config.identifying_motion_interval > 0:
        # The detector's confirming motions (paper §3.3, as in body_detection), with the identifying
        # motion's far postures while identifying.
        builder.Connect(loop.motion_confirm(), station.GetInputPort("motion_confirm"))
    builder.Connect(station.GetOutputPort("X_WH"), candidates.GetInputPort("X_WH"))
    builder.Connect(station.GetOutputPort("X_WL"), candidates.GetInputPort("X_WL"))
    builder.Connect(machine.GetOutputPort("pause"), station.GetInputPort("motion_pause"))
    if config.slip_from_wrench:  # the wrist wrench's payload identification watches the held tool
        loop.wrench_watch = add_wrench_watch(builder, station, machine, len(arm_of(scenario).joints))
    return loop


def add_wrench_watch(builder, station, machine, num_joints: int) -> PayloadLoop:
    """``slip_from_wrench``: a payload loop of ``wrench_watch_config`` on ``station``'s wrist wrench
    (``connect_station_wrench``), its change detections reported to the hand-eye state machine
    ``machine`` (``connect_wrench_watch``). Returns the payload loop."""
    payload = add_payload_loop(builder, num_joints, wrench_watch_config())
    connect_station_wrench(builder, station, payload)
    connect_wrench_watch(builder, machine, payload)
    return payload


def connect_station_wrench(builder, station, payload: PayloadLoop) -> None:
    """The station's wrist wrench, the sensor frame's kinematics and the joint velocities into the
    dynamic-mode payload loop ``payload`` (a ``loops.payload.PayloadLoop``)."""
    builder.Connect(station.GetOutputPort("wrench"), payload.identifier.GetInputPort("wrench"))
    identifier, gate = payload.identifier, payload.gate
    builder.Connect(station.GetOutputPort("sensor_kinematics"), identifier.GetInputPort("kinematics_K"))
    builder.Connect(station.GetOutputPort("joint_velocities"), gate.GetInputPort("joint_velocities"))


def add_to_diagram(builder, station, scenario, meshcat, parts: HandEyeParts | None = None) -> HandEyeHandle:
    loop = build_loop(builder, station, scenario, parts)
    tracker, detector, candidates, machine = loop.tracker, loop.detector, loop.candidates, loop.state_machine
    period = 1.0 / scenario.hand_eye.log_rate
    systems = {"candidates": candidates, "state_machine": machine, "station": station,
               "camera_motion": loop.camera_motion}
    logged = _LOGGED + ((("camera_motion", "camera_motion"),) if loop.camera_motion is not None else ())
    loggers = {port: LogVectorOutput(systems[key].GetOutputPort(port), builder, period)
               for key, port in logged}
    for name in _POSES:
        matrix = builder.AddSystem(PoseToVector())
        matrix.set_name(f"hand_eye_{name}_matrix")
        builder.Connect(station.GetOutputPort(name), matrix.get_input_port())
        loggers[name] = LogVectorOutput(matrix.get_output_port(), builder, period)
    if meshcat is not None:  # the replay shows the estimated camera and followed point beside the truth
        add_estimate_overlay(builder, meshcat, camera_info(scenario), add_inspection(builder, loop, None),
                             station.GetOutputPort("X_WH"), station.GetOutputPort("true_X_WC"))
    return HandEyeHandle(scenario, tracker, detector, candidates, machine, loggers, loop.camera_motion,
                         tool_boxes(station), loop.wrench_watch)


def tool_boxes(station) -> tuple:
    """The held tool's geometry (every geometry of the plant's body ``tool``, whatever its role) as
    oriented bounding boxes in the tool's body frame T (``hand_eye_metrics.Box``); none without a
    tool. Evaluation only: which body an adopted point is on."""
    plant = station.GetSubsystemByName("plant")
    if not plant.HasBodyNamed("tool"):
        return ()
    inspector = station.GetSubsystemByName("scene_graph").model_inspector()
    frame = plant.GetBodyFrameIdOrThrow(plant.GetBodyByName("tool").index())
    boxes = []
    for geometry in inspector.GetGeometries(frame):
        obb = inspector.GetObbInGeometryFrame(geometry)
        if obb is not None:
            X_TB = inspector.GetPoseInFrame(geometry) @ obb.pose()
            boxes.append(m.Box(X_TB.GetAsMatrix4(), np.array(obb.half_width())))
    return tuple(boxes)


# ---- evaluation ------------------------------------------------------------------------------
def _disturbances(scenario) -> list[dict]:
    out = []
    for d in timeline(scenario):
        if isinstance(d, ToolSlip):
            out.append({"kind": "tool_slip", "time_s": d.time})
        elif isinstance(d, HeadMove):
            out.append({"kind": "head_move", "time_s": d.time})
    return sorted(out, key=lambda d: d["time_s"])


# Who saw a change, by its event's detail (any other detail: the observation rule).
_CAUSES = {coordination.CAMERA_MOVED_DETAIL: "camera_motion", coordination.BODY_CHANGED_DETAIL: "wrench"}


def _log(handle, diagram, context, name):
    log = handle.loggers[name].FindLog(context)
    return log.sample_times(), log.data().T


def evaluate(handle, diagram, context) -> dict:
    """The metrics of a run (see the module docstring); pure reading of logs and states."""
    scenario, config = handle.scenario, handle.scenario.hand_eye
    events = handle.state_machine.events(handle.state_machine.GetMyContextFromRoot(context))
    bank = handle.candidates.bank(handle.candidates.GetMyContextFromRoot(context))
    convergences = [e.time for e in events if e.kind == coordination.CONVERGED]
    detections = [e.time for e in events if e.kind == coordination.CHANGE_DETECTED]
    # Who saw each change: the observation rule (Eq. (2) errors), the camera's own motion or the wrench.
    causes = {e.time: _CAUSES.get(e.detail, "observation")
              for e in events if e.kind == coordination.CHANGE_DETECTED}
    t_pose, X_WC_log = _log(handle, diagram, context, "true_X_WC")
    _, X_HT_log = _log(handle, diagram, context, "true_X_HT")
    _, p_HP_log = _log(handle, diagram, context, "true_p_HP")
    rule_config = hand_eye_parts(config).coordination
    criteria = rule_config.criteria()
    points = _followed_points(handle, diagram, context)

    adopted = []
    for k, t in enumerate(convergences):
        if k >= len(bank.adoptions):
            break
        a = bank.adoptions[k]
        identifier = EyeToHandIdentifier(rule_config.forgetting_factor, criteria)
        identifier.set_state(a.statistic)
        est = a.estimate
        X_WC = m.at(t_pose, X_WC_log, t).reshape(4, 4)
        p_true = best_p_HP_given_camera(a.statistic, X_WC[:3, :3], X_WC[:3, 3])
        tool_tip = m.at(t_pose, p_HP_log, t)  # the held tool's tracked_point (any tool.model)
        point = points[k]  # the physical point this model follows: on the tool or on the hand
        p_point = point.p_HP(m.at(t_pose, X_HT_log, t).reshape(4, 4))
        adopted.append({
            "time_s": t, "feature_id": a.feature_id, "kind": a.kind, "candidate_found_s": a.admitted,
            "round_start_s": a.round_start, "num_samples": identifier.num_samples,
            "camera_position_error_mm": 1e3 * float(np.linalg.norm(est.p_WC - X_WC[:3, 3])),
            # Along the optical axis (+: the estimate is in front of the true camera) and across it:
            # a depth camera sees the near surface of the tool, not the tracked corner's axis.
            "camera_position_error_along_axis_mm": 1e3 * float((est.p_WC - X_WC[:3, 3]) @ X_WC[:3, 2]),
            "camera_rotation_error_deg": math.degrees(rotation_angle(est.R_WC.T @ X_WC[:3, :3])),
            "tool_point_error_mm": 1e3 * float(np.linalg.norm(est.p_HP - p_true)),
            "tool_point_distance_to_rod_tip_mm": 1e3 * float(np.linalg.norm(est.p_HP - tool_tip)),
            "body": point.body,
            "distance_to_tool_mm": (1e3 * point.distance_to_tool if math.isfinite(point.distance_to_tool)
                                    else None),
            "true_point_error_mm": 1e3 * float(np.linalg.norm(est.p_HP - p_point)),
            "expected_rms_mm": 1e3 * math.sqrt(max(est.mean_squared_error, 0.0)),
            # How well the points' views pinned the camera's rotation (identified adoptions only).
            "rotation_lever_mm": 1e3 * a.rotation_lever if math.isfinite(a.rotation_lever) else None,
            # The camera's own 95 % region when adopted (None where its fit gives no covariance):
            # whether it holds the true error is the verdict's honesty on this scene.
            **_region_95(a.camera_sd),
            # The adopted point's own identification (the paper's one point), beside the adopted
            # estimate (whose camera may be refined with other points: CandidateParams.joint).
            **_single_point_errors(identifier, X_WC),
        })  # fmt: skip

    disturbances = _disturbances(scenario)
    for d in disturbances:
        after = [t for t in detections if t >= d["time_s"]]
        nxt = [x["time_s"] for x in disturbances if x["time_s"] > d["time_s"]]
        limit = nxt[0] if nxt else math.inf
        d["detected_s"] = after[0] if after and after[0] < limit else None
        d["detection_latency_s"] = None if d["detected_s"] is None else d["detected_s"] - d["time_s"]
        d["detected_by"] = None if d["detected_s"] is None else causes[d["detected_s"]]
        reconv = [t for t in convergences if d["detected_s"] is not None and t > d["detected_s"]]
        d["reconverged_s"] = reconv[0] if reconv else None
        d["reconvergence_after_detection_s"] = None if not reconv else reconv[0] - d["detected_s"]
    # The model in use (adopted, and refined while observing when the rule adopts refinements)
    # just before each disturbance and at the end: what the robot works with.
    t_x, x_log = _log(handle, diagram, context, "adopted_x")
    observing = _observing(handle, diagram, context, t_x)
    for d in disturbances:
        d["model_in_use_before"] = m.camera_errors(t_x, x_log, t_pose, X_WC_log, d["time_s"] - 0.1)
    # The worst camera and tool point the loop relied on, outside each change's window from the
    # disturbance to its detection (the model is stale there by definition); a change never
    # detected excuses only the detection target's time after it.
    windows = m.excused_windows(disturbances, target_bound("hand_eye", "detection_latency_s"))
    worst = m.worst_model_in_use(t_x, x_log, observing, t_pose, X_WC_log, windows)
    t_tool, tool = _tool_point_series(handle, diagram, context, points)
    later = m.before_next(t_tool, tool, disturbances, float(t_tool[-1]))
    for d, at_later in zip(disturbances, later, strict=True):
        d["tool_point_in_use_before_next"] = at_later
    # The camera and tool point adopted at each re-convergence (what the loop settled on).
    for d, settled in zip(disturbances, m.adopted_after(disturbances, adopted), strict=True):
        d["adopted_after"] = settled
    refinements = [e.time for e in events if e.kind == coordination.REFINED]
    false_alarms = [t for t in detections
                    if not any(0.0 <= t - d["time_s"] <= config.false_alarm_window for d in disturbances)]
    first = adopted[0] if adopted else None
    wrong = m.wrong_adoptions(adopted)
    return {
        "convergence_times_s": convergences,
        "detection_times_s": detections,
        "detection_causes": [causes[t] for t in detections],
        "camera_moves_s": _camera_moves(handle, diagram, context),
        "adopted": adopted,
        "disturbances": disturbances,
        "false_alarms_s": false_alarms,
        "num_false_alarms": len(false_alarms),
        # From the run's first candidate (a reset before the first convergence does not restart it).
        "first_convergence_after_found_s": (
            None if first is None else first["time_s"] - bank.first_found),
        "first_convergence_after_adopted_feature_found_s": (
            None if first is None else first["time_s"] - first["candidate_found_s"]),
        "observed_fraction": _observed_fraction(handle, diagram, context),
        "refinement_times_s": refinements,
        "model_in_use_at_end": m.camera_errors(t_x, x_log, t_pose, X_WC_log, float(t_x[-1])),
        "model_in_use_worst": worst,
        "tool_point_in_use_worst": m.worst_tool_point(t_tool, tool, windows),
        "tool_point_in_use_worst_including_windows": m.worst_tool_point(t_tool, tool, []),
        "tool_point_in_use_at_end": m.tool_point_at(t_tool, tool, float(t_tool[-1])),
        "wrong_adoptions": wrong,
        "num_wrong_adoptions": len(wrong),
        "wrench_watch_events": _watch_events(handle, context),
    }


def _watch_events(handle, context) -> list[dict] | None:
    """The payload loop's events (``slip_from_wrench``; None without it): when it identified the held
    tool and when it saw the tool change."""
    if handle.wrench_watch is None:
        return None
    machine = handle.wrench_watch.state_machine
    return [{"time_s": e.time, "kind": e.kind, "detail": e.detail}
            for e in machine.events(machine.GetMyContextFromRoot(context))]


def _followed_points(handle, diagram, context) -> list[m.FollowedPoint]:
    """The physical point each adoption (a CONVERGED event and its ``bank.adoptions`` entry)
    follows: the point whose ``p_HP`` best explains the adopted statistic under the TRUE camera at
    the adoption, kept on the held tool or the hand (``hand_eye_metrics.followed_point``)."""
    events = handle.state_machine.events(handle.state_machine.GetMyContextFromRoot(context))
    adoptions = handle.candidates.bank(handle.candidates.GetMyContextFromRoot(context)).adoptions
    convergences = [e.time for e in events if e.kind == coordination.CONVERGED]
    t_pose, X_WC_log = _log(handle, diagram, context, "true_X_WC")
    _, X_HT_log = _log(handle, diagram, context, "true_X_HT")
    points = []
    for t, a in zip(convergences, adoptions, strict=False):
        X_WC = m.at(t_pose, X_WC_log, t).reshape(4, 4)
        p_HP = best_p_HP_given_camera(a.statistic, X_WC[:3, :3], X_WC[:3, 3])
        points.append(m.followed_point(t, p_HP, m.at(t_pose, X_HT_log, t).reshape(4, 4), handle.tool_boxes))
    return points


def _tool_point_series(handle, diagram, context, points) -> tuple[np.ndarray, np.ndarray]:
    """The log's times and, at each, the error (m) of the tool point in use (NaN: none in use;
    ``hand_eye_metrics.tool_point_errors``)."""
    t_x, x_log = _log(handle, diagram, context, "adopted_x")
    t_pose, X_HT_log = _log(handle, diagram, context, "true_X_HT")
    return t_x, m.tool_point_errors(t_x, x_log, _observing(handle, diagram, context, t_x), t_pose, X_HT_log,
                                    points)


def _observing(handle, diagram, context, times) -> np.ndarray:
    """Per time of ``times``: the state machine observes (a model is vouched for)."""
    t_mode, mode = _log(handle, diagram, context, "mode")
    return np.array([m.at(t_mode, mode, t)[0] == coordination.OBSERVE for t in times], dtype=bool)


def _camera_moves(handle, diagram, context) -> list[float] | None:
    """When the camera-motion detector declared each camera move (None without the detector)."""
    if handle.camera_motion is None:
        return None
    times, data = _log(handle, diagram, context, "camera_motion")
    return [float(t) for t in times[1:][np.diff(data[:, 1]) > 0]]


def _region_95(sd) -> dict:
    """The adopted camera's 95 % region, ``fitting.REGION_95`` times its 1 sd (mm, deg; None
    without one)."""
    if sd is None:
        return {"camera_region_95_mm": None, "camera_region_95_deg": None}
    return {"camera_region_95_mm": 1e3 * REGION_95 * sd[0],
            "camera_region_95_deg": math.degrees(REGION_95 * sd[1])}


def _single_point_errors(identifier: EyeToHandIdentifier, X_WC: np.ndarray) -> dict:
    single = identifier.solve().estimate
    if single is None:
        return {}
    R_WC, p_WC = X_WC[:3, :3], X_WC[:3, 3]
    return {"single_point_camera_position_error_mm": 1e3 * float(np.linalg.norm(single.p_WC - p_WC)),
            "single_point_camera_rotation_error_deg": math.degrees(rotation_angle(single.R_WC.T @ R_WC))}


def _observed_fraction(handle, diagram, context) -> float | None:
    """Of the log samples in OBSERVE, the fraction with a new observation since the previous one
    (the adopted point was seen and measured)."""
    times, mode = _log(handle, diagram, context, "mode")
    _, observation = _log(handle, diagram, context, "observation")
    observing = mode[1:, 0] == coordination.OBSERVE
    if not observing.any():
        return None
    new = np.diff(observation[:, 0]) > 0
    return float(new[observing].mean())


def plot(handle, diagram, context, metrics, path: Path) -> None:
    """Paper Fig. 9: lambda_13..16, SSD, and s_t against the allowable error, the mode shaded; below
    them the errors of the model in use over time (the camera's, and the tool point's against the
    physical point it follows)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t, eig = _log(handle, diagram, context, "eigenvalues")
    _, ssd = _log(handle, diagram, context, "ssd")
    _, observation = _log(handle, diagram, context, "observation")
    _, sigma = _log(handle, diagram, context, "allowable_error")
    _, mode = _log(handle, diagram, context, "mode")
    fig, axes = plt.subplots(4, 1, figsize=(10, 10.5), sharex=True)
    for k in range(12, 16):
        axes[0].semilogy(t, np.maximum(eig[:, k], 1e-16), label=f"$\\lambda_{{{k + 1}}}$")
    axes[0].set_ylabel("eigenvalues")
    axes[0].legend(loc="upper right", ncol=4, fontsize=8)
    axes[1].semilogy(t, np.where(np.isfinite(ssd[:, 0]), ssd[:, 0], np.nan), color="k")
    axes[1].axhline(hand_eye_parts(handle.scenario.hand_eye).coordination.max_ssd, color="r", ls="--", lw=0.8)
    axes[1].set_ylabel("SSD")
    observing = mode[:, 0] == coordination.OBSERVE
    # Only the logged samples with a new observation (the observed point was seen since the last).
    new = np.concatenate([[False], np.diff(observation[:, 0]) > 0])
    s_t = np.where(observing & new & np.isfinite(observation[:, 1]), observation[:, 1], np.nan)
    # s_t = 0: a frame with only the depth check, which saw the tool where the model puts it.
    axes[2].semilogy(t, np.maximum(s_t, 1e-9), ".", ms=1.5, label="$s_t$ (m$^2$; 0 drawn at 1e-9)")
    axes[2].semilogy(t, np.where(observing, sigma[:, 0], np.nan), "r", lw=1, label="allowable error")
    axes[2].set_ylabel("error")
    axes[2].legend(loc="upper right", fontsize=8)
    _plot_in_use(axes[3], handle, diagram, context)
    for ax in axes:
        _shade(ax, t, observing)
        for d in metrics["disturbances"]:
            ax.axvline(d["time_s"], color="m", lw=1)
        for c in metrics["convergence_times_s"]:
            ax.axvline(c, color="g", lw=0.8, ls=":")
        for c in metrics["detection_times_s"]:
            ax.axvline(c, color="r", lw=0.8, ls=":")
    axes[3].set_xlabel("time (s): OBSERVE shaded; disturbance magenta, convergence green, detection red")
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    plt.close(fig)
    write_atomically(path, buffer.getvalue())


def _plot_in_use(ax, handle, diagram, context) -> None:
    """The camera in use (position mm, rotation deg on the right axis) and the tool point in use
    (mm) over time, against the 2 mm target."""
    t_x, tool = _tool_point_series(handle, diagram, context, _followed_points(handle, diagram, context))
    _, x_log = _log(handle, diagram, context, "adopted_x")
    t_pose, X_WC_log = _log(handle, diagram, context, "true_X_WC")
    camera = [m.camera_errors(t_x, x_log, t_pose, X_WC_log, float(t)) or {} for t in t_x]
    position = np.array([e.get("camera_position_error_mm", np.nan) for e in camera])
    rotation = np.array([e.get("camera_rotation_error_deg", np.nan) for e in camera])
    ax.semilogy(t_x, position, "b", lw=1, label="camera position in use (mm)")
    ax.semilogy(t_x, 1e3 * tool, "darkorange", lw=1.2, label="tool point in use (mm)")
    ax.axhline(2.0, color="r", ls="--", lw=0.8)
    ax.set_ylabel("error in use (mm)")
    ax.legend(loc="upper left", fontsize=8)
    right = ax.twinx()
    right.semilogy(t_x, rotation, "c", lw=0.8, ls="--", label="camera rotation in use (deg)")
    right.set_ylabel("deg")
    right.legend(loc="upper right", fontsize=8)


def _shade(ax, t, on) -> None:
    edges = np.flatnonzero(np.diff(np.concatenate([[0], on.astype(int), [0]])))
    for start, stop in zip(edges[::2], edges[1::2], strict=True):
        ax.axvspan(t[start], t[min(stop, len(t) - 1)], color="0.85", lw=0)


def finish(handle, diagram, context, out_dir) -> dict:
    metrics = evaluate(handle, diagram, context)
    out_dir = Path(out_dir)
    plot(handle, diagram, context, metrics, out_dir / "hand_eye_fig9.png")
    metrics["plot"] = "hand_eye_fig9.png"
    return metrics
