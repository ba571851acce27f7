"""Body detection by motion coincidence (paper §3.3.2, §4.2) as an experiment on the station.

``add_to_diagram`` wires, on the station's ports:

    color_image, depth_image, image_time -> OpticalFlowTracker
    joint_positions -> MotionCoincidenceDetector.actuator_positions
    tracker.visual_change, tracker.tracked_features -> detector
    detector.confirm -> station.motion_confirm          (the confirming motions, if enabled)
    label_image, ... -> BodyDetectionEvaluation           (ground truth, evaluation only)

The label image never reaches the tracker or the detector: it is read only by the evaluation
system, which streams every frame into an :class:`EpisodeEvaluator` whose accumulators are its
discrete state. ``finish`` writes the metrics and the pictures (likelihood maps like the
paper's Figs. 3-5, the scored mask against the truth).

Truth: a cell is body where the robot's *moving* bodies (every arm body the actuators move and
the held tool) cover at least ``body_cover`` of it in some frame. The arm's base is welded to
the world and never moves, so motion coincidence cannot see it: it counts as background.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem
from pydrake.systems.sensors import ImageLabel16I, ImageRgba8U

from sustain_drake.files import write_atomically
from sustain_drake.loops.body_detection import BodyDetectionConfig, add_body_detection
from sustain_drake.perception.evaluation import (
    EpisodeEvaluator,
    draw_likelihood_map,
    draw_mask_vs_truth,
    png_bytes,
)
from sustain_drake.perception.optical_flow import CellGrid
from sustain_drake.station import camera_info
from sustain_drake.station.scenario import ScenarioError, arm_of
from sustain_drake.systems.motion_coincidence_detector import MotionCoincidenceDetector
from sustain_drake.systems.optical_flow_tracker import OpticalFlowTracker

# Parts of the scored mask, scored separately too (metrics "parts").
PARTS = ("cells", "features")


@dataclass(frozen=True)
class Snapshot:
    """What a likelihood-map picture needs at one time."""

    time: float
    image: np.ndarray          # RGB uint8
    likelihood: np.ndarray     # ε, n_a x n_c
    body: np.ndarray           # scored body mask (bool, n_c)
    sdot: np.ndarray           # ṡ_j


class BodyDetectionEvaluation(LeafSystem):
    """Scores the body detection against the renderer's labels, frame by frame (evaluation only).

    .. pydrake_system::

        name: BodyDetectionEvaluation
        input_ports:
        - label_image
        - image_time
        - color_image
        - body_cells
        - body_feature_cells
        - visual_change
        - likelihood

    Once per new camera frame (``image_time`` increased) it adds the frame to an
    :class:`~sustain_drake.perception.evaluation.EpisodeEvaluator`: the label image gives the
    per-cell truth, the scored mask is ``body_cells`` (with ``score_features``, united with
    ``body_feature_cells``), ``visual_change`` marks visible motion. The evaluator's
    accumulators are one discrete-state vector; the likelihood-map snapshots taken at
    ``snapshot_times`` are abstract state. It has no outputs: read it with :meth:`metrics` and
    :meth:`snapshots` after the simulation.
    """

    def __init__(self, grid: CellGrid, num_actuators: int, body_labels, distractor_labels,
                 period: float, offset: float, body_cover: float = 0.10,
                 score_features: bool = True, snapshot_times=()):
        super().__init__()
        self._grid = grid
        self._n_a = int(num_actuators)
        self._score_features = bool(score_features)
        self._snapshot_times = tuple(sorted(float(t) for t in snapshot_times))
        self._template = (tuple(body_labels), tuple(distractor_labels), float(body_cover))
        n = grid.num_cells
        self._label = self.DeclareAbstractInputPort(
            "label_image", AbstractValue.Make(ImageLabel16I()))
        self._time = self.DeclareVectorInputPort("image_time", 1)
        self._color = self.DeclareAbstractInputPort(
            "color_image", AbstractValue.Make(ImageRgba8U()))
        self._cells = self.DeclareVectorInputPort("body_cells", n)
        self._feature_cells = self.DeclareVectorInputPort("body_feature_cells", n)
        self._sdot = self.DeclareVectorInputPort("visual_change", n)
        self._likelihood = self.DeclareVectorInputPort("likelihood", self._n_a * n)
        # [time of the last frame evaluated (-1: none), the evaluator's accumulators].
        self._state = self.DeclareDiscreteState(
            np.concatenate([[-1.0], self._evaluator().to_vector()]))
        self._snapshots = self.DeclareAbstractState(AbstractValue.Make(()))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, offset, self._update)

    def _evaluator(self, vector: np.ndarray | None = None) -> EpisodeEvaluator:
        body, distractor, cover = self._template
        ev = EpisodeEvaluator(self._grid, body, distractor, cover, parts=PARTS)
        if vector is not None:
            ev.set_vector(vector)
        return ev

    def evaluator(self, context) -> EpisodeEvaluator:
        """The episode so far, from ``context``."""
        return self._evaluator(context.get_discrete_state(self._state).value()[1:])

    def metrics(self, context) -> dict:
        return self.evaluator(context).metrics()

    def snapshots(self, context) -> tuple[Snapshot, ...]:
        return context.get_abstract_state(self._snapshots).get_value()

    def scored_mask(self, context) -> np.ndarray:
        cells = self._cells.Eval(context) > 0
        if self._score_features:
            cells |= self._feature_cells.Eval(context) > 0
        return cells

    def _update(self, context, state):
        t = float(self._time.Eval(context)[0])
        x = context.get_discrete_state(self._state).value()
        labels = self._label.Eval(context)
        if t <= x[0] or labels.width() != self._grid.width or labels.height() != self._grid.height:
            return  # no new frame (or none yet)
        ev = self._evaluator(x[1:])
        cells = self._cells.Eval(context) > 0
        features = self._feature_cells.Eval(context) > 0
        sdot = self._sdot.Eval(context)
        mask = cells | features if self._score_features else cells
        ev.update(t, labels.data, mask, sdot, parts={"cells": cells, "features": features})
        state.get_mutable_discrete_state(self._state).set_value(
            np.concatenate([[t], ev.to_vector()]))
        taken = self.snapshots(context)
        due = [s for s in self._snapshot_times if s <= t][len(taken):]
        if due:
            color = self._color.Eval(context)
            if color.width() == self._grid.width and color.height() == self._grid.height:
                snap = Snapshot(t, np.array(color.data[:, :, :3]),
                                self._likelihood.Eval(context).reshape(self._n_a, -1).copy(),
                                mask, np.array(sdot))
                state.get_mutable_abstract_state(self._snapshots).set_value(taken + (snap,))


@dataclass
class BodyDetectionHandle:
    config: BodyDetectionConfig
    station: object
    tracker: OpticalFlowTracker
    detector: MotionCoincidenceDetector
    evaluation: BodyDetectionEvaluation | None
    num_joints: int  # the arm's actuators the detector relates image motion to


def body_labels(station, scenario) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Render labels (the plant's body indices) of the robot's moving bodies (arm bodies the
    actuators move, and the held tool) and of the distractor (the person)."""
    plant = station.GetSubsystemByName("plant")
    static = {int(b.index()) for b in plant.GetBodiesWeldedTo(plant.world_body())}

    def instance_bodies(name):
        if not plant.HasModelInstanceNamed(name):
            return []
        return [int(b) for b in plant.GetBodyIndices(plant.GetModelInstanceByName(name))]

    robot = [b for b in instance_bodies(scenario.arm.model) if b not in static]
    if plant.HasBodyNamed("tool"):  # any tool.model: its instance (the tool and its grip links)
        robot += instance_bodies(plant.GetModelInstanceName(plant.GetBodyByName("tool").model_instance()))
    person = instance_bodies("person")
    return tuple(robot), tuple(person)


