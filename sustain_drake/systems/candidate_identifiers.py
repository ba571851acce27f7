"""One eye-to-hand identifier per candidate body feature (paper Fig. 7) as a Drake system."""

from __future__ import annotations

import dataclasses
from functools import partial

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem
from pydrake.systems.sensors import CameraInfo, ImageDepth32F, ImageRgba8U

from sustain_drake.identification import candidates
from sustain_drake.identification.candidates import CandidateBank, CandidateParams
from sustain_drake.identification.coordination import NO_RESET
from sustain_drake.identification.eye_to_hand import N_UNKNOWNS
from sustain_drake.identification.sustainable_identifier import Verdict
from sustain_drake.perception.anchored_points import AnchoredTracks, refine_anchored
from sustain_drake.perception.camera_motion import SceneTurn
from sustain_drake.perception.free_space import depth_gap
from sustain_drake.perception.optical_flow import TrackedFeatures
from sustain_drake.perception.point_refinement import RefinedPoints, RefinementParams, refine_features
from sustain_drake.systems.depth_noise import DepthNoiseModel
from sustain_drake.systems.motion_coincidence_detector import FeatureBodyFlags
from sustain_drake.systems.optical_flow_tracker import intrinsics_from_camera_info
from sustain_drake.systems.shared_state import Shared
from sustain_drake.systems.sustainable_identifier_system import EyeToHandFormulation, declare_solution_outputs


class FeatureRefiner(LeafSystem):
    """The tracked features with drift-free 3-D points for the identifiers. Put between an
    ``OpticalFlowTracker`` and ``CandidateIdentifiers``: a point fixed on the hand (Eq. (30)) must
    be the same physical point in every frame, which a frame-to-frame track is not (it drifts by
    millimetres over tens of seconds).

    .. pydrake_system::

        name: FeatureRefiner
        input_ports:
        - tracked_features
        - color_image
        - depth_image
        - image_time (optional)
        output_ports:
        - tracked_features

    ``tracked_features`` out is the input with ``p_px``, ``p_CP``, ``valid`` and ``symmetric``
    replaced (same ids and order, so a detector's body flags still match). The images must be the
    frame the features come from: when ``image_time`` (connected) differs from the features'
    ``time``, every feature is invalid for that evaluation (no point is better than a point from
    another frame).

    With ``params.anchor_window_px`` > 0 each track's point is anchored to the patch the track saw
    in its first frame (``perception.anchored_points``): the anchors are an abstract state updated
    once per frame, ``period`` s apart from ``offset`` (between the tracker's update and the
    reader's; the output is the last update's points, invalid for a frame it has not seen).
    Otherwise each point is the sub-pixel corner near the tracked pixel
    (``perception.point_refinement``), the output a function of the inputs with no state.
    ``depth_noise`` is the depth camera's noise model (``DepthNoiseModel``, its default if None):
    an anchor pins its point within it.
    """

    def __init__(self, camera_info: CameraInfo, params: RefinementParams | None = None,
                 depth_noise: DepthNoiseModel | None = None, period: float = 1.0 / 30.0,
                 offset: float = 0.5 / 30.0):
        super().__init__()
        self._intrinsics = intrinsics_from_camera_info(camera_info)
        self._params = params or RefinementParams()
        self._depth_noise = depth_noise or DepthNoiseModel()
        self._features = self.DeclareAbstractInputPort(
            "tracked_features", AbstractValue.Make(TrackedFeatures()))
        self._color = self.DeclareAbstractInputPort("color_image", AbstractValue.Make(ImageRgba8U()))
        self._depth = self.DeclareAbstractInputPort("depth_image", AbstractValue.Make(ImageDepth32F()))
        self._time = self.DeclareVectorInputPort("image_time", 1)
        if self._params.anchor_window_px > 0:
            # (the tracks' anchors and corners, the last frame's refined features)
            self._anchors = self.DeclareAbstractState(AbstractValue.Make(
                Shared((AnchoredTracks(), TrackedFeatures(time=-np.inf)))))
            self.DeclarePeriodicUnrestrictedUpdateEvent(period, offset, self._update_anchors)
            self.DeclareAbstractOutputPort(
                "tracked_features", lambda: AbstractValue.Make(TrackedFeatures()), self._calc_anchored,
                prerequisites_of_calc={self.all_state_ticket(), self._features.ticket()})
        else:
            self.DeclareAbstractOutputPort(
                "tracked_features", lambda: AbstractValue.Make(TrackedFeatures()), self._calc)

    @property
    def params(self) -> RefinementParams:
        return self._params

    @property
    def depth_noise(self) -> DepthNoiseModel:
        return self._depth_noise

    def _frame(self, context):
        """The features and their frame's images, or None when the images are not that frame's."""
        features = self._features.Eval(context)
        color, depth = self._color.Eval(context).data, self._depth.Eval(context).data
        shape_ok = color.shape[:2] == (self._intrinsics.height, self._intrinsics.width) == depth.shape[:2]
        if len(features) == 0 or not (_same_frame(self._time, context, features.time) and shape_ok):
            return features, None, None
        return features, color, depth

    def _calc(self, context, output) -> None:
        features, color, depth = self._frame(context)
        if color is None:
            output.set_value(_without_points(features))
            return
        refined = refine_features(color, depth, features.p_px, self._intrinsics, self._params)
        output.set_value(dataclasses.replace(features, **refined._asdict()))

    def _update_anchors(self, context, state) -> None:
        anchors, last = context.get_abstract_state(int(self._anchors)).get_value().value
        features, color, depth = self._frame(context)
        if len(features) and features.time <= last.time:
            return
        if color is None:  # no image of this frame: no points, and the anchors wait for the next
            refined = _without_points(features)
        else:
            anchors, points = refine_anchored(anchors, color, depth, features.ids, features.p_px,
                                              self._intrinsics, self._params, self._depth_noise.sigma)
            refined = dataclasses.replace(features, **points._asdict())
        state.get_mutable_abstract_state(int(self._anchors)).set_value(Shared((anchors, refined)))

    def _calc_anchored(self, context, output) -> None:
        features = self._features.Eval(context)
        _, last = context.get_abstract_state(int(self._anchors)).get_value().value
        same = last.time == features.time and np.array_equal(last.ids, features.ids)
        output.set_value(last if same else _without_points(features))


