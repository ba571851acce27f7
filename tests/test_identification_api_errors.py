"""The identification API's error contract (issue #23): every public function and method of
``sustain_drake.identification`` and its modules raises only ``IdentificationError`` (a ``ValueError``
with a one-line message naming the argument) for an argument of the wrong type, shape or value.

A table of bad calls per public function, and a hypothesis fuzz that calls the API with random
arguments (random shapes and dtypes, None, nested lists, strings, NaN, slightly wrong valid arrays)
and accepts only a result or an IdentificationError. The fuzz takes about 10 s; with
``SUSTAIN_DRAKE_FUZZ=long`` it runs 20 times as many (a few minutes, not derandomized).
"""

from __future__ import annotations

import inspect
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as npst
from scipy.spatial.transform import Rotation

from sustain_drake.identification import (
    ConvergenceCriteria,
    EyeToHandIdentifier,
    IdentificationError,
    PayloadIdentifier,
    SustainableIdentifier,
    batch,
    camera_turn,
    coordination,
    eye_to_hand,
    observability,
    payload,
    rotation,
    sustainable_identifier,
    touch,
    view_correlation,
)
from sustain_drake.identification import (
    eye_to_hand_points as points,
)

LONG = os.environ.get("SUSTAIN_DRAKE_FUZZ", "") == "long"

# ---- valid arguments ----------------------------------------------------------------------------
R = Rotation.from_euler("xyz", [0.3, -0.2, 0.5]).as_matrix()
REFLECTION = R @ np.diag([1.0, 1.0, -1.0])  # orthonormal, det -1
SCALED = 1.01 * R  # det +1.03, not orthonormal
NAN3 = np.full((3, 3), np.nan)
P, P2 = np.array([0.1, -0.2, 0.9]), np.array([0.4, 0.1, 0.3])
X = np.eye(4)
X[:3, :3], X[:3, 3] = R, P2
WRENCH = np.array([0.01, -0.02, 0.0, 0.5, -1.0, 5.0])
G = np.array([0.0, 0.0, -9.81])


def _filled_eye() -> EyeToHandIdentifier:
    rng = np.random.default_rng(3)
    ident = EyeToHandIdentifier()
    for q in Rotation.random(20, random_state=rng).as_matrix():
        ident.add(rng.normal(size=3), q, rng.normal(size=3))
    return ident


def _views_of_filled_eye() -> np.ndarray:
    """``_filled_eye``'s 20 samples as 4 views of 5 (``view_correlation.view_row`` sums)."""
    rng = np.random.default_rng(3)
    rows = [view_correlation.view_row(rng.normal(size=3), q, rng.normal(size=3))
            for q in Rotation.random(20, random_state=rng).as_matrix()]
    return np.array(rows).reshape(4, 5, -1).sum(axis=1)


EYE = _filled_eye()
S16, WEIGHT = EYE.core.S, EYE.core.weight
VIEWS = _views_of_filled_eye()
_PAYLOAD = PayloadIdentifier()
for _q in Rotation.random(12, random_state=np.random.default_rng(6)).as_matrix():
    _f = _q.T @ [0.0, 0.0, 5.0]
    _PAYLOAD.add(np.concatenate([np.cross([0.0, 0.0, 0.1], _f), _f]), _q)
S5, WEIGHT5, X5 = _PAYLOAD.core.S, _PAYLOAD.core.weight, _PAYLOAD.solve().x
ESTIMATE = EYE.solve().estimate
STATE = EYE.state
CORE = SustainableIdentifier(4)
CORE.add(np.arange(8.0).reshape(2, 4))
CORE.add(np.eye(4))
EIGEN = CORE.eigen()
CRITERIA = ConvergenceCriteria(max_expected_rms=0.01)
RULE = coordination.CoordinationRule()
REPORT = coordination.IdentifierReport(True, 1e-6, 5, 1e-7)
_anchor_rng = np.random.default_rng(4)
B0 = _anchor_rng.normal(size=(12, 3))
B0 /= np.linalg.norm(B0, axis=1, keepdims=True)
B1 = B0 @ R  # the scene turned by R^T
Q0 = 2.0 * B0
N_BATCH = 12
P_C = np.random.default_rng(5).normal(size=(N_BATCH, 3))
X_WH = np.tile(X, (N_BATCH, 1, 1))
R_WK = np.tile(R, (N_BATCH, 1, 1))
WRENCHES = np.tile(WRENCH, (N_BATCH, 1))
TRACKS = {"a": (np.arange(N_BATCH), P_C), 2: (np.arange(1, N_BATCH), P_C[1:] + 0.1)}

