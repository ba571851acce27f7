"""Dynamic payload identification against recursive least squares and the static mode (issue 26), every
estimator on the same recorded streams.

    .venv/bin/python bench/bench_payload_dynamic.py [--seeds 11 1 2 3 4] [--duration 12] [--results]
    .venv/bin/python bench/bench_payload_dynamic.py --coverage 100 [--seeds ...] [--results]

One simulation per run of ``diagrams/inertia_touch.yaml`` (the babbling only: its touching program and
its payload loop off; the sensor's gripper compensation off, so the wrench is that of the whole body
outboard of the sensor: gripper, finger and box, 0.9 kg) records, at the sensor's 100 Hz: the wrench,
the sensor frame's kinematics from the plant (``SensorKinematicsFromPlant``) and, as on hardware, from
the joint encoders (``SensorKinematicsFromEncoders``: Savitzky-Golay, the loop's defaults; the
encoders sampled with the wrench), the quasi-static gate's verdicts and the truth. Then, offline on the
same samples, each solved after every sample:

- ``sustainable``: ``DynamicPayloadIdentifier`` (N = 17) with the loop's criteria (the scenario's, with
  the dynamic mode's own gap), on every sample the dynamic gate passes (from 0.2 s on); "identified" is
  its verdict;
- ``sustainable, encoders``: the same on the encoder filter's stream;
- ``RLS``: ``DynamicPayloadRLS`` (forgetting 0.999 per sample: a 10 s memory) on the samples of
  ``sustainable``; "identified" is its covariance within the dynamic verdict's uncertainty bounds;
- ``static``: ``PayloadIdentifier`` (N = 5) on the quasi-static samples, the scenario's criteria.

Runs: the scenario's seeds (``--seeds``) as the station builds them, the same seeds with a rigid grasp
(``rigid``: the finger's and the grip's joints locked; in the station the box sits on stiff but compliant grip
joints and the finger on a 200 N/m servo, so the outboard body is not quite rigid), then ``bias`` (a sensor
bias of [0.015, -0.02, 0.01] N m and [0.4, -0.3, 0.5] N) on the first two seeds, ``fast`` (no rests:
``motion.dwell`` 0, ``max_speed`` 2 rad/s, ``min_duration`` 0.5 s: the issue's targets are for motion without
rests) on every seed, ``fast, bias`` on the first two, and with each move chosen for the information it adds
(``exciting``: ``ExcitingPostures`` with ``MoveInformation``, driven by an online dynamic identifier's
statistic) with rests, without rests, and without rests with the grasp rigid, on every seed. Times are from
the motion's start. Errors are those of the outboard body (what the wrench measures and what is identified) at
the time the estimator says identified; the rotational inertia's is that of the inertia about the centre of
mass (spectral norm) in % of its largest principal moment; "held box's inertia" is the same for the box alone
once the gripper's known parameters are subtracted (a dynamic tool calibration). "Within targets" is when the
estimate enters the targets for good (mass <= 0.5 %, centre of mass <= 1 mm, inertia <= 10 %, bias <= 0.05 N
and 0.002 N m; the static mode: mass and centre of mass only).
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, ZeroOrderHold

sys.path.insert(0, str(Path(__file__).resolve().parent))
from results_page import number, publish  # noqa: E402  (bench/results_page.py)

from sustain_drake.experiments.hand_eye import connect_station_wrench  # noqa: E402
from sustain_drake.experiments.kinesthetic import add_exciting_postures  # noqa: E402
from sustain_drake.identification import payload_dynamic as dynamic  # noqa: E402
from sustain_drake.identification.payload import PayloadIdentifier  # noqa: E402
from sustain_drake.identification.rls import DynamicPayloadRLS  # noqa: E402
from sustain_drake.loops.payload import add_payload_loop, payload_formulation  # noqa: E402
from sustain_drake.station import build_station, load_scenario  # noqa: E402
from sustain_drake.station.scenario import arm_of  # noqa: E402
from sustain_drake.station.scenario_files import with_seed  # noqa: E402
from sustain_drake.systems.ground_truth import PoseToVector  # noqa: E402
from sustain_drake.systems.quasi_static_gate import QuasiStaticGate  # noqa: E402
from sustain_drake.systems.sensor_kinematics import SensorKinematicsFromEncoders  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "diagrams" / "inertia_touch.yaml"
BIAS = (0.015, -0.02, 0.01, 0.4, -0.3, 0.5)  # [b_tau (N m); b_f (N)]
TARGETS = {"mass": 0.5, "com": 1.0, "inertia": 10.0, "bias_f": 0.05, "bias_tau": 0.002}
ESTIMATORS = ("sustainable", "sustainable, encoders", "RLS", "static")
RLS_FORGETTING = 0.999
SEEDS = [11, 1, 2, 3, 4, 5, 6, 7]  # the scenario's seed, then seven more (issue 25: >= 8 seeds)
GRASP_JOINTS = ("gripper_joint", "tool_slide", "tool_pivot")
_LOGGED = ("wrench", "sensor_kinematics", "true_outboard_inertia", "true_tool_inertia", "joint_velocities")


@dataclass
class Run:
    name: str
    seed: int
    bias: tuple = (0.0,) * 6
    fast: bool = False
    rigid: bool = False
    noise_free: bool = False  # the sensor without noise (``coverage`` draws it)
    excite: bool = False  # each move chosen for the information it adds (``ExcitingPostures``)


@dataclass
class Outcome:
    """One estimator on one run: when it said identified (s from the motion's start), its errors
    then, and when its estimate entered the targets for good (None: never)."""

    identified: float | None = None
    errors: dict = field(default_factory=dict)
    within: float | None = None
    reason: str = ""


def scenario_of(run: Run, duration: float):
    scenario = with_seed(load_scenario(SCENARIO), run.seed)
    scenario.duration = duration
    scenario.touch_motion.enabled = False
    scenario.kinesthetic.enabled = False
    scenario.wrench_sensor.compensate_gripper = False
    scenario.wrench_sensor.bias = list(run.bias)
    scenario.kinesthetic.mode = "dynamic"  # what the exciting motion's information is of
    if run.fast:
        scenario.motion.dwell, scenario.motion.max_speed, scenario.motion.min_duration = 0.0, 2.0, 0.5
    if run.noise_free:
        scenario.wrench_sensor.force_noise = scenario.wrench_sensor.torque_noise = 0.0
    return scenario


def coverage(seed: int, draws: int, duration: float = 2.0) -> list[str]:
    """How often the verdict's declared estimate lies outside its accuracy bounds, over ``draws``
    draws of the scenario's white sensor noise added to one noise-free stream of motion without rests
    with the grasp held rigid (so the rigid model is exact and only the noise is random): per bound,
    the draws whose error at declaration exceeds it (a 95 % region should leave about 1 in 20), and
    the draws within every bound."""
    run = Run(f"fast, rigid, seed {seed}", seed, fast=True, rigid=True, noise_free=True)
    streams, sensor = record(run, duration), scenario_of(Run("", seed), duration).wrench_sensor
    sd = np.array([sensor.torque_noise] * 3 + [sensor.force_noise] * 3)
    rng, clean = np.random.default_rng(seed), streams["wrench"]
    outcomes = []
    for _ in range(draws):
        streams["wrench"] = clean + rng.normal(size=clean.shape) * sd
        outcomes.append(evaluate(streams, "sustainable"))
    said = [o for o in outcomes if o.identified is not None]
    misses = {key: sum(o.errors[key] > TARGETS[key] for o in said) for key in TARGETS}
    cells = [run.name, str(draws), str(len(said)), _span([o.identified for o in said], ".2f")]
    cells += [str(misses[key]) for key in TARGETS] + [str(sum(within(o.errors) for o in said))]
    header = ["stream", "noise draws", "identified", "identified (s)", "mass > 0.5 %", "CoM > 1 mm",
              "inertia > 10 %", "bias f > 0.05 N", "bias tau > 0.002 N m", "within every target"]
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header), "| " + " | ".join(cells) + " |"]


def record(run: Run, duration: float) -> dict:
    """Simulates ``run`` and returns its streams sampled at the sensor's instants."""
    scenario = scenario_of(run, duration)
    period = 1.0 / scenario.wrench_sensor.rate
    station = build_station(scenario)
    plant = station.GetSubsystemByName("plant")
    builder = DiagramBuilder()
    builder.AddSystem(station)
    k = scenario.kinesthetic
    joints = [plant.GetJointByName(name) for name in arm_of(scenario).joints]
    qs = k.quasi_static
    gates = {}
    for name, still in (("static_valid", True), ("dynamic_valid", False)):
        gate = builder.AddSystem(QuasiStaticGate(len(joints), period, qs.max_joint_speed,
                                                 qs.max_joint_acceleration, qs.window, require_still=still))
        builder.Connect(station.GetOutputPort("joint_velocities"), gate.GetInputPort("joint_velocities"))
        gates[name] = gate.GetOutputPort("sample_valid")
    # The simulated reaction force is the plant step's, which started one time step before the sample.
    encoders = builder.AddSystem(SensorKinematicsFromEncoders(
        plant, plant.GetJointByName("ft_sensor").frame_on_child(), period, k.dynamic.encoder_window,
        k.dynamic.encoder_order, joints, wrench_delay=plant.time_step()))  # fmt: skip
    # The encoders read at the wrench's instants: the wrench is a sampled sensor, so sample them alike.
    hold = builder.AddSystem(ZeroOrderHold(period, len(joints)))
    builder.Connect(station.GetOutputPort("joint_positions"), hold.get_input_port())
    builder.Connect(hold.get_output_port(), encoders.GetInputPort("joint_positions"))
    builder.Connect(station.GetOutputPort("wrench"), encoders.GetInputPort("wrench"))
    if run.excite:  # the online identifier's statistic chooses the moves
        watch = add_payload_loop(builder, len(joints), k)
        connect_station_wrench(builder, station, watch)
        add_exciting_postures(builder, station, scenario, watch.identifier)
    pose = builder.AddSystem(PoseToVector())
    builder.Connect(station.GetOutputPort("X_WH"), pose.get_input_port())  # K = H in the station
    ports = {name: station.GetOutputPort(name) for name in _LOGGED} | gates | {"X_WK": pose.get_output_port()}
    ports |= {"encoder_kinematics": encoders.GetOutputPort("kinematics_K"),
              "encoder_wrench": encoders.GetOutputPort("wrench_aligned"),
              "encoder_valid": encoders.GetOutputPort("valid")}
    loggers = {name: LogVectorOutput(port, builder, period) for name, port in ports.items()}
    diagram = builder.Build()
    simulator = Simulator(diagram)
    if run.rigid:  # the finger's and the grip's joints locked: the box cannot move in the hand
        plant_context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
        for name in GRASP_JOINTS:
            plant.GetJointByName(name).Lock(plant_context)
    simulator.AdvanceTo(duration)
    context = simulator.get_context()
    streams = {name: logger.FindLog(context).data().T for name, logger in loggers.items()}
    streams["time"] = loggers["wrench"].FindLog(context).sample_times()
    streams["bias"] = np.array(run.bias)
    streams["criteria"] = k.coordination.criteria(has_rotation=False)  # the static mode's
    streams["dynamic_criteria"] = payload_formulation(dataclasses.replace(k, mode="dynamic")).criteria
    return streams


def payload_errors(phi, bias, truth_outboard, truth_tool, true_bias) -> dict | None:
    """The errors of an estimate of the outboard body (``phi`` 10, or ``[m; h]`` 4 for the static mode)
    against the truth, and the held box's inertia error once the gripper's known parameters are
    subtracted (``box_inertia``, % of the box's largest principal moment)."""
    n = len(phi)
    if not phi[0] > 0.0:
        return None
    m, c = phi[0], np.asarray(phi[1:4]) / phi[0]
    m_true, c_true, I_true = dynamic.central_inertia(truth_outboard)
    errors = {"mass": 100.0 * abs(m - m_true) / m_true, "com": 1000.0 * float(np.linalg.norm(c - c_true))}
    if n == dynamic.N_INERTIAL:
        errors["inertia"] = _inertia_error(phi, I_true)
        box = np.asarray(phi) - (truth_outboard - truth_tool)
        box_truth = dynamic.central_inertia(truth_tool)[2]
        errors["box_inertia"] = _inertia_error(box, box_truth) if box[0] > 0 else math.inf
        errors["bias_tau"] = float(np.abs(bias[:3] - true_bias[:3]).max())
        errors["bias_f"] = float(np.abs(bias[3:] - true_bias[3:]).max())
    return errors


def _inertia_error(phi, I_true) -> float:
    """The central inertia's error (spectral norm) in % of the true largest principal moment."""
    I_Cm = dynamic.central_inertia(phi)[2]
    return 100.0 * float(np.linalg.norm(I_Cm - I_true, 2) / np.linalg.eigvalsh(I_true)[-1])


def within(errors: dict | None) -> bool:
    return errors is not None and all(errors[key] <= TARGETS[key] for key in TARGETS if key in errors)


def evaluate(streams: dict, estimator: str) -> Outcome:
    """Runs ``estimator`` over the stream, solving after every sample."""
    t = streams["time"]
    moving = np.abs(streams["joint_velocities"]).max(axis=1) > 1e-3
    start = t[int(np.argmax(moving))]
    samples, valid, identify, estimate = _estimator(streams, estimator)
    outcome, entered = Outcome(), None
    for i in range(t.size):
        if valid[i] > 0.5:
            identify.add(*samples(i))
        said, reason = identify_verdict(identify)
        errors = None
        if identify.num_samples:
            truth = streams["true_outboard_inertia"][i], streams["true_tool_inertia"][i], streams["bias"]
            errors = payload_errors(*estimate(identify), *truth)
        if said and outcome.identified is None:
            outcome.identified, outcome.errors = t[i] - start, errors
        outcome.reason = reason
        entered = (entered if entered is not None else t[i] - start) if within(errors) else None
    outcome.within = entered
    return outcome


def identify_verdict(identify) -> tuple[bool, str]:
    if isinstance(identify, DynamicPayloadRLS):
        return identify.identified(), ""
    verdict = identify.solve().verdict
    return verdict.converged, verdict.reason


def _estimator(streams: dict, estimator: str):
    """``(samples(i), valid, identifier, estimate(identifier))`` of ``estimator`` on ``streams``."""
    criteria = streams["criteria"]
    if estimator == "static":
        identify = PayloadIdentifier(criteria=criteria)
        R = streams["X_WK"].reshape(-1, 4, 4)[:, :3, :3]
        return (lambda i: (streams["wrench"][i], R[i]), streams["static_valid"][:, 0], identify,
                lambda s: (_static_phi(s.solve()), None))  # fmt: skip
    if estimator == "RLS":
        identify = DynamicPayloadRLS(RLS_FORGETTING)
        return (lambda i: (streams["wrench"][i], streams["sensor_kinematics"][i]),
                streams["dynamic_valid"][:, 0], identify, lambda s: (s.phi, s.bias))  # fmt: skip
    identify = dynamic.DynamicPayloadIdentifier(criteria=streams["dynamic_criteria"])
    if estimator == "sustainable, encoders":
        valid = streams["dynamic_valid"][:, 0] * streams["encoder_valid"][:, 0]
        return (lambda i: (streams["encoder_wrench"][i], streams["encoder_kinematics"][i]), valid, identify,
                lambda s: (s.solve().phi, s.solve().bias))  # fmt: skip
    return (lambda i: (streams["wrench"][i], streams["sensor_kinematics"][i]), streams["dynamic_valid"][:, 0],
            identify, lambda s: (s.solve().phi, s.solve().bias))  # fmt: skip


def _static_phi(solution) -> np.ndarray:
    if not solution.mass > 0.0:
        return np.zeros(4)
    return np.concatenate([[solution.mass], solution.mass * solution.p_KCm])


# The summaries after the one of every run: the targets are for motion without rests.
GROUPS = (("Motion without rests, babbling", lambda r: r.fast and not r.excite),
          ("Motion without rests, exciting", lambda r: r.fast and r.excite and not r.rigid),
          ("Motion without rests, exciting, the grasp rigid", lambda r: r.fast and r.excite and r.rigid),
          ("With rests, babbling, as built", lambda r: not (r.fast or r.excite or r.rigid)),
          ("With rests, exciting, as built", lambda r: r.excite and not (r.fast or r.rigid)))


def runs_of(seeds: list[int]) -> list[Run]:
    runs = [Run(f"seed {s}", s) for s in seeds]
    runs += [Run(f"rigid, seed {s}", s, rigid=True) for s in seeds]
    runs += [Run(f"bias, seed {s}", s, bias=BIAS) for s in seeds[:2]]
    runs += [Run(f"fast, seed {s}", s, fast=True) for s in seeds]
    runs += [Run(f"fast, bias, seed {s}", s, bias=BIAS, fast=True) for s in seeds[:2]]
    runs += [Run(f"exciting, seed {s}", s, excite=True) for s in seeds]
    runs += [Run(f"fast, exciting, seed {s}", s, fast=True, excite=True) for s in seeds]
    runs += [Run(f"fast, exciting, rigid, seed {s}", s, fast=True, excite=True, rigid=True) for s in seeds]
    return runs


def row(run: Run, estimator: str, o: Outcome) -> str:
    e = o.errors or {}
    cells = [run.name, estimator, number(o.identified, ".2f")]
    cells += [number(e.get(key), spec) for key, spec in _FIGURES] + [number(o.within, ".2f")]
    if o.identified is None:
        cells[3] = f"not identified: {o.reason}" if o.reason else "not identified"
    return "| " + " | ".join(cells) + " |"


_FIGURES = (("mass", ".3f"), ("com", ".2f"), ("inertia", ".1f"), ("bias_f", ".3f"), ("bias_tau", ".4f"),
            ("box_inertia", ".1f"))  # fmt: skip
COLUMNS = ["run", "estimator", "identified (s)", "mass (%)", "CoM (mm)", "inertia (%)", "bias f (N)",
           "bias tau (N m)", "held box's inertia (%)", "within targets (s)"]


def summary(results: list[tuple[Run, str, Outcome]]) -> list[str]:
    lines = ["| estimator | identified | identified (s) | mass (%) | CoM (mm) | inertia (%) | bias f (N) | "
             "bias tau (N m) | held box's inertia (%) | all targets met when identified | "
             "within targets (s) |",
             "|" + "---|" * 11]
    for estimator in ESTIMATORS:
        outcomes = [o for _, e, o in results if e == estimator]
        said = [o for o in outcomes if o.identified is not None]
        cells = [estimator, f"{len(said)} of {len(outcomes)}", _span([o.identified for o in said], ".2f")]
        for key, spec in _FIGURES:
            values = [o.errors[key] for o in said if o.errors and key in o.errors]
            cells.append(number(max(values), spec) if values else "-")
        cells.append(f"{sum(within(o.errors) for o in said)} of {len(outcomes)}")
        entered = [o.within for o in outcomes if o.within is not None]
        cells.append(_span(entered, ".2f") + ("" if len(entered) == len(outcomes) else
                                              f" ({len(outcomes) - len(entered)} never)"))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _span(values: list, spec: str) -> str:
    return "-" if not values else f"{format(min(values), spec)}-{format(max(values), spec)}"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=SEEDS, help="babbling seeds (>= 2)")
    p.add_argument("--duration", type=float, default=12.0, help="simulated seconds per run")
    p.add_argument("--results", action="store_true", help="also write the tables on docs/results.md")
    p.add_argument("--coverage", type=int, metavar="DRAWS",
                   help="instead: the verdict's misses over DRAWS noise draws on each seed's rigid stream")
    args = p.parse_args(argv)
    if args.coverage is not None:
        if args.coverage < 1:
            raise SystemExit("--coverage needs at least one draw")
        lines = coverage(args.seeds[0], args.coverage)
        for seed in args.seeds[1:]:
            lines += coverage(seed, args.coverage)[2:]
        print("\n".join(lines))
        if args.results:
            publish("bench_payload_dynamic_coverage", lines)
        return 0
    if args.results and (args.seeds != SEEDS or args.duration != 12.0):
        raise SystemExit("--results publishes the default seeds and duration only")
    results = []
    for run in runs_of(args.seeds):
        streams = record(run, args.duration)
        for estimator in ESTIMATORS:
            outcome = evaluate(copy.copy(streams), estimator)
            results.append((run, estimator, outcome))
            print(row(run, estimator, outcome), flush=True)
    lines = ["All runs:", ""] + summary(results)
    for title, keep in GROUPS:
        group = [r for r in results if keep(r[0])]
        lines += ["", f"{title} ({len(group) // len(ESTIMATORS)} runs):", ""] + summary(group)
    lines += ["", "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += [row(run, estimator, o) for run, estimator, o in results]
    print("\n".join(lines))
    if args.results:
        publish("bench_payload_dynamic", lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