def _without_points(features: TrackedFeatures) -> TrackedFeatures:
    """The features with no point (every ``valid`` and ``symmetric`` False)."""
    none = np.zeros(len(features), bool)
    return dataclasses.replace(features, **RefinedPoints(np.zeros((len(features), 3)), none,
                                                         features.p_px, none.copy())._asdict())


def _same_frame(image_time_port, context, features_time: float) -> bool:
    """Whether the images on the inputs are the features' frame (True when ``image_time`` is not
    connected: the caller vouches for it)."""
    return (not image_time_port.HasValue(context)
            or abs(float(image_time_port.Eval(context)[0]) - features_time) < 1e-9)


class CandidateIdentifiers(LeafSystem):
    """Identifiers for the candidate tracked points, the first to converge leads
    (``identification.candidates``).

    .. pydrake_system::

        name: CandidateIdentifiers
        input_ports:
        - tracked_features
        - feature_on_body
        - X_WH
        - reset (optional)
        - reset_reason (optional)
        - reference_x (optional)
        - allowable_error (optional)
        - depth_image (with camera_info)
        - image_time (optional, with camera_info)
        - scene_turn (optional)
        - scene_still_since (optional)
        - X_WL (optional)
        output_ports:
        - eigenvalues
        - x
        - ssd
        - verdict
        - expected_mse
        - observation
        - solution
        - X_WC
        - p_HP
        - candidates
        - more_motion
        - motion_statistic

    Inputs: ``tracked_features`` (``TrackedFeatures`` of an ``OpticalFlowTracker``: ids, ``p_CP``
    in m, ``valid``, capture ``time``), ``feature_on_body`` (``FeatureBodyFlags`` of a
    ``MotionCoincidenceDetector``, same order), ``X_WH`` (``RigidTransform``, the hand pose now:
    the pose at each frame's capture time is taken from a short history), ``reset`` (1,
    edge-triggered: a new value drops every candidate; connect a ``CoordinationStateMachine``'s
    ``reset``), ``reset_reason`` (1, why: the state machine's ``reset_reason``; a reset for
    ``coordination.CAMERA_MOVED`` drops the model's camera, any other keeps it as the previous camera
    that a slipped tool leaves in place; unconnected: never a camera move), ``reference_x`` (16: the
    adopted estimate, for ``observation``; connect the state machine's ``adopted_x``),
    ``allowable_error`` (1, m^2: the state machine's sigma, so that a tracking failure of the observed
    point, which its witness does not share, is told from a change of the body; unconnected: never).
    With ``camera_info`` (and ``params.free_space_radius`` > 0): ``depth_image`` (``ImageDepth32F``,
    m) and ``image_time`` (1, s), the features' frame's depth, against which the adopted tool point
    is checked every frame (``perception.free_space``; an image from another frame than the
    features', by ``image_time``, is not used).
    ``scene_turn`` (``perception.camera_motion.SceneTurn``: connect a ``CameraMotionDetector``'s
    ``scene_turn``; unconnected: none): with ``params.keep_tool_points``, the camera after a move
    is the old one turned as the static scene shows, placed by the tool points
    (``identification.candidates.step``). ``scene_still_since`` (1, s: a ``CameraMotionDetector``'s;
    unconnected: inf): a still scene showing the camera unmoved since before a reset says it did not move, and
    the kept camera then leads with ``params.keep_camera_min_samples`` samples. ``X_WL``
    (``RigidTransform``: the pose now of the hand's parent link, the body the hand's last moving
    joint turns it on; unconnected: not known): a candidate whose samples fit that link better than
    the hand is fixed on it, not on the hand, and is rejected (``fitting.on_parent_link``).

    Outputs, the same as a ``SustainableIdentifierSystem`` with ``EyeToHandFormulation`` so that a
    ``CoordinationStateMachine`` plugs in: the solution-derived ports are those of the *shown*
    candidate (the leader once one converged, else the one with the most samples);
    ``observation`` is ``[sample_count, s_t]`` of the observed feature (the leader's, or a
    re-acquired one) under ``reference_x``, m^2; ``X_WC`` (RigidTransform), ``p_HP`` (3, m);
    ``candidates`` (``candidates.CandidateBank``: every candidate, the leader, the adoptions).
    ``more_motion`` (1): 1 while no candidate leads and either, before the first identification, a
    candidate has ``params.motion_min_samples`` samples, or (from a frame where a candidate
    converged and was confirmed but its points' views did not pin the camera's rotation,
    ``params.min_rotation_lever`` or ``params.min_adopt_rotation_spread``, or its camera's 95 %
    region exceeded ``params.camera_accuracy`` or ``camera_rotation_accuracy``) until a leader is
    chosen, a reset, or no converged candidate is left; 2 instead of 1 while that converged
    candidate is held back and seen (it wants more points too: the detector's trials); else 0: the
    hand should move more (``CandidateBank.motion_wanted``; connect an ``IdentifyingMotion``'s
    ``more_motion``). ``motion_statistic`` (258): while ``more_motion`` is set, the statistic
    ``[S | n_eff | count]`` of the candidate held back for more views, else of the centrally
    symmetric one with the most samples, else of the one with the most; zeros otherwise
    (connect an ``IdentifyingMotion``'s ``statistic``).

    State: the ``CandidateBank`` (abstract, immutable: a cloned context shares it), updated every ``period``
    s (a periodic unrestricted update at the camera's rate).
    """

    def __init__(self, formulation: EyeToHandFormulation | None = None, params: CandidateParams | None = None,
                 period: float = 1.0 / 30.0, camera_info: CameraInfo | None = None):  # fmt: skip
        super().__init__()
        if not period > 0:
            raise ValueError(f"period must be > 0, got {period}")
        self._formulation = formulation or EyeToHandFormulation()
        self._params = params or CandidateParams()
        if camera_info is not None and not self._params.free_space_radius > 0:
            raise ValueError("CandidateIdentifiers: camera_info is for the depth check, which needs "
                             "params.free_space_radius > 0")
        if self._params.pose_tolerance >= period:
            self._params = CandidateParams(**{**self._params.__dict__, "pose_tolerance": 0.3 * period})
        self._features = self.DeclareAbstractInputPort(
            "tracked_features", AbstractValue.Make(TrackedFeatures()))
        self._flags = self.DeclareAbstractInputPort("feature_on_body", AbstractValue.Make(FeatureBodyFlags()))
        self._X_WH = self.DeclareAbstractInputPort("X_WH", AbstractValue.Make(RigidTransform()))
        self._reset = self.DeclareVectorInputPort("reset", 1)
        self._reset_reason = self.DeclareVectorInputPort("reset_reason", 1)
        self._reference = self.DeclareVectorInputPort("reference_x", N_UNKNOWNS)
        self._sigma = self.DeclareVectorInputPort("allowable_error", 1)
        self._turn = self.DeclareAbstractInputPort("scene_turn", AbstractValue.Make(SceneTurn()))
        self._still = self.DeclareVectorInputPort("scene_still_since", 1)
        self._X_WL = self.DeclareAbstractInputPort("X_WL", AbstractValue.Make(RigidTransform()))
        self._intrinsics = self._depth = self._time = None
        if camera_info is not None:
            self._intrinsics = intrinsics_from_camera_info(camera_info)
            self._depth = self.DeclareAbstractInputPort("depth_image", AbstractValue.Make(ImageDepth32F()))
            self._time = self.DeclareVectorInputPort("image_time", 1)
        self._empty = candidates.empty_solution(self._formulation.criteria)
        self._bank = self.DeclareAbstractState(AbstractValue.Make(Shared(CandidateBank())))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

        declare_solution_outputs(self, N_UNKNOWNS, self.solution)
        self.DeclareVectorOutputPort(
            "observation", 2,
            lambda c, o: o.SetFromVector([self.bank(c).sample_count, self.bank(c).sample_error]),
            prerequisites_of_calc={self.all_state_ticket()},
        )  # fmt: skip
        self.DeclareAbstractOutputPort(
            "solution", lambda: AbstractValue.Make(self._empty),
            lambda c, o: o.set_value(self.solution(c)), prerequisites_of_calc={self.all_state_ticket()},
        )  # fmt: skip
        self._formulation.declare_outputs(self, self.solution)
        self.DeclareAbstractOutputPort(
            "candidates", lambda: AbstractValue.Make(CandidateBank()), lambda c, o: o.set_value(self.bank(c)),
            prerequisites_of_calc={self.abstract_state_ticket(self._bank)},
        )  # fmt: skip
        self.DeclareVectorOutputPort(
            "more_motion", 1, lambda c, o: o.SetFromVector([self.bank(c).motion_wanted()]),
            prerequisites_of_calc={self.all_state_ticket()},
        )  # fmt: skip
        self.DeclareVectorOutputPort(
            "motion_statistic", N_UNKNOWNS * N_UNKNOWNS + 2,
            lambda c, o: o.SetFromVector(self._motion_statistic(c)),
            prerequisites_of_calc={self.abstract_state_ticket(self._bank)},
        )  # fmt: skip

    @property
    def params(self) -> CandidateParams:
        return self._params

    @property
    def criteria(self):
        """The ``ConvergenceCriteria`` each candidate's identifier is judged by."""
        return self._formulation.criteria

    def bank(self, context) -> CandidateBank:
        return context.get_abstract_state(self._bank).get_value().value

    def _motion_statistic(self, context) -> np.ndarray:
        """While ``more_motion``: the statistic of the candidate held back for more views, else of the
        centrally symmetric candidate with the most samples (only such a point leads while one
        converges in time), else of the one with the most samples; zeros otherwise."""
        bank = self.bank(context)
        wanting = None
        if bank.more_motion and bank.candidates:
            symmetric = [c for c in bank.candidates if c.symmetric]
            wanting = bank.find(bank.held_back) or max(symmetric or bank.candidates,
                                                       key=lambda c: c.solution.num_samples)
        return wanting.statistic if wanting is not None else np.zeros(N_UNKNOWNS * N_UNKNOWNS + 2)

    def solution(self, context):
        """The shown candidate's solution (an empty one before any candidate). Only a leader's
        solution says converged: before one is chosen (a single candidate's verdict may say
        converged before a second point confirms it, or before the joint identification does),
        the shown solution's verdict is "not converged", so a state machine adopts leaders only."""
        bank = self.bank(context)
        shown = bank.shown
        if shown is None:
            return self._empty
        if bank.leader < 0 and shown.solution.verdict.converged:
            return dataclasses.replace(shown.solution, verdict=Verdict(False, "no leader chosen yet"))
        if bank.leader >= 0 and bank.refined_solution is not None:
            return bank.refined_solution  # the adopted model, refined while observing
        return shown.solution

    def _update(self, context, state) -> None:
        features = self._features.Eval(context)
        flags = self._flags.Eval(context)
        on_body = in_body_cell = np.zeros(len(features), bool)
        if len(flags.ids) == len(features) and np.array_equal(flags.ids, features.ids):
            on_body = np.asarray(flags.on_body, bool)
            in_body_cell = np.asarray(flags.in_body_cell, bool)
        reset = float(self._reset.Eval(context)[0]) if self._reset.HasValue(context) else 0.0
        reference = self._reference.Eval(context) if self._reference.HasValue(context) else None
        sigma = float(self._sigma.Eval(context)[0]) if self._sigma.HasValue(context) else np.inf
        if not sigma > 0:
            sigma = np.inf  # no adopted model yet
        still = float(self._still.Eval(context)[0]) if self._still.HasValue(context) else np.inf
        reason = (int(self._reset_reason.Eval(context)[0]) if self._reset_reason.HasValue(context)
                  else NO_RESET)
        frame = candidates.FrameInput(
            time=context.get_time(), reset=reset, X_WH=self._X_WH.Eval(context).GetAsMatrix4(),
            frame_time=features.time, ids=features.ids, p_CP=features.p_CP, valid=features.valid,
            on_body=on_body, reference_x=reference, forgetting_factor=self._formulation.forgetting_factor,
            in_body_cell=in_body_cell, allowable_error=sigma,
            depth_gap=self._depth_gap(context, features.time),
            scene_turn=self._turn.Eval(context) if self._turn.HasValue(context) else None,
            scene_still_since=still, reset_reason=reason,
            symmetric=features.symmetric,  # a length that does not match counts as not known
            X_WL=self._X_WL.Eval(context).GetAsMatrix4() if self._X_WL.HasValue(context) else None,
        )
        new = candidates.step(self.bank(context), self._params, self._formulation.criteria, frame)
        state.get_mutable_abstract_state(self._bank).set_value(Shared(new))

    def _depth_gap(self, context, features_time: float):
        """``candidates.FrameInput.depth_gap`` for this frame, None without its depth image."""
        if self._depth is None or not self._depth.HasValue(context):
            return None
        depth = self._depth.Eval(context).data
        size = (self._intrinsics.height, self._intrinsics.width)
        if depth.shape[:2] != size or not _same_frame(self._time, context, features_time):
            return None
        return partial(depth_gap, depth, self._intrinsics, radius=self._params.free_space_radius)