# name -> (callable, valid arguments). Methods get a fresh object (or a filled one) per call.
TARGETS = {
    "SustainableIdentifier": (SustainableIdentifier, (4, 1.0)),
    "SustainableIdentifier.add": (lambda A: SustainableIdentifier(4).add(A), (np.ones((2, 4)),)),
    "SustainableIdentifier.set_state": (lambda s: SustainableIdentifier(4).set_state(s), (CORE.state,)),
    "SustainableIdentifier.eigen": (lambda T: CORE.eigen(T), (np.eye(4),)),
    "SustainableIdentifier.sample_error": (SustainableIdentifier.sample_error, (np.ones((2, 4)), np.ones(4))),
    "SustainableIdentifier.mean_squared_error": (lambda x: CORE.mean_squared_error(x), (np.ones(4),)),
    "ConvergenceCriteria": (ConvergenceCriteria, (0.01, 10.0, 0.1, 10)),
    "judge": (sustainable_identifier.judge, (CRITERIA, 20, EIGEN, 0.001, None, 0.01, " m")),
    "EyeToHandIdentifier": (EyeToHandIdentifier, (1.0, None)),
    "EyeToHandIdentifier.add": (lambda *a: EyeToHandIdentifier().add(*a), (P, R, P2)),
    "EyeToHandIdentifier.add_pose": (lambda *a: EyeToHandIdentifier().add_pose(*a), (P, X)),
    "EyeToHandIdentifier.sample_error": (lambda *a: EYE.sample_error(*a), (P, R, P2, ESTIMATE)),
    "EyeToHandIdentifier.solve": (lambda *a: _filled_eye().solve(*a), (True,)),
    "EyeToHandIdentifier.set_state": (lambda s: EyeToHandIdentifier().set_state(s), (STATE,)),
    "eye_to_hand.default_criteria": (eye_to_hand.default_criteria, ()),
    "eye_to_hand.build_A": (eye_to_hand.build_A, (P, R, P2, None)),
    "eye_to_hand.pack_x": (eye_to_hand.pack_x, (R, P, P2)),
    "eye_to_hand.predicted_points": (eye_to_hand.predicted_points, (ESTIMATE, X_WH)),
    "eye_to_hand.path_information": (eye_to_hand.path_information, (STATE, [(P_C, X_WH, np.ones(N_BATCH))])),
    "eye_to_hand.conditioning_transform": (eye_to_hand.conditioning_transform, (S16, None)),
    "eye_to_hand.refine": (eye_to_hand.refine, (S16, WEIGHT, R, P, P2, 30, 1e-12)),
    "eye_to_hand_points.refine_joint": (points.refine_joint, ([S16, S16], R, P, [P2, P2], 30, 1e-10)),
    "eye_to_hand_points.rotation_levers": (points.rotation_levers, ([S16], R, P, [P2])),
    "eye_to_hand_points.position_given_rotation": (points.position_given_rotation, ([S16], [P2], R)),
    "eye_to_hand_points.camera_given_points": (points.camera_given_points, ([S16], [P2])),
    "eye_to_hand_points.spread_off_line": (points.spread_off_line, (0.01 * np.eye(3),)),
    "eye_to_hand_points.points_given_camera": (points.points_given_camera, ([S16], R, P)),
    "eye_to_hand_points.refine_joint_weighted": (points.refine_joint_weighted, ([S16, S16], R, P, 10, 1e-3)),
    "eye_to_hand_points.joint_covariance": (points.joint_covariance,
                                            ([S16, S16], R, P, [P2, P2], None, False, [5.0, 5.0])),
    "eye_to_hand_points.position_and_points_given_rotation": (points.position_and_points_given_rotation,
                                                              ([S16, S16], R, [5.0, 5.0])),
    "view_correlation.view_row": (view_correlation.view_row, (P, R, P2)),
    "view_correlation.repeated_share": (view_correlation.repeated_share, (VIEWS, S16, R, P, P2)),
    "view_correlation.independent_samples": (view_correlation.independent_samples, (VIEWS, S16, R, P, P2)),
    "camera_turn.camera_after_turn": (camera_turn.camera_after_turn,
                                      (R, P, camera_turn.TurnAnchors(B0, Q0, B1), [], [], 5, 2, 1e-3)),
    "PayloadIdentifier": (PayloadIdentifier, (G, 1.0, None)),
    "PayloadIdentifier.add": (lambda *a: PayloadIdentifier().add(*a), (WRENCH, R)),
    "PayloadIdentifier.sample_error": (lambda *a: PayloadIdentifier().sample_error(*a),
                                       (WRENCH, R, np.ones(5))),
    "payload.default_criteria": (payload.default_criteria, ()),
    "payload.build_A": (payload.build_A, (WRENCH, R, G, None)),
    "payload.posture_information": (payload.posture_information, (_PAYLOAD.state, R_WK, G, 60.0)),
    "PostureInformation": (payload.PostureInformation, (G, 60.0)),
    "PostureInformation.__call__": (lambda *a: payload.PostureInformation(G, 60.0)(*a),
                                    (_PAYLOAD.state, R_WK)),
    "batch.calibrate_eye_to_hand": (batch.calibrate_eye_to_hand, (P_C, X_WH, None)),
    "batch.calibrate_eye_to_hand_points": (batch.calibrate_eye_to_hand_points, (TRACKS, X_WH, None)),
    "batch.identify_payload": (batch.identify_payload, (WRENCHES, R_WK, G, None)),
    "batch.check_rotations": (batch.check_rotations, ("R", R_WK)),
    "batch.eye_to_hand_residuals": (batch.eye_to_hand_residuals, (X, P, P_C, X_WH)),
    "rotation.det3": (rotation.det3, (R,)),
    "rotation.skew": (rotation.skew, (P,)),
    "rotation.so3_exp": (rotation.so3_exp, (P,)),
    "rotation.rotation_angle": (rotation.rotation_angle, (R,)),
    "rotation.project_to_rotation": (rotation.project_to_rotation, (R.ravel(),)),
    "rotation.projection_parts": (rotation.projection_parts, (R.ravel(),)),
    "rotation.nearest_rotation": (rotation.nearest_rotation, (SCALED,)),
    "touch.Box": (touch.Box, ((0.1, 0.2, 0.3),)),
    "touch.Cylinder": (touch.Cylinder, (0.05, 0.2)),
    "touch.Sphere": (touch.Sphere, (0.1,)),
    "touch.predicted_wrench": (touch.predicted_wrench, (0.5, P, R, G)),
    "touch.line_of_action": (touch.line_of_action, (P, P2)),
    "touch.locate_touch": (touch.locate_touch, (WRENCH, touch.Sphere(0.1), X)),
    "observability.eye_to_hand_standard_errors": (observability.eye_to_hand_standard_errors, (S16, R, 1e-6)),
    "observability.eye_to_hand_covariance": (observability.eye_to_hand_covariance, (S16, R)),
    "observability.payload_covariance": (observability.payload_covariance, (S5, WEIGHT5, X5, G)),
    "observability.region_95": (observability.region_95, (3,)),
    "observability.radius_95": (observability.radius_95, (np.eye(3),)),
    "coordination.CoordinationRule": (coordination.CoordinationRule, (100.0, 10, 3.0, 0.0, False)),
    "coordination.allowable_error": (coordination.allowable_error, (RULE, 1e-6)),
    "coordination.initial_state": (coordination.initial_state, ()),
    "coordination.IdentifierReport": (coordination.IdentifierReport, (True, 1e-6, 5, 1e-7, 5, 0)),
    "coordination.step": (coordination.step, (coordination.initial_state(), RULE, 1.0, REPORT, False, None,
                                              None, None)),
}

