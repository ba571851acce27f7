"""Kinesthetic coordination (paper §3.5, §4.4): the held object's mass and centre of mass (and, in the
dynamic mode, its rotational inertia and the sensor's bias) from the wrist wrench, decided by the
identify <-> observe loop, then touches estimated on it. The adopted payload is written as
``payload.yaml`` (``calibration_export.payload_yaml``).

The loop: ``QuasiStaticGate`` (joint encoders, touch flag) -> ``sample_valid`` of a
``SustainableIdentifierSystem`` with the ``PayloadFormulation`` (station ``wrench`` and the sensor
pose ``X_WH``, K = H) <-> ``CoordinationStateMachine`` (convergence and the observation rule from
the scenario's ``CoordinationConfig``, exactly as for hand-eye); its ``pause`` pauses the
babbling after convergence. The adopted payload and allowable error go to a ``TouchEstimator``
whose shape is the held tool's collision geometry, read from the SceneGraph. Its touch flag feeds
the station's touching program (the "keep touching" rule) and keeps touched samples out of the
identifier (see ``QuasiStaticGate``); the mode (OBSERVE) starts the touching program.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, VectorLogSink

from sustain_drake.calibration_export import CalibrationExportError, payload_yaml
from sustain_drake.files import write_atomically
from sustain_drake.identification import coordination, payload, payload_dynamic
from sustain_drake.identification.payload_dynamic import DynamicPayloadSolution
from sustain_drake.loops.payload import add_payload_loop
from sustain_drake.station import (
    babbling_joints,
    babbling_ranges,
    held_shape,
    sensor_frame,
    sensor_pose_in_hand,
)
from sustain_drake.station.scenario import arm_motion, arm_of
from sustain_drake.systems.coordination_state_machine import CoordinationStateMachine
from sustain_drake.systems.exciting_postures import Clearance, ExcitingPostures
from sustain_drake.systems.motion_generator import Pace
from sustain_drake.systems.sustainable_identifier_system import SustainableIdentifierSystem
from sustain_drake.systems.touch_estimator import TouchEstimator

# m: how near the held tool a chosen move may bring anything else (``exciting_postures.PATH_CHECK_STEP``'s
# 2 cm between checks).
EXCITE_CLEARANCE = 0.02


@dataclass
class KinestheticHandle:
    """What ``finish`` needs: the systems and their loggers."""

    identifier: SustainableIdentifierSystem
    state_machine: CoordinationStateMachine
    estimator: TouchEstimator
    loggers: dict[str, VectorLogSink]
    eval_min_force: float
    true_bias: np.ndarray  # the wrench sensor's bias [b_tau; b_f] (the dynamic mode identifies it)


def add_to_diagram(builder: DiagramBuilder, station, scenario, meshcat=None) -> KinestheticHandle:
    config = scenario.kinesthetic
    if scenario.tool.model == "none":
        raise ValueError("kinesthetic: the scenario holds no tool")
    if not sensor_pose_in_hand(station).IsExactlyIdentity():
        raise ValueError("kinesthetic: the sensor frame K must be the hand frame H (X_WH is used as X_WK)")
    shape, X_KG = held_shape(station)
    loop = add_payload_loop(builder, len(arm_of(scenario).joints), config, shape, X_KG)
    ident, sm, gate, estimator = loop.identifier, loop.state_machine, loop.gate, loop.estimator

    wrench, X_WK = station.GetOutputPort("wrench"), station.GetOutputPort("X_WH")  # K = H
    for system in (ident, estimator):
        builder.Connect(wrench, system.GetInputPort("wrench"))
    builder.Connect(X_WK, estimator.GetInputPort("X_WK"))
    # The sensor frame's kinematics from the plant, at the wrench's instants: the touch estimator
    # predicts the moving payload's wrench, and the dynamic mode identifies from it.
    kinematics = station.GetOutputPort("sensor_kinematics")
    builder.Connect(kinematics, estimator.GetInputPort("kinematics_K"))
    dynamic = config.mode == "dynamic"
    if dynamic:
        builder.Connect(kinematics, ident.GetInputPort("kinematics_K"))
    else:
        builder.Connect(X_WK, ident.GetInputPort("X_WK"))
    builder.Connect(station.GetOutputPort("joint_velocities"), gate.GetInputPort("joint_velocities"))
    builder.Connect(sm.GetOutputPort("pause"), station.GetInputPort("motion_pause"))
    if config.excite:
        add_exciting_postures(builder, station, scenario, ident)
    if station.HasInputPort("touch_start"):
        builder.Connect(sm.GetOutputPort("mode"), station.GetInputPort("touch_start"))
        builder.Connect(estimator.GetOutputPort("touch"), station.GetInputPort("touch_feedback"))

    period = config.period
    sources = {
        "eigenvalues": ident.GetOutputPort("eigenvalues"), "mode": sm.GetOutputPort("mode"),
        "sample_valid": gate.GetOutputPort("sample_valid"), "touch": estimator.GetOutputPort("touch"),
        "p_WP": estimator.GetOutputPort("p_WP"), "f_env_W": estimator.GetOutputPort("f_env_W"),
        "residual_wrench": estimator.GetOutputPort("residual_wrench"),
        "true_contact": station.GetOutputPort("true_contact"),
        "true_tool_mass": station.GetOutputPort("true_tool_mass"),
        "true_p_KCm": station.GetOutputPort("true_p_KCm"),
        "true_touch": station.GetOutputPort("true_touch"),
        "true_outboard_inertia": station.GetOutputPort("true_outboard_inertia"),
    }  # fmt: skip
    if station.HasOutputPort("touch_phase"):
        sources["touch_phase"] = station.GetOutputPort("touch_phase")
    loggers = {name: LogVectorOutput(port, builder, period) for name, port in sources.items()}
    return KinestheticHandle(ident, sm, estimator, loggers, config.eval_min_force,
                             np.array(scenario.wrench_sensor.bias, dtype=float))


def add_exciting_postures(builder: DiagramBuilder, station, scenario, ident) -> ExcitingPostures:
    """The babbling's next posture from the payload identifier's statistic (``kinesthetic.excite``):
    in the static mode each rest gives the quasi-static samples of ``motion.dwell`` less the gate's
    ``window``; in the dynamic mode every sample of the move counts (``MoveInformation``). No chosen
    move brings the held tool within ``EXCITE_CLEARANCE`` of anything it could touch (the table, the
    arm's pedestal): its samples would then be contact, not weight."""
    m, config = arm_motion(scenario), scenario.kinesthetic
    plant = station.GetSubsystemByName("plant")
    joints = babbling_joints(station, scenario)
    if config.mode == "dynamic":
        information = payload_dynamic.MoveInformation(config.dynamic.torque_length)
    else:
        rest_samples = max(m.dwell - config.quasi_static.window, config.period) / config.period
        information = payload.PostureInformation(ident.formulation.gravity_W, rest_samples)
    tool = frozenset(plant.GetCollisionGeometriesForBody(plant.GetBodyByName("tool")))
    clearance = Clearance(station, tool, EXCITE_CLEARANCE)
    chooser = builder.AddSystem(ExcitingPostures(
        plant, sensor_frame(station), joints, babbling_ranges(scenario, joints),
        Pace(m.max_speed, m.min_duration, m.dwell), information, clearance, seed=m.seed,
        rate=1.0 / config.period))  # fmt: skip
    chooser.set_name("exciting_postures")
    builder.Connect(ident.GetOutputPort("statistic"), chooser.GetInputPort("statistic"))
    builder.Connect(station.GetOutputPort("joint_positions"), chooser.GetInputPort("joint_positions"))
    builder.Connect(chooser.GetOutputPort("goal"), station.GetInputPort("motion_goal"))
    return chooser


def _logs(handle: KinestheticHandle, context):
    out = {}
    for name, logger in handle.loggers.items():
        log = logger.FindLog(context)
        out.setdefault("time", log.sample_times())
        out[name] = log.data().T
    return out


def touch_errors(logs: dict, min_force: float) -> dict:
    """Touch-point errors (mm) where the estimator declares a touch and the true contact force
    is at least ``min_force``; false touches (declared with no real or applied contact) and
    strong contacts missed, in samples."""
    touch = logs["touch"][:, 0] > 0.5
    truth = logs["true_contact"]
    contact = truth[:, 0] > 0.5
    strong = contact & (np.linalg.norm(truth[:, 4:7], axis=1) >= min_force)
    pushed = logs["true_touch"][:, 0] > 0.5  # applied (finger) forces are not contacts
    scored = touch & strong
    errors = 1000.0 * np.linalg.norm(logs["p_WP"][scored] - truth[scored, 1:4], axis=1)
    # Free motion after the identification: the residual force the touch threshold must clear.
    free = ~contact & ~pushed & (logs["mode"][:, 0] > 0.5)
    residual = np.linalg.norm(logs["residual_wrench"][free, 3:6], axis=1)
    return {
        "samples_scored": int(scored.sum()),
        "median_mm": float(np.median(errors)) if errors.size else None,
        "max_mm": float(np.max(errors)) if errors.size else None,
        "p90_mm": float(np.percentile(errors, 90)) if errors.size else None,
        "false_touch_samples": int((touch & ~contact & ~pushed).sum()),
        "missed_strong_contact_samples": int((strong & ~touch).sum()),
        "strong_contact_samples": int(strong.sum()),
        "free_motion_max_residual_force_N": float(residual.max()) if residual.size else None,
    }


def finish(handle: KinestheticHandle, diagram, context, out_dir) -> dict:
    out_dir = Path(out_dir)
    sm_context = handle.state_machine.GetMyContextFromRoot(context)
    events = handle.state_machine.events(sm_context)
    logs = _logs(handle, context)
    t = logs["time"]
    converged = [e for e in events if e.kind == coordination.CONVERGED]
    metrics = {
        "events": [{"time_s": e.time, "kind": e.kind, "detail": e.detail} for e in events],
        "identification_time_s": converged[0].time if converged else None,
        "change_detections": sum(e.kind == coordination.CHANGE_DETECTED for e in events),
    }
    adopted = handle.state_machine.GetOutputPort("adopted_solution").Eval(sm_context)
    final = handle.identifier.solution(handle.identifier.GetMyContextFromRoot(context))
    if converged and adopted is not None:
        k = min(int(np.searchsorted(t, converged[0].time)), t.size - 1)
        m_true, p_true = float(logs["true_tool_mass"][k, 0]), logs["true_p_KCm"][k]
        if isinstance(adopted, DynamicPayloadSolution):  # the whole outboard body, and the sensor's bias
            metrics["dynamic"] = dynamic_errors(adopted, logs["true_outboard_inertia"][k], handle.true_bias)
            m_true, p_true = metrics["dynamic"]["true_mass_kg"], np.array(metrics["dynamic"]["true_p_KCm_m"])
        metrics.update({
            "mass_kg": adopted.mass, "true_mass_kg": m_true,
            "mass_error_percent": 100.0 * abs(adopted.mass - m_true) / m_true,
            "p_KCm_m": adopted.p_KCm.tolist(), "true_p_KCm_m": p_true.tolist(),
            "com_error_mm": 1000.0 * float(np.linalg.norm(adopted.p_KCm - p_true)),
            "samples_at_convergence": adopted.num_samples,
            "allowable_error": float(
                handle.state_machine.GetOutputPort("allowable_error").Eval(sm_context)[0]),
        })  # fmt: skip
    metrics["final_estimate"] = {
        "converged": final.verdict.converged, "reason": final.verdict.reason, "samples": final.num_samples,
        "mass_kg": final.mass, "p_KCm_m": final.p_KCm.tolist(),
    }  # fmt: skip
    metrics["payload_yaml"] = _write_payload(adopted if converged else None, out_dir)
    metrics["touch"] = touch_errors(logs, handle.eval_min_force)
    if "touch_phase" in logs:
        metrics["touch"]["touches_felt"] = int(logs["touch_phase"][-1, 2])
        metrics["touch"]["touches_missed"] = int(logs["touch_phase"][-1, 3])
    metrics["quasi_static_fraction"] = float(np.mean(logs["sample_valid"][:, 0] > 0.5))
    _plot(logs, converged[0].time if converged else None, handle.eval_min_force, out_dir)
    metrics["figures"] = ["kinesthetic_eigenvalues.png", "kinesthetic_touch_points.png"]
    return _finite(metrics)


def dynamic_errors(adopted: DynamicPayloadSolution, true_phi: np.ndarray, true_bias: np.ndarray) -> dict:
    """The dynamic payload's errors against the outboard body's true inertial parameters ``true_phi``
    (``identification.payload_dynamic``) and the sensor's true bias: the rotational inertia's about
    the centre of mass (spectral norm) in % of its largest principal moment, the bias's largest."""
    m, p, I_Cm = payload_dynamic.central_inertia(true_phi)
    inertia_error = float(np.linalg.norm(adopted.I_Cm_K - I_Cm, 2) / np.linalg.eigvalsh(I_Cm)[-1])
    return {
        "true_mass_kg": m, "true_p_KCm_m": p.tolist(), "I_BBcm": adopted.I_BBcm.tolist(),
        "true_I_BBcm": payload_dynamic.moments_products(I_Cm).tolist(),
        "inertia_error_percent": 100.0 * inertia_error,
        "bias": adopted.bias.tolist(),
        "bias_error_N": float(np.abs(adopted.bias[3:] - true_bias[3:]).max()),
        "bias_error_Nm": float(np.abs(adopted.bias[:3] - true_bias[:3]).max()),
    }  # fmt: skip


def _write_payload(adopted, out_dir: Path) -> str:
    """Writes the adopted payload as ``payload.yaml`` (a spatial inertia about K's origin, in K; with
    the identified rotational inertia in the dynamic mode, a point mass in the static one): its file
    name, or why nothing was written (no payload adopted, or not physically valid: one line)."""
    if adopted is None:
        return "not written: no payload was identified"
    try:
        text = payload_yaml(adopted.mass, adopted.p_KCm, I_BBcm=getattr(adopted, "I_BBcm", None))
    except CalibrationExportError as e:
        return f"not written: {e}"
    write_atomically(out_dir / "payload.yaml", text)
    return "payload.yaml"


def _finite(value):
    """JSON has no NaN or infinity: such numbers become None."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _plot(logs, t_converged, min_force, out_dir: Path) -> None:
    """Fig. 11 of the paper: (A) lambda_2..lambda_5 over time; (B) the touch points in 3-D and
    (b) projected on y-z."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = logs["time"]
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for i in range(1, 5):
        ax.semilogy(t, np.maximum(logs["eigenvalues"][:, i], 1e-12), label=f"$\\lambda_{i + 1}$")
    if t_converged is not None:
        ax.axvline(t_converged, color="k", ls="--", lw=1, label=f"identified {t_converged:.1f} s")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("eigenvalue (conditioned)")
    ax.set_title("(A) payload identification reliability")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    _save(fig, out_dir / "kinesthetic_eigenvalues.png")
    plt.close(fig)

    touch = logs["touch"][:, 0] > 0.5
    truth = logs["true_contact"]
    strong = (truth[:, 0] > 0.5) & (np.linalg.norm(truth[:, 4:7], axis=1) >= min_force)
    est, true = logs["p_WP"][touch], truth[strong, 1:4]
    fig = plt.figure(figsize=(10, 4.5))
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    ax3.scatter(*est.T, s=4, c="r", label="estimated touch")
    ax3.scatter(*true.T, s=10, c="k", marker="x", linewidths=0.5, label=f"true contact (>= {min_force:g} N)")
    ax3.set_xlabel("x [m]")
    ax3.set_ylabel("y [m]")
    ax3.set_zlabel("z [m]")
    ax3.set_title("(B) touch points")
    ax3.legend(fontsize=8)
    ax2 = fig.add_subplot(1, 2, 2)
    ax2.scatter(est[:, 1], est[:, 2], s=4, c="r", label="estimated")
    ax2.scatter(true[:, 1], true[:, 2], s=10, c="k", marker="x", linewidths=0.5, label="true")
    ax2.set_xlabel("y [m]")
    ax2.set_ylabel("z [m]")
    ax2.set_title("(b) projected on y-z (table top: z = 0)")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    _save(fig, out_dir / "kinesthetic_touch_points.png")
    plt.close(fig)


def _save(fig, path: Path) -> None:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=120)
    write_atomically(path, buffer.getvalue())
