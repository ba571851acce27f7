"""The hand-eye station holding the ChArUco board, driven posture by posture for the marker-based
baseline (``bench_baseline_hand_eye.py``): the babbling's stops and one RGB-D image at each.

The arm goes through the postures the scenario's babbling draws (the station's own
``MotionGenerator``, run alone with a rest of ``SETTLE`` s after each move, its ``dwell``): a
stop is a rest of the generator's desired state, taken when the rest ends. No closed loop runs: the
plant's context is set to the stop's posture (the arm settled exactly there) and the station's
RGB-D sensor is evaluated, with the station's depth noise for that frame (``RgbdCameraSampler``'s:
seeded by the scenario's seed and the frame's index; the station adds no colour noise).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from pydrake.systems.analysis import Simulator

from sustain_drake.perception.charuco import BOARD, CharucoFinder, corner_points
from sustain_drake.perception.optical_flow import PinholeIntrinsics
from sustain_drake.station import Scenario, build_station, camera_info
from sustain_drake.station.scenario import arm_motion, arm_of
from sustain_drake.systems.depth_noise import DepthNoiseModel
from sustain_drake.systems.motion_generator import MotionGenerator

# s of rest after each move before the image is taken (the arm settles on its PD; a frame at 30 Hz
# comes within it). Part of the collect time the bench reports.
SETTLE = 0.5
TOOL = "charuco_board"


@dataclass(frozen=True)
class Stop:
    """A rest of the babbling: the arm's joint angles (rad) and when the rest ends (s from the start)."""

    q: np.ndarray
    time: float


def holding_the_board(scenario: Scenario) -> Scenario:
    """``scenario`` with the ChArUco board in the gripper at the nominal grasp instead of its tool."""
    tool = dataclasses.replace(scenario.tool, model=TOOL, slide=0.0, pivot=0.0)
    return dataclasses.replace(scenario, tool=tool, disturbances=[])


def joint_ranges(scenario: Scenario, plant, arm) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(lower, upper, q0)``: the babbling's ranges clipped to the arm's joint limits and its initial
    posture clipped to them, as the station gives them to its motion generator."""
    joints = [plant.GetJointByName(name, arm) for name in arm_of(scenario).joints]
    limits_lo = np.array([j.position_lower_limits()[0] for j in joints])
    limits_hi = np.array([j.position_upper_limits()[0] for j in joints])
    ranges = np.asarray(arm_motion(scenario).joint_ranges, float)
    lower, upper = np.maximum(ranges[:, 0], limits_lo), np.minimum(ranges[:, 1], limits_hi)
    q0 = np.clip(arm_motion(scenario).initial_posture, limits_lo, limits_hi)
    return lower, upper, np.clip(q0, lower, upper)


def babbling_stops(scenario: Scenario, lower, upper, q0, count: int) -> list[Stop]:
    """The first ``count`` stops of the scenario's babbling with a rest of ``SETTLE`` s after each move:
    the ``MotionGenerator`` simulated alone, its desired state read between its updates (a rest is
    where the desired velocity is exactly zero)."""
    m = arm_motion(scenario)
    generator = MotionGenerator(lower, upper, q0, seed=m.seed, max_speed=m.max_speed,
                                min_duration=m.min_duration, dwell=SETTLE, period=m.period)
    simulator = Simulator(generator)
    context = generator.GetMyContextFromRoot(simulator.get_mutable_context())
    n, dt = len(q0), m.period
    stops, rest, k = [], None, 0
    while len(stops) < count:
        t = (k + 0.5) * dt  # between two updates: the state is settled there
        simulator.AdvanceTo(t)
        state = generator.get_output_port().Eval(context)
        if np.max(np.abs(state[n:])) < 1e-9:
            rest = state[:n].copy()
        elif rest is not None:
            stops.append(Stop(rest, t - dt / 2))  # the rest ended at the previous update
            rest = None
        k += 1
    return stops


@dataclass(frozen=True)
class Shot:
    """One image at a stop: colour (H x W x 3, uint8), depth (H x W, m, with the station's noise),
    the hand's pose ``X_WH`` and the board's ``X_WB`` (4 x 4, ground truth)."""

    color: np.ndarray
    depth: np.ndarray
    X_WH: np.ndarray
    X_WB: np.ndarray


class BoardScene:
    """The station of ``scenario`` holding the board (``holding_the_board``), its arm set posture by
    posture; ``X_WC`` is the camera's true pose (the head does not move)."""

    def __init__(self, scenario: Scenario):
        self.scenario = holding_the_board(scenario)
        self.station = build_station(self.scenario)
        self._context = self.station.CreateDefaultContext()
        self.plant = self.station.GetSubsystemByName("plant")
        self._sensor = self.station.GetSubsystemByName("rgbd_sensor")
        self._plant_context = self.plant.GetMyMutableContextFromRoot(self._context)
        self._sensor_context = self._sensor.GetMyContextFromRoot(self._context)
        self.arm = self.plant.GetModelInstanceByName(self.scenario.arm.model)
        self._joints = [self.plant.GetJointByName(name, self.arm) for name in arm_of(self.scenario).joints]
        self._hand = self.plant.GetBodyByName(arm_of(self.scenario).hand_body, self.arm)
        self._board = self.plant.GetFrameByName("charuco")
        info = camera_info(self.scenario)
        self.intrinsics = PinholeIntrinsics(info.width(), info.height(), info.focal_x(), info.focal_y(),
                                            info.center_x(), info.center_y())
        self.X_WC = self.station.GetOutputPort("true_X_WC").Eval(self._context).GetAsMatrix4()
        noise = self.scenario.depth_noise
        self._noise = DepthNoiseModel(noise.a, noise.b, noise.z0) if noise.enabled else None
        self._noise_seed = noise.seed
        self.finder = CharucoFinder(BOARD)

    def joint_ranges(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return joint_ranges(self.scenario, self.plant, self.arm)

    def tracked_corner(self) -> int:
        """The ChArUco corner the tool's ``tracked_point`` frame marks (the one point of "ours")."""
        X_BT = self._board.GetFixedPoseInBodyFrame().inverse()
        p_BQ = X_BT @ self.plant.GetFrameByName("tracked_point").GetFixedPoseInBodyFrame().translation()
        distances = np.linalg.norm(corner_points(BOARD) - p_BQ, axis=1)
        if distances.min() > 1e-6:
            raise ValueError("the board's tracked_point is no ChArUco corner")
        return int(np.argmin(distances))

    def shot(self, q, time: float) -> Shot:
        """The image at joint angles ``q`` taken at ``time`` (s: sets the depth noise's frame)."""
        for joint, angle in zip(self._joints, q, strict=True):
            joint.set_angle(self._plant_context, float(angle))
        color = np.array(self._sensor.color_image_output_port().Eval(self._sensor_context).data[:, :, :3])
        depth = np.array(self._sensor.depth_image_32F_output_port().Eval(self._sensor_context).data[:, :, 0])
        if self._noise is not None:
            frame = math.floor(time * self.scenario.camera.fps + 1e-6)
            depth = self._noise.apply(depth, np.random.default_rng([self._noise_seed, frame]))
        X_WH = self.plant.EvalBodyPoseInWorld(self._plant_context, self._hand).GetAsMatrix4()
        X_WB = self._board.CalcPoseInWorld(self._plant_context).GetAsMatrix4()
        return Shot(color, depth, X_WH, X_WB)