# Result records, not checked (built by the API itself), and the checks themselves.
NOT_TARGETS = {"EigenSolution", "Verdict", "SolutionProperties", "FormulationIdentifier", "EyeToHandEstimate",
               "EyeToHandSolution", "PayloadSolution", "CameraAfterTurn", "TurnAnchors", "RotationProjection",
               "TouchPoint",
               "Event", "EyeToHandResult", "EyeToHandPointsResult", "PayloadResult", "IdentificationError"}


def _call(name: str, args: tuple):
    return TARGETS[name][0](*args)


def test_every_valid_call_works():
    for fn, args in TARGETS.values():
        fn(*args)


def test_every_public_function_and_class_is_a_target():
    for module in (sustainable_identifier, eye_to_hand, payload, batch, rotation, touch, coordination,
                   observability, camera_turn, view_correlation):
        for attr, value in vars(module).items():
            if attr.startswith("_") or getattr(value, "__module__", None) != module.__name__:
                continue
            if not (inspect.isfunction(value) or inspect.isclass(value)) or attr in NOT_TARGETS:
                continue
            short = module.__name__.rsplit(".", 1)[1]
            assert attr in TARGETS or f"{short}.{attr}" in TARGETS, f"{short}.{attr} is not covered"


def _with(name: str, index: int, value) -> tuple:
    args = list(TARGETS[name][1])
    args[index] = value
    return tuple(args)