def add_to_diagram(builder, station, scenario, meshcat=None) -> BodyDetectionHandle:
    config = scenario.body_detection
    if not (station.HasOutputPort("color_image") and station.HasOutputPort("image_time")):
        raise ScenarioError("body_detection needs the camera's color image (camera.rgb: true)")
    info = camera_info(scenario)
    period, n_a = 1.0 / scenario.camera.fps, len(arm_of(scenario).joints)
    try:
        loop = add_body_detection(builder, info, n_a, scenario.camera.fps, config)
    except ValueError as e:
        raise ScenarioError(f"body_detection: {e}") from None
    tracker, detector = loop.tracker, loop.detector
    for name in ("color_image", "depth_image", "image_time"):
        if station.HasOutputPort(name):
            builder.Connect(station.GetOutputPort(name), tracker.GetInputPort(name))
    builder.Connect(station.GetOutputPort("joint_positions"),
                    detector.GetInputPort("actuator_positions"))
    if config.confirm:
        confirm = station.GetInputPort("motion_confirm")
        if builder.IsConnectedOrExported(confirm):
            raise ScenarioError("body_detection.confirm: the station's motion_confirm is "
                                "already driven by another experiment")
        builder.Connect(detector.GetOutputPort("confirm"), confirm)

    evaluation = None
    if station.HasOutputPort("label_image"):
        robot, person = body_labels(station, scenario)
        evaluation = builder.AddSystem(BodyDetectionEvaluation(
            tracker.grid, n_a, robot, person, period=period, offset=0.75 * period,
            body_cover=config.body_cover, score_features=config.score_features,
            snapshot_times=config.snapshot_times))
        evaluation.set_name("body_detection_evaluation")
        for name in ("label_image", "image_time", "color_image"):
            builder.Connect(station.GetOutputPort(name), evaluation.GetInputPort(name))
        for name in ("body_cells", "body_feature_cells", "likelihood"):
            builder.Connect(detector.GetOutputPort(name), evaluation.GetInputPort(name))
        builder.Connect(tracker.GetOutputPort("visual_change"),
                        evaluation.GetInputPort("visual_change"))
    return BodyDetectionHandle(config, station, tracker, detector, evaluation, n_a)


