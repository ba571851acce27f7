"""The hand-eye metrics of the model in use on synthetic logs (no simulation): the tool point in use
against the physical point it follows, through a tool slip detected or not; the windows a change
excuses; wrong adoptions; which body an adopted point is on."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator

from sustain_drake.experiments import hand_eye
from sustain_drake.experiments import hand_eye_metrics as m
from sustain_drake.experiments.targets import TARGETS, target_bound
from sustain_drake.station import build_station
from sustain_drake.station.scenario import Scenario, ToolSlip

# A rod 50 mm square, 0.3 m long along z of its frame T, held 90 mm above the hand's origin.
ROD = (m.Box(RigidTransform([0.0, 0.0, 0.1]).GetAsMatrix4(), np.array([0.025, 0.025, 0.15])),)
X_HT_HELD = RigidTransform([0.0, 0.0, 0.09]).GetAsMatrix4()
# A slip: 40 mm along the rod and 0.35 rad about x (the scenario's ToolSlip).
X_HT_SLIPPED = RigidTransform(RollPitchYaw(0.35, 0.0, 0.0), [0.0, 0.0, 0.13]).GetAsMatrix4()
P_TP = np.array([0.025, 0.0, 0.2])  # a point on a side face of the rod, near its tip
P_WC = np.array([1.4, 0.0, 0.6])
TIMES = np.round(np.arange(0.0, 20.0, 0.1), 6)


def x_of(p_HP, p_WC=P_WC):
    return np.concatenate([np.eye(3).reshape(9, order="F"), p_WC, p_HP, [1.0]])


def run_log(slip_at=5.0, identify=None, readopt=None):
    """The logs of a run adopting ``P_TP`` at 1 s; the tool slips at ``slip_at``; with ``identify``
    the loop detects it then (IDENTIFY, the old model kept in ``adopted_x``) and adopts the moved
    point at ``readopt``. Returns (times, x_log, observing, X_HT_log, points)."""
    p_before = X_HT_HELD[:3, :3] @ P_TP + X_HT_HELD[:3, 3]
    p_after = X_HT_SLIPPED[:3, :3] @ P_TP + X_HT_SLIPPED[:3, 3]
    x_log = np.array([np.zeros(16) if t <= 1.0 else x_of(p_after if readopt and t > readopt else p_before)
                      for t in TIMES])
    observing = np.array([t > 1.0 and not (identify and identify <= t <= (readopt or np.inf)) for t in TIMES])
    X_HT_log = np.array([(X_HT_SLIPPED if t >= slip_at else X_HT_HELD).reshape(-1) for t in TIMES])
    points = [m.followed_point(1.0, p_before, X_HT_HELD, ROD)]
    if readopt:
        points.append(m.followed_point(readopt, p_after, X_HT_SLIPPED, ROD))
    return TIMES, x_log, observing, X_HT_log, points


def tool_errors(times, x_log, observing, X_HT_log, points):
    return m.tool_point_errors(times, x_log, observing, times, X_HT_log, points)


def test_an_undetected_slip_shows_as_a_large_tool_point_error_after_the_detection_target():
    times, x_log, observing, X_HT_log, points = run_log()
    errors = tool_errors(times, x_log, observing, X_HT_log, points)
    assert np.isnan(errors[times <= 1.0]).all()  # nothing adopted (the adoption's own sample too)
    assert np.nanmax(errors[times < 5.0]) < 1e-12  # the model follows its point until the slip
    moved = np.linalg.norm((X_HT_SLIPPED - X_HT_HELD)[:3, :3] @ P_TP + (X_HT_SLIPPED - X_HT_HELD)[:3, 3])
    windows = m.excused_windows([{"time_s": 5.0, "detected_s": None}], target_bound("hand_eye",
                                                                                    "detection_latency_s"))
    assert windows == [(5.0, 6.0)]  # never detected: only the detection target's second is excused
    worst = m.worst_tool_point(times, errors, windows)
    assert worst["error_mm"] == pytest.approx(1e3 * moved) and worst["error_mm"] > 40.0
    assert worst["at_s"] > 6.0
    assert m.tool_point_at(times, errors, times[-1])["error_mm"] == pytest.approx(1e3 * moved)
    later = m.before_next(times, errors, [{"time_s": 5.0}], float(times[-1]))
    assert later[0]["time_s"] == pytest.approx(times[-1] - 1.0) and later[0]["error_mm"] > 40.0


def test_a_detected_slip_is_excused_from_the_disturbance_to_its_detection():
    times, x_log, observing, X_HT_log, points = run_log(identify=5.3, readopt=12.0)
    errors = tool_errors(times, x_log, observing, X_HT_log, points)
    assert np.isnan(errors[(times >= 5.3) & (times <= 12.0)]).all()  # identifying: no tool point in use
    windows = m.excused_windows([{"time_s": 5.0, "detected_s": 5.3}], 1.0)
    assert windows == [(5.0, 5.3)]
    assert m.worst_tool_point(times, errors, windows)["error_mm"] < 1e-9  # the new point is followed
    stale = m.worst_tool_point(times, errors, [])  # the slip's 0.3 s before its detection
    assert stale["error_mm"] > 40.0 and 5.0 <= stale["at_s"] < 5.3
    later = m.before_next(times, errors, [{"time_s": 5.0}], float(times[-1]))
    assert later[0]["error_mm"] < 1e-9


def test_a_refinement_moves_the_model_not_the_followed_point():
    times, x_log, observing, X_HT_log, points = run_log(slip_at=np.inf)
    x_log[times > 8.0, 12] += 0.003  # a refinement 3 mm off the followed point at 8 s
    errors = tool_errors(times, x_log, observing, X_HT_log, points)
    assert m.worst_tool_point(times, errors, [])["error_mm"] == pytest.approx(3.0)


def test_a_point_on_the_tool_or_on_the_hand():
    on_tool = m.followed_point(1.0, X_HT_HELD[:3, 3] + [0.027, 0.0, 0.1], X_HT_HELD, ROD)
    assert on_tool.body == m.TOOL and on_tool.distance_to_tool == pytest.approx(0.002)
    assert np.allclose(on_tool.p_BP, [0.027, 0.0, 0.1])  # kept in T: moves with the tool
    p_HP_slipped = X_HT_SLIPPED[:3, :3] @ [0.027, 0.0, 0.1] + X_HT_SLIPPED[:3, 3]
    assert np.allclose(on_tool.p_HP(X_HT_SLIPPED), p_HP_slipped)
    palm_corner = np.array([0.045, 0.02, 0.05])  # 20 mm beside the rod, near its held end
    on_hand = m.followed_point(1.0, palm_corner, X_HT_HELD, ROD)
    assert on_hand.body == m.HAND and on_hand.distance_to_tool == pytest.approx(0.02)
    assert np.allclose(on_hand.p_HP(X_HT_SLIPPED), palm_corner)  # stays where it is in H
    no_tool = m.followed_point(1.0, [0.0, 0.0, 0.1], np.eye(4), ())
    assert no_tool.body == m.HAND and no_tool.distance_to_tool == np.inf
    assert m.distance_to_boxes([0.0, 0.0, 0.1], ROD) == 0.0  # inside


def test_wrong_adoptions_are_counted():
    good = {"time_s": 10.0, "feature_id": 1, "kind": "identified", "body": "tool",
            "camera_position_error_mm": 0.8, "camera_rotation_error_deg": 0.05, "true_point_error_mm": 1.0}
    adopted = [good, {**good, "time_s": 20.0, "camera_position_error_mm": 11.6},
               {**good, "time_s": 30.0, "camera_rotation_error_deg": 0.6},
               {**good, "time_s": 40.0, "true_point_error_mm": 89.0, "body": "hand"}]
    wrong = m.wrong_adoptions(adopted)
    assert [w["time_s"] for w in wrong] == [20.0, 30.0, 40.0]
    assert wrong[2]["body"] == "hand" and wrong[2]["true_point_error_mm"] == 89.0
    targets = {t.name: t for t in TARGETS["hand_eye"]}
    assert not targets["wrong_adoptions"].met({"num_wrong_adoptions": len(wrong)})
    assert targets["wrong_adoptions"].met({"num_wrong_adoptions": 0})


def test_an_undetected_camera_move_cannot_hide_a_stale_camera():
    x_log = np.array([np.zeros(16) if t <= 1.0 else x_of(np.zeros(3)) for t in TIMES])
    X_WC = np.array([RigidTransform(P_WC + ([0.0, 0.05, 0.0] if t >= 5.0 else 0.0)).GetAsMatrix4().reshape(-1)
                     for t in TIMES])
    undetected = m.excused_windows([{"time_s": 5.0, "detected_s": None}], 1.0)
    observing = np.ones(len(TIMES), bool)
    worst = m.worst_model_in_use(TIMES, x_log, observing, TIMES, X_WC, undetected)
    assert worst["camera_position_error_mm"] == pytest.approx(50.0) and worst["position_at_s"] > 6.0
    detected_late = m.excused_windows([{"time_s": 5.0, "detected_s": 30.0}], 1.0)
    late = m.worst_model_in_use(TIMES, x_log, observing, TIMES, X_WC, detected_late)
    assert late["camera_position_error_mm"] < 1e-9
    # Detected at 6 s: the loop identifies from then on (no model vouched for), until it observes
    # again at 15 s with a camera where the truth is.
    detected = m.excused_windows([{"time_s": 5.0, "detected_s": 6.0}], 1.0)
    again = TIMES >= 15.0
    x_again = np.array([x if t < 15.0 else x_of(np.zeros(3), P_WC + [0.0, 0.05, 0.0])
                        for t, x in zip(TIMES, x_log, strict=True)])
    worst = m.worst_model_in_use(TIMES, x_again, (TIMES <= 6.0) | again, TIMES, X_WC, detected)
    assert worst["camera_position_error_mm"] < 1e-9
    # Counted while observing: the stale camera kept after the detection is the one in use.
    kept = m.worst_model_in_use(TIMES, x_again, observing, TIMES, X_WC, detected)
    assert kept["camera_position_error_mm"] == pytest.approx(50.0)


def test_the_tool_point_in_use_target_reads_its_worst():
    target = {t.name: t for t in TARGETS["hand_eye"]}["tool_point_in_use_mm"]
    assert target.met({"tool_point_in_use_worst": {"error_mm": 1.2, "at_s": 30.0}})
    assert not target.met({"tool_point_in_use_worst": {"error_mm": 89.0, "at_s": 80.0}})
    assert not target.met({"tool_point_in_use_worst": None})  # never in use is not a pass


def test_the_station_gives_the_tool_pose_in_the_hand_and_the_tool_geometry():
    """``true_X_HT`` carries the tracked point (``true_p_HP``) through a slip; the held tool's geometry
    read from the plant's SceneGraph bounds the rod (its tip, 0.25 m along z of T, on its surface)."""
    s = Scenario()
    s.camera.rgb = s.camera.depth = s.camera.label = False
    s.distractor.enabled = False
    s.motion.joint_ranges = [[q, q] for q in s.motion.initial_posture]
    s.disturbances = [ToolSlip(time=0.2, slide=0.03, pivot=0.3, duration=0.05)]
    station = build_station(s)
    simulator = Simulator(station)
    context = simulator.get_context()
    p_TP = np.array([0.0, 0.0, 0.25])  # the rod's tracked tip
    for t in (0.1, 0.6):
        simulator.AdvanceTo(t)
        X_HT = station.GetOutputPort("true_X_HT").Eval(context)
        np.testing.assert_allclose(X_HT @ p_TP, station.GetOutputPort("true_p_HP").Eval(context), atol=1e-12)
    assert X_HT.translation()[2] == pytest.approx(0.09 + 0.03, abs=3e-3)  # slid 30 mm along z
    boxes = hand_eye.tool_boxes(station)
    assert len(boxes) >= 1 and m.distance_to_boxes(p_TP, boxes) < 1e-9
    assert m.distance_to_boxes(p_TP + [0.0, 0.0, 0.01], boxes) == pytest.approx(0.01)
    s.tool.model, s.disturbances = "none", []
    assert hand_eye.tool_boxes(build_station(s)) == ()