def _bad(name: str, index: int, value, expected: str):
    return pytest.param(name, _with(name, index, value), expected, id=f"{name}[{index}]={_label(value)}")


def _label(value) -> str:
    if isinstance(value, np.ndarray):
        return f"array{value.shape}"
    text = repr(value)
    return text if len(text) <= 20 else text[:17] + "..."


LAST_ROW = X.copy()
LAST_ROW[3, 0] = 1.0
ZERO_ROW = B0.copy()
ZERO_ROW[3] = 0.0
BAD_CALLS = [
    # the streaming identifiers
    _bad("EyeToHandIdentifier.add", 0, None, "p_CP"),
    _bad("EyeToHandIdentifier.add", 0, [0.1, 0.2], "p_CP"),
    _bad("EyeToHandIdentifier.add", 0, 0.5, "p_CP"),  # a scalar would broadcast
    _bad("EyeToHandIdentifier.add", 0, [[0.1, 0.2, 0.3]], "p_CP"),
    _bad("EyeToHandIdentifier.add", 0, "abc", "p_CP"),
    _bad("EyeToHandIdentifier.add", 0, [0.1, np.nan, 0.3], "p_CP"),
    _bad("EyeToHandIdentifier.add", 1, None, "R_WH"),
    _bad("EyeToHandIdentifier.add", 1, REFLECTION, "R_WH"),
    _bad("EyeToHandIdentifier.add", 1, SCALED, "R_WH"),
    _bad("EyeToHandIdentifier.add", 1, NAN3, "R_WH"),
    _bad("EyeToHandIdentifier.add", 1, [1.0, 0.0, 0.0], "R_WH"),  # would broadcast into rows
    _bad("EyeToHandIdentifier.add", 1, np.eye(4), "R_WH"),
    _bad("EyeToHandIdentifier.add", 1, "R", "R_WH"),
    _bad("EyeToHandIdentifier.add", 2, [0.0, 0.0], "p_WH"),
    _bad("EyeToHandIdentifier.add", 2, [np.inf, 0.0, 0.0], "p_WH"),
    _bad("EyeToHandIdentifier.add", 2, [1e200, 0.0, 0.0], "p_WH"),  # A^T A overflows
    _bad("EyeToHandIdentifier.add_pose", 1, np.eye(3), "X_WH"),
    _bad("EyeToHandIdentifier.add_pose", 1, LAST_ROW, "X_WH"),
    _bad("EyeToHandIdentifier.sample_error", 3, None, "estimate"),
    _bad("EyeToHandIdentifier.solve", 0, "yes", "refine_estimate"),
    _bad("EyeToHandIdentifier.set_state", 0, [1.0, 2.0], "state"),
    _bad("EyeToHandIdentifier", 0, None, "forgetting_factor"),
    _bad("EyeToHandIdentifier", 0, 1.5, "forgetting_factor"),
    _bad("EyeToHandIdentifier", 1, "strict", "criteria"),
    _bad("PayloadIdentifier", 0, [0.0, 0.0, 0.0], "gravity_W"),
    _bad("PayloadIdentifier", 0, None, "gravity_W"),
    _bad("PayloadIdentifier.add", 0, WRENCH[:5], "wrench_K"),
    _bad("PayloadIdentifier.add", 0, [np.nan] * 6, "wrench_K"),
    _bad("PayloadIdentifier.add", 1, REFLECTION, "R_WK"),
    _bad("PayloadIdentifier.add", 1, SCALED, "R_WK"),
    _bad("PayloadIdentifier.sample_error", 2, np.ones(4), "x"),
    _bad("SustainableIdentifier", 0, None, "num_unknowns"),
    _bad("SustainableIdentifier", 0, 2.5, "num_unknowns"),
    _bad("SustainableIdentifier", 0, 10**9, "num_unknowns"),
    _bad("SustainableIdentifier", 1, "1", "forgetting_factor"),
    _bad("SustainableIdentifier.add", 0, None, "A_t"),
    _bad("SustainableIdentifier.add", 0, [[1.0, 2.0]], "A_t"),
    _bad("SustainableIdentifier.add", 0, np.zeros((0, 4)), "A_t"),
    _bad("SustainableIdentifier.add", 0, np.full((2, 4), np.nan), "not finite"),
    _bad("SustainableIdentifier.add", 0, np.ones((2, 4), complex), "A_t"),
    _bad("SustainableIdentifier.eigen", 0, "T", "T"),
    _bad("SustainableIdentifier.eigen", 0, np.full((4, 4), np.nan), "T"),
    _bad("SustainableIdentifier.sample_error", 0, None, "A"),
    _bad("SustainableIdentifier.sample_error", 1, np.ones(3), "x"),
    _bad("SustainableIdentifier.mean_squared_error", 0, [1.0], "x"),
    _bad("ConvergenceCriteria", 0, None, "max_expected_rms"),
    _bad("ConvergenceCriteria", 0, np.nan, "max_expected_rms"),
    _bad("ConvergenceCriteria", 1, 0.5, "min_gap_ratio"),
    _bad("ConvergenceCriteria", 2, "0.1", "max_ssd"),
    _bad("ConvergenceCriteria", 3, 2.5, "min_samples"),
    _bad("judge", 0, None, "criteria"),
    _bad("judge", 1, "20", "num_samples"),
    _bad("judge", 2, [1.0], "eigen"),
    _bad("judge", 3, None, "expected_rms"),
    _bad("judge", 4, 5, "constraint_problem"),
    # the math helpers
    _bad("eye_to_hand.build_A", 0, [1.0, 2.0], "p_CP"),
    _bad("eye_to_hand.build_A", 3, np.zeros((3, 15)), "out"),
    _bad("eye_to_hand.pack_x", 1, None, "p_WC"),
    _bad("eye_to_hand.predicted_points", 0, None, "estimate"),
    _bad("eye_to_hand.predicted_points", 1, X_WH[:, :3], "X_WH"),
    _bad("eye_to_hand.path_information", 0, STATE[:-1], "state"),
    _bad("eye_to_hand.path_information", 1, None, "paths"),
    _bad("eye_to_hand.path_information", 1, [(P_C, X_WH)], "paths"),
    _bad("eye_to_hand.path_information", 1, [(P_C[:3], X_WH, np.ones(N_BATCH))], "p_CP"),
    _bad("eye_to_hand.path_information", 1, [(P_C, X_WH, -np.ones(N_BATCH))], "w"),
    _bad("eye_to_hand.conditioning_transform", 0, np.zeros((16, 16)), "S"),
    _bad("eye_to_hand.conditioning_transform", 0, S16[:15], "S"),
    _bad("eye_to_hand.refine", 0, None, "S"),
    _bad("eye_to_hand.refine", 1, 0.0, "weight"),
    _bad("eye_to_hand.refine", 2, REFLECTION, "R"),
    _bad("eye_to_hand.refine", 3, [0.0, 0.0], "p_WC"),
    _bad("eye_to_hand.refine", 5, -1, "max_iterations"),
    _bad("eye_to_hand.refine", 6, np.nan, "tolerance"),
    _bad("eye_to_hand_points.refine_joint", 0, None, "S_list"),
    _bad("eye_to_hand_points.refine_joint", 0, [S16, None], "S_list[1]"),
    _bad("eye_to_hand_points.refine_joint", 1, SCALED, "R"),
    _bad("eye_to_hand_points.refine_joint", 3, [P2], "p_HP"),
    _bad("eye_to_hand_points.rotation_levers", 2, "p", "p_WC"),
    _bad("eye_to_hand_points.position_given_rotation", 2, NAN3, "R_WC"),
    _bad("eye_to_hand_points.camera_given_points", 1, [[1.0, 2.0]], "p_HP"),
    _bad("observability.eye_to_hand_standard_errors", 1, REFLECTION, "R"),
    _bad("observability.eye_to_hand_standard_errors", 2, np.nan, "sigma2"),
    _bad("observability.eye_to_hand_covariance", 0, S16[:15], "S"),
    _bad("observability.payload_covariance", 1, "n", "weight"),
    _bad("observability.payload_covariance", 2, np.ones(4), "x"),
    _bad("observability.region_95", 0, 0, "dimensions"),
    _bad("observability.region_95", 0, 1.5, "dimensions"),
    _bad("observability.radius_95", 0, np.ones((2, 3)), "covariance"),
    _bad("observability.radius_95", 0, np.full((3, 3), np.nan), "covariance"),
    _bad("eye_to_hand_points.spread_off_line", 0, NAN3, "covariance"),
    _bad("eye_to_hand_points.points_given_camera", 1, SCALED, "R_WC"),
    _bad("eye_to_hand_points.points_given_camera", 0, [S16[:4]], "S_list[0]"),
    _bad("eye_to_hand_points.refine_joint_weighted", 3, 0, "max_rounds"),
    _bad("eye_to_hand_points.refine_joint_weighted", 4, -1.0, "tolerance"),
    _bad("eye_to_hand_points.joint_covariance", 3, [P2], "p_HP"),
    _bad("eye_to_hand_points.joint_covariance", 4, [1.0, -1.0], "weights"),
    _bad("eye_to_hand_points.joint_covariance", 4, [1.0, np.nan], "weights"),
    _bad("eye_to_hand_points.joint_covariance", 6, [1.0, 0.0], "independent"),
    _bad("eye_to_hand_points.joint_covariance", 6, [1.0], "independent"),
    _bad("view_correlation.repeated_share", 0, VIEWS[:, :15], "views"),
    _bad("view_correlation.repeated_share", 0, -VIEWS, "views"),
    _bad("view_correlation.independent_samples", 0, "views", "views"),
    _bad("view_correlation.independent_samples", 1, S16[:15], "S"),
    _bad("view_correlation.independent_samples", 2, SCALED, "R_WC"),
    _bad("view_correlation.independent_samples", 4, [0.0, np.nan, 0.0], "p_HP"),
    _bad("eye_to_hand_points.position_and_points_given_rotation", 2, [1.0, -2.0], "independent"),
    _bad("eye_to_hand_points.position_and_points_given_rotation", 2, "two", "independent"),
    _bad("eye_to_hand_points.position_and_points_given_rotation", 0, [], "at least one statistic"),
    _bad("camera_turn.camera_after_turn", 0, None, "R_WC0"),
    _bad("camera_turn.camera_after_turn", 2, camera_turn.TurnAnchors(ZERO_ROW, Q0, B1), "b0"),
    _bad("camera_turn.camera_after_turn", 2, camera_turn.TurnAnchors(B0, Q0[:5], B1), "q0"),
    _bad("camera_turn.camera_after_turn", 2, (B0, Q0, B1), "anchors"),
    _bad("camera_turn.camera_after_turn", 5, 0, "min_points"),
    _bad("camera_turn.camera_after_turn", 6, 0, "iterations"),
    _bad("camera_turn.camera_after_turn", 7, -1e-3, "max_rotation_sd"),
    _bad("camera_turn.camera_after_turn", 7, "0.1", "max_rotation_sd"),
    _bad("payload.build_A", 2, None, "g_W"),
    _bad("batch.calibrate_eye_to_hand", 0, None, "p_C"),
    _bad("batch.calibrate_eye_to_hand", 1, X_WH[:, :3, :3], "X_WH"),
    _bad("batch.calibrate_eye_to_hand", 2, 5, "criteria"),
    _bad("batch.calibrate_eye_to_hand_points", 0, None, "points must be a mapping"),
    _bad("batch.calibrate_eye_to_hand_points", 0, {}, "points must be a mapping"),
    _bad("batch.calibrate_eye_to_hand_points", 0, {True: TRACKS["a"]}, "a label must be"),
    _bad("batch.calibrate_eye_to_hand_points", 0, {"": TRACKS["a"]}, "a label must be"),
    _bad("batch.calibrate_eye_to_hand_points", 0, {"a": P_C}, "points['a'] must be a pair"),
    _bad("batch.calibrate_eye_to_hand_points", 0, {"a": (np.arange(3), P_C[:3])}, "needs at least 4"),
    _bad("batch.calibrate_eye_to_hand_points", 0, {"a": (np.arange(N_BATCH), P_C[:, :2])}, "points['a'] p_C"),
    _bad("batch.calibrate_eye_to_hand_points", 0, {"a": (np.arange(N_BATCH - 1), P_C)}, "pair one to one"),
    _bad("batch.calibrate_eye_to_hand_points", 0, {"a": (np.arange(N_BATCH) + 1, P_C)}, "index of X_WH"),
    _bad("batch.calibrate_eye_to_hand_points", 0, {"a": (np.arange(N_BATCH) - 0.5, P_C)}, "not an index"),
    _bad("batch.calibrate_eye_to_hand_points", 0, {"a": (np.arange(N_BATCH) // 2, P_C)}, "sample 0 twice"),
    _bad("batch.calibrate_eye_to_hand_points", 0, {"a": ([np.nan] * N_BATCH, P_C)}, "samples"),
    _bad("batch.calibrate_eye_to_hand_points", 1, X_WH[:, :3, :3], "X_WH"),
    _bad("batch.calibrate_eye_to_hand_points", 2, 5, "criteria"),
    _bad("batch.identify_payload", 2, "down", "gravity_W"),
    _bad("batch.identify_payload", 1, np.tile(SCALED, (N_BATCH, 1, 1)), "R_WK"),
    _bad("batch.check_rotations", 1, [1.0, 2.0, 3.0], "R"),
    _bad("batch.eye_to_hand_residuals", 3, X_WH[:5], "pair one to one"),
    _bad("rotation.det3", 0, None, "X"),
    _bad("rotation.skew", 0, [1.0, 2.0], "w"),
    _bad("rotation.so3_exp", 0, [np.nan, 0.0, 0.0], "w"),
    _bad("rotation.rotation_angle", 0, SCALED, "R"),
    _bad("rotation.rotation_angle", 0, REFLECTION, "R"),
    _bad("rotation.project_to_rotation", 0, np.ones(8), "x9"),
    _bad("rotation.projection_parts", 0, "x9", "x9"),
    _bad("rotation.nearest_rotation", 0, NAN3, "M"),
    _bad("touch.Box", 0, (0.1, 0.2), "size"),
    _bad("touch.Box", 0, (0.1, -0.2, 0.3), "size"),
    _bad("touch.Cylinder", 1, None, "length"),
    _bad("touch.Sphere", 0, 0.0, "radius"),
    _bad("payload.posture_information", 0, _PAYLOAD.state[:-1], "state"),
    _bad("payload.posture_information", 0, None, "state"),
    _bad("payload.posture_information", 1, REFLECTION, "R_WK_candidates"),
    _bad("payload.posture_information", 1, [REFLECTION], "R_WK_candidates"),
    _bad("payload.posture_information", 2, [0.0, 9.81], "g_W"),
    _bad("payload.posture_information", 3, 0.0, "samples"),
    _bad("payload.posture_information", 3, "60", "samples"),
    _bad("PostureInformation", 1, -1.0, "samples"),
    _bad("PostureInformation", 0, None, "g_W"),
    _bad("PostureInformation.__call__", 1, np.ones((2, 3, 3)), "R_WK_candidates"),
    _bad("touch.predicted_wrench", 0, -1.0, "mass"),
    _bad("touch.predicted_wrench", 2, REFLECTION, "R_WK"),
    _bad("touch.line_of_action", 0, np.zeros(3), "f_c"),
    _bad("touch.locate_touch", 0, [np.nan] * 6, "residual_wrench"),
    _bad("touch.locate_touch", 1, "box", "shape"),
    _bad("touch.locate_touch", 2, LAST_ROW, "X_KG"),
    _bad("coordination.CoordinationRule", 0, 0.0, "allowable_error_factor"),
    _bad("coordination.CoordinationRule", 1, 2.5, "max_consecutive_violations"),
    _bad("coordination.CoordinationRule", 3, "a", "noise_rms"),
    _bad("coordination.CoordinationRule", 4, "yes", "adopt_refinements"),
    _bad("coordination.allowable_error", 1, np.nan, "expected_mse"),
    _bad("coordination.step", 0, None, "state"),
    _bad("coordination.step", 0, np.full(coordination.STATE_SIZE, np.inf), "state"),
    _bad("coordination.step", 1, None, "rule"),
    _bad("coordination.step", 2, np.inf, "time"),
    _bad("coordination.IdentifierReport", 0, "yes", "converged"),
    _bad("coordination.IdentifierReport", 1, "small", "expected_mse"),
    _bad("coordination.IdentifierReport", 2, -1, "sample_count"),
    _bad("coordination.IdentifierReport", 4, 2.5, "num_samples"),
    _bad("coordination.IdentifierReport", 5, -1, "refinement"),
    _bad("coordination.step", 3, (True, 1e-6, 5, 1e-7), "report"),
    _bad("coordination.step", 4, "yes", "camera_moving"),
    _bad("coordination.step", 5, -2, "camera_moves"),
    _bad("coordination.step", 7, np.nan, "camera_move_start"),
    _bad("coordination.step", 7, "soon", "camera_move_start"),
]


@pytest.mark.parametrize(("name", "args", "expected"), BAD_CALLS)
def test_bad_call_raises_one_line_identification_error(name, args, expected):
    with pytest.raises(IdentificationError) as info:
        _call(name, args)
    message = str(info.value)
    assert isinstance(info.value, ValueError)
    assert message and "\n" not in message
    assert expected in message


def test_a_name_with_line_breaks_still_gives_a_one_line_message():
    """``check_rotations`` names the array with the caller's text; a line break in it (found by the
    long fuzz) must not split the message."""
    for name, value in (("\n", False), ("rotations\nof the hand", np.full((2, 3, 3), np.nan)), ("", None)):
        with pytest.raises(IdentificationError) as e:
            batch.check_rotations(name, value)
        assert str(e.value).strip() and "\n" not in str(e.value)


def test_a_refused_sample_leaves_the_state_unchanged():
    ident = _filled_eye()
    state = ident.state
    for R_WH in (REFLECTION, SCALED, NAN3, [1.0, 0.0, 0.0]):
        with pytest.raises(IdentificationError, match="R_WH"):
            ident.add(P, R_WH, P2)
        assert np.array_equal(ident.state, state)
    ident.add(list(P), R.tolist(), tuple(P2))  # lists of the right shape are samples
    assert ident.num_samples == 21


# ---- the fuzz -----------------------------------------------------------------------------------
_scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-(2**70), 2**70), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=4), st.complex_numbers(max_magnitude=1e3),
)
_nested = st.recursive(_scalars, lambda inner: st.lists(inner, max_size=4) | st.tuples(inner, inner, inner),
                       max_leaves=12)  # fmt: skip