def _summary_line(m: dict) -> str:
    latency = m.get("latency_median_s")
    return (f"body_detection: precision {m['precision']:.3f}, recall {m['recall']:.3f}, "
            f"IoU {m['iou']:.3f}, distractor cells marked {m['distractor_cells_marked']} of "
            f"{m['distractor_cells']}, median latency "
            f"{'n/a' if latency is None else f'{latency:.2f} s'}")


def finish(handle: BodyDetectionHandle, diagram, context, out_dir) -> dict:
    """Metrics (also printed on one line) and pictures in ``out_dir``:
    ``likelihood_<t>s.png`` (snapshots and the end), ``likelihood_joint<i>.png`` (each
    actuator's ε_i· and the cells it moves, at the end), ``body_vs_truth.png``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tracker_ctx = handle.tracker.GetMyContextFromRoot(context)
    detector_ctx = handle.detector.GetMyContextFromRoot(context)
    station_ctx = handle.station.GetMyContextFromRoot(context)
    grid = handle.tracker.grid
    n_a = handle.num_joints
    s = handle.detector.detector_state(detector_ctx)
    rule = handle.detector.params
    features = handle.detector.GetOutputPort("feature_on_body").Eval(detector_ctx)
    detector = {
        "body_cells_now": int(s.body(rule).sum()),
        "confirm_requests": int(s.request_count),
        "confirm_trials": int(s.trial_count),
        "coincidences": int(s.eps.sum()),
        "features_tracked": int(len(features.ids)),
        "features_on_body": int(np.sum(features.on_body)),
    }
    metrics: dict = {"detector": detector, "pictures": []}
    if handle.evaluation is None:
        metrics["evaluated"] = False  # no label image in this scenario
        print("body_detection: no label image (camera.label: false), nothing evaluated")
        return metrics

    eval_ctx = handle.evaluation.GetMyContextFromRoot(context)
    ev = handle.evaluation.evaluator(eval_ctx)
    metrics.update(ev.metrics())
    metrics["evaluated"] = True

    color = handle.station.GetOutputPort("color_image").Eval(station_ctx)
    image = np.array(color.data[:, :, :3])
    eps = handle.detector.GetOutputPort("likelihood").Eval(detector_ctx).reshape(n_a, -1)
    sdot = handle.tracker.GetOutputPort("visual_change").Eval(tracker_ctx)
    final = Snapshot(context.get_time(), image, eps, handle.evaluation.scored_mask(eval_ctx), sdot)
    pictures = {}
    for snap in handle.evaluation.snapshots(eval_ctx) + (final,):
        pictures[f"likelihood_{snap.time:05.1f}s.png"] = draw_likelihood_map(
            snap.image, grid, snap.likelihood, snap.body, snap.sdot)
    moves = handle.detector.GetOutputPort("actuator_cells").Eval(detector_ctx).reshape(n_a, -1)
    for i in range(n_a):
        pictures[f"likelihood_joint{i + 1}.png"] = draw_likelihood_map(
            image, grid, eps[i], moves[i] > 0)
    pictures["body_vs_truth.png"] = draw_mask_vs_truth(
        image, grid, ev.ever_marked, ev.truth.truth(), ev.truth.distractor_cells())
    for name, rgb in pictures.items():
        write_atomically(out / name, png_bytes(rgb))
    metrics["pictures"] = sorted(pictures)
    print(_summary_line(metrics))
    return metrics