_arrays = npst.arrays(
    dtype=st.sampled_from([np.float64, np.float32, np.int64, np.bool_, np.complex128, np.dtype("U3")]),
    shape=npst.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=5),
)


def _mutated(valid: np.ndarray, how: str):
    """A valid array made slightly wrong (or only converted: some of these are valid)."""
    a = np.array(valid, dtype=float)
    flat = a.reshape(-1)
    if how == "nan" and flat.size:
        flat[flat.size // 2] = np.nan
    elif how == "inf" and flat.size:
        flat[0] = -np.inf
    elif how == "huge":
        a = a * 1e200
    elif how == "scale":
        a = a * 1.5
    elif how == "negate":
        a = -a
    elif how == "shorter":
        a = a[:-1]
    elif how == "longer":
        a = np.concatenate([a, a[:1]])
    elif how == "column":
        a = a.reshape(-1, 1)
    elif how == "transpose":
        a = a.T
    elif how == "list":
        return a.tolist()
    elif how == "int":
        return a.astype(np.int64)
    elif how == "float32":
        return a.astype(np.float32)
    return a


_MUTATIONS = ["nan", "inf", "huge", "scale", "negate", "shorter", "longer", "column", "transpose", "list",
              "int", "float32"]


@st.composite
def _argument(draw, valid):
    kind = draw(st.sampled_from(["valid", "valid", "mutated", "mutated", "scalar", "nested", "array"]))
    if kind == "valid" or (kind == "mutated" and not isinstance(valid, np.ndarray)):
        return valid
    if kind == "mutated":
        return _mutated(valid, draw(st.sampled_from(_MUTATIONS)))
    return draw({"scalar": _scalars, "nested": _nested, "array": _arrays}[kind])


@settings(max_examples=50000 if LONG else 2500, deadline=None, derandomize=not LONG,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])  # fmt: skip
@given(data=st.data())
@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # overflow in absurd but finite inputs
def test_fuzz_only_identification_errors(data):
    name = data.draw(st.sampled_from(sorted(TARGETS)), label="target")
    valid = TARGETS[name][1]
    args = tuple(data.draw(_argument(v), label=f"arg{k}") for k, v in enumerate(valid))
    try:
        _call(name, args)
    except IdentificationError as error:
        message = str(error)
        assert message and "\n" not in message, f"{name}: {message!r}"
