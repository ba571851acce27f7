"""Scenario validation: the accepted range of every numeric key (``RANGES``), the fixed poses
(``POSES``), Drake's enum-like strings and the sections' consistency. ``validate_scenario`` runs
before anything is built (the loaders, ``with_seed``, ``build_station`` and the sweeps call it);
every problem is a one-line ``ScenarioError`` naming the key and what it accepts."""

import dataclasses
import math

import numpy as np
from pydrake.common.schema import Rotation, Transform
from pydrake.geometry import LightParameter, Rgba
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.systems.sensors import CameraConfig

from sustain_drake.identification.differentiation import savitzky_golay_weights
from sustain_drake.loops.body_detection import BodyDetectionConfig
from sustain_drake.loops.hand_eye import HandEyeConfig, hand_eye_parts
from sustain_drake.loops.identify_observe import CoordinationConfig
from sustain_drake.loops.payload import (
    PAYLOAD_MODES,
    DynamicPayloadConfig,
    KinestheticConfig,
    QuasiStaticConfig,
)
from sustain_drake.perception.camera_motion import CameraMotionParams
from sustain_drake.station.models import ARMS
from sustain_drake.station.random_disturbances import SETTLE, RandomDisturbances
from sustain_drake.station.scenario import (
    TOOL_MODELS,
    DepthNoiseConfig,
    DistractorConfig,
    HeadConfig,
    HeadMove,
    MotionConfig,
    Scenario,
    ScenarioError,
    ToolConfig,
    ToolSlip,
    Touch,
    TouchMotionConfig,
    TouchTarget,
    WrenchSensorConfig,
    arm_motion,
    one_line,
    timeline,
)
from sustain_drake.station.scenario_yaml import schema_fields, shown
from sustain_drake.systems.depth_noise import DepthNoiseModel


@dataclasses.dataclass(frozen=True)
class Range:
    """The accepted values of a numeric key: ``low`` to ``high`` in ``unit`` (``low`` excluded when
    ``above``); ``off_inf``: .inf is accepted too (it turns a rule off)."""

    low: float
    high: float
    unit: str = ""
    above: bool = False
    off_inf: bool = False
    note: str = ""  # why, when the range alone does not say

    def accepts(self, value) -> bool:
        if self.off_inf and value == math.inf:
            return True
        if isinstance(value, float) and not math.isfinite(value):
            return False
        return (value > self.low if self.above else value >= self.low) and value <= self.high

    def words(self, integer: bool) -> str:
        unit = f" {self.unit}" if self.unit else ""
        if integer:
            text = (f"a whole number >= {self.low:g}" if self.high == math.inf
                    else f"a whole number from {self.low:g} to {self.high:g}")
        elif self.low == self.high:
            text = f"{self.low:g}{unit}"
        elif self.above:
            text = f"a number above {self.low:g} and at most {self.high:g}{unit}"
        else:
            text = f"a number from {self.low:g} to {self.high:g}{unit}"
        return text + (" (or .inf: off)" if self.off_inf else "") + (f" ({self.note})" if self.note else "")


def _from(low: float, high: float, unit: str = "", **kw) -> Range:
    return Range(low, high, unit, **kw)


def _above(low: float, high: float, unit: str = "", **kw) -> Range:
    return Range(low, high, unit, above=True, **kw)


DAY = 86400.0  # s: the longest time a scenario states (a run, a delay)
HOUR = 3600.0
ANGLE = _from(-2 * math.pi, 2 * math.pi, "rad")  # a joint angle
SEED = _from(0, math.inf)  # any integer >= 0
COUNT = _from(0, 10_000_000)  # samples, trials
AT_LEAST_ONE = _from(1, 10_000_000)
TIME = _from(0, DAY, "s")
WAIT = _from(0, HOUR, "s")
SPAN = _above(0, HOUR, "s")
FRACTION = _from(0, 1)
PIXELS = _from(0, 4096, "px")

# The ranges, by the section's class and the key: physical ranges, and upper bounds that keep a run
# feasible (a 1 GHz sensor or a billion candidates would never finish). A list's range is its items'.
RANGES: dict[type, dict[str, Range]] = {
    Scenario: {"duration": _above(0, DAY, "s")},
    MultibodyPlantConfig: {
        # discrete, for the PD-controlled actuators; 10 us at least, or a run never ends
        "time_step": _from(1e-5, 0.01, "s"),
        "penetration_allowance": _above(0, 1, "m"),
        "stiction_tolerance": _above(0, 1, "m/s"),
        "sap_near_rigid_threshold": _from(0, 10),
    },
    CameraConfig: {
        "width": _from(1, 4096), "height": _from(1, 4096),
        "center_x": _above(0, 4096, "px"), "center_y": _above(0, 4096, "px"),
        "clipping_near": _above(0, 100, "m"), "clipping_far": _above(0, 1000, "m"),
        "z_near": _above(0, 100, "m"), "z_far": _above(0, 100, "m"),
        "fps": _above(0, 240, "Hz"),
        "capture_offset": _from(0, 0, "s", note="the station renders frame k at t = k / fps"),
        "output_delay": _from(0, 0, "s", note="the station renders frame k at t = k / fps"),
    },
    CameraConfig.FocalLength: {"x": _above(0, 100_000, "px"), "y": _above(0, 100_000, "px")},
    CameraConfig.FovDegrees: {"x": _above(0, 170, "deg"), "y": _above(0, 170, "deg")},
    Rgba: {"rgba": FRACTION},
    # the camera's lights: Drake's default intensity is 1; a spot's cone_angle is its half-angle
    LightParameter: {"intensity": _from(0, 100), "cone_angle": _from(0, 90, "deg"),
                     "position": _from(-100, 100, "m"), "direction": _from(-1000, 1000),
                     "attenuation_values": _from(0, 1000)},
    HeadConfig: {"pan": _from(-math.pi, math.pi, "rad"), "tilt": _from(-math.pi, math.pi, "rad")},
    ToolConfig: {
        # a slip in the grasp: up to half the rod's length, a quarter turn
        "slide": _from(-0.15, 0.15, "m"), "pivot": _from(-math.pi / 2, math.pi / 2, "rad"),
        "gripper_position": _from(0, 0.03, "m"),  # the finger's travel
    },
    MotionConfig: {
        "seed": SEED, "joint_ranges": ANGLE, "initial_posture": ANGLE,
        "max_speed": _above(0, 10, "rad/s"), "min_duration": SPAN, "dwell": WAIT,
        "confirm_hold": WAIT, "confirm_step": _from(0, math.pi, "rad"),
        "confirm_near": _from(0, 2 * math.pi, "rad"), "period": _from(1e-4, 1, "s"),
    },
    WrenchSensorConfig: {
        "rate": _above(0, 10_000, "Hz"), "force_noise": _from(0, 100, "N"),
        "torque_noise": _from(0, 10, "N m"), "bias": _from(-1000, 1000, "N m or N"), "seed": SEED,
    },
    DepthNoiseModel: {"a": _from(0, 1, "m"), "b": _from(0, 1, "1/m"), "z0": _from(0, 100, "m")},
    DepthNoiseConfig: {"a": _from(0, 1, "m"), "b": _from(0, 1, "1/m"), "z0": _from(0, 100, "m"),
                       "seed": SEED},
    DistractorConfig: {"waypoints": _from(-50, 50, "m"), "speed": _above(0, 10, "m/s"),
                       "start_time": TIME},
    ToolSlip: {"time": TIME, "slide": _from(-0.15, 0.15, "m"),
               "pivot": _from(-math.pi / 2, math.pi / 2, "rad"), "duration": SPAN},
    HeadMove: {"time": TIME, "pan": _from(-math.pi, math.pi, "rad"),
               "tilt": _from(-math.pi, math.pi, "rad"), "duration": SPAN},
    # A slip's or a turn's size within a change ToolSlip and HeadMove accept; a soak of days at most.
    RandomDisturbances: {
        "seed": SEED, "start_time": TIME, "interval": _from(SETTLE, DAY, "s"),
        "slip_probability": FRACTION, "slide": _from(0, 0.15, "m"), "pivot": _from(0, math.pi / 2, "rad"),
        "slide_limit": _from(0, 0.15, "m"), "pivot_limit": _from(0, math.pi / 2, "rad"),
        "slip_duration": SPAN, "turn": _from(0, 1, "rad"), "turn_limit": _from(0, math.pi, "rad"),
        "turn_duration": SPAN,
    },
    Touch: {"time": TIME, "duration": SPAN, "p_TQ": _from(-1, 1, "m"), "f_T": _from(-1000, 1000, "N")},
    TouchTarget: {"p_TQ": _from(-1, 1, "m"), "down_T": _from(-1000, 1000), "p_WQ": _from(-5, 5, "m")},
    TouchMotionConfig: {
        "approach_height": _above(0, 1, "m"), "retreat_height": _above(0, 2, "m"),
        "press_depth": _above(0, 0.5, "m"), "descend_speed": _above(0, 1, "m/s"),
        "press_extra": _from(0, 0.5, "m"), "keep_touching": WAIT, "start_delay": TIME, "rest": WAIT,
        "max_speed": _above(0, 10, "rad/s"),
    },
    BodyDetectionConfig: {
        "grid_rows": _from(1, 512), "grid_cols": _from(1, 512), "max_corners": _from(1, 10_000),
        "min_distance_px": PIXELS, "quality_level": _above(0, 1), "tau_a": _above(0, 60, "s"),
        "tau_s": _above(0, 60, "s"), "adot_threshold": _from(0, 100, "rad/s"),
        "sdot_threshold": _from(0, 100_000, "px/s"), "alpha": _above(0, 0.999),
        "p_response": _above(0, 0.999), "body_onset_rate": _above(0, 1000, "1/s"),
        "memory": _above(0, DAY, "s"), "response_window": _above(0, 60, "s"),
        "posture_tolerance": _above(0, 2 * math.pi, "rad"), "confirm_timeout": SPAN,
        "request_interval": WAIT, "max_sequence_trials": _from(0, 10_000),
        "feature_hits": _from(1, 10_000), "feature_flow_threshold_px": _above(0, 1000, "px"),
        "body_cover": FRACTION, "snapshot_times": TIME,
    },
    CoordinationConfig: {
        "max_expected_rms": _above(0, 100), "min_gap_ratio": _from(1, 1e12), "max_ssd": _above(0, 100),
        "min_samples": AT_LEAST_ONE, "forgetting_factor": _above(0, 1),
        "allowable_error_factor": _above(0, 1e9), "max_consecutive_violations": AT_LEAST_ONE,
        "pause_after_convergence": WAIT, "noise_rms": _from(0, 100),
    },
    CameraMotionParams: {
        "min_background": _from(3, 10_000), "anchor_time": _from(0, 60, "s"),
        "inlier_px": _above(0, 100, "px"), "min_inlier_fraction": _above(0, 1),
        "still_px": _from(0, 100, "px"), "feature_still_px": _from(0, 100, "px"),
        "arm_speed": _from(0, 100, "rad/s"), "rest_frames": _from(1, 1000),
        "min_frames": _from(1, 1000), "move_px": _above(0, 4096, "px"),
        "view_still_px": _from(0, 100, "px"), "turn_frames": _from(0, 1000),
    },
    HandEyeConfig: {
        "max_hand_radius": _above(0, 5, "m"), "tool_radius": _above(0, 5, "m", off_inf=True),
        "min_samples": AT_LEAST_ONE, "max_expected_rms": _above(0, 100, "m"),
        "allowable_error_factor": _above(0, 1e9), "max_consecutive_violations": AT_LEAST_ONE,
        "pause_after_convergence": WAIT, "max_candidates": _from(1, 64),
        "identifying_motion_interval": WAIT, "identifying_motion_max_hold": WAIT,
        "identifying_motion_reach": _from(0, 2 * math.pi, "rad"),
        "false_alarm_window": WAIT, "log_rate": _above(0, 1000, "Hz"),
    },
    KinestheticConfig: {"period": _from(1e-4, 1, "s"), "min_touch_force": _from(0, 1000, "N"),
                        "eval_min_force": _from(0, 1000, "N")},
    DynamicPayloadConfig: {"torque_length": _above(0, 10, "m"), "encoder_window": _from(3, 1001),
                           "encoder_order": _from(2, 20), "wrench_delay": _from(0, 1, "s")},
    QuasiStaticConfig: {
        "max_joint_speed": _above(0, 10, "rad/s"), "max_joint_acceleration": _above(0, 100, "rad/s^2"),
        "window": _from(0, 60, "s"), "touch_holdoff": WAIT, "max_touch_duration": _above(0, DAY, "s"),
    },
}

# The largest translation (m, per axis) of each fixed pose, and the frame it is measured in.
POSES = {"head.X_WP": (5.0, "the world"), "tool.X_GT": (0.5, "the grasp frame G"),
         "camera.X_PB": (1.0, None), "camera.X_BC": (1.0, "the camera body B"),
         "camera.X_BD": (1.0, "the camera body B")}

# Drake's accepted strings of a light (LightParameter, as RenderEngineVtk reads it).
LIGHT_STRINGS = {"type": ("point", "spot", "directional"), "frame": ("world", "camera")}
# Drake's accepted strings (MultibodyPlantConfig; see its documentation).
PLANT_STRINGS = {
    "contact_model": ("point", "hydroelastic", "hydroelastic_with_fallback"),
    "discrete_contact_approximation": ("lagged", "sap", "similar", "tamsi", ""),
    "contact_surface_representation": ("polygon", "triangle"),
}


def range_of(section: type, key: str) -> Range | None:
    """The accepted range of ``key`` of a section of class ``section`` (None: none stated)."""
    for cls in getattr(section, "__mro__", (section,)):
        if key in RANGES.get(cls, {}):
            return RANGES[cls][key]
    return None


def _check(condition: bool, message: str) -> None:
    if not condition:
        raise ScenarioError(message)


def _section_items(section):
    """``(key, value)`` of a dataclass or a Drake schema object (e.g. CameraConfig)."""
    fields = schema_fields(type(section))
    return [(name, getattr(section, name)) for name in fields] if fields is not None else []


def _check_numbers(section, path: str) -> None:
    """Every number below ``section`` finite and in its range, every fixed pose fixed and finite."""
    for key, value in _section_items(section):
        where = f"{path}.{key}" if path else key
        _check_value(type(section), key, value, where)


def _check_value(section: type, key: str, value, where: str) -> None:
    if isinstance(value, Transform):
        _fixed_pose(value, where)
    elif isinstance(value, bool | str | None):
        return
    elif isinstance(value, int | float | np.integer | np.floating):
        accepted = range_of(section, key)
        integer = isinstance(value, int | np.integer)
        if accepted is None:
            _check(integer or math.isfinite(value), f"{where} must be a finite number, got {shown(value)}")
        else:
            _check(accepted.accepts(value), f"{where} must be {accepted.words(integer)}, got {shown(value)}")
    elif isinstance(value, list | tuple | np.ndarray):
        for i, item in enumerate(value):
            _check_value(section, key, item, f"{where}[{i}]")
    elif schema_fields(type(value)) is not None:
        _check_numbers(value, where)


def _fixed_pose(transform: Transform, where: str) -> RigidTransform:
    """The fixed pose a scenario's Transform states, or a ScenarioError (random, NaN, not a rotation,
    too far); checked before Drake's own checks, which end the process."""
    bound, frame = POSES.get(where, (10.0, None))
    rotation = transform.rotation.value
    if isinstance(rotation, Rotation.AngleAxis) and isinstance(rotation.axis, np.ndarray):
        axis = rotation.axis
        _check(bool(np.all(np.isfinite(axis))) and np.linalg.norm(axis) > 1e-9,
               f"{where}.rotation: !AngleAxis needs a finite, non-zero axis, got {shown(axis)}")
    _check(transform.IsDeterministic(), f"{where} must be a fixed pose, not a random one (!Uniform, "
           "!Gaussian): give fixed numbers")
    if frame is not None:
        base = transform.base_frame
        unset = base in (None, "") or (frame == "the world" and base == "world")
        _check(unset, f"{where}.base_frame: this pose is always in {frame}; leave base_frame out")
    try:
        X = transform.GetDeterministicValue()
        p, R = X.translation(), X.rotation().matrix()
    except Exception:  # noqa: BLE001 (Drake refuses a NaN rotation)
        raise ScenarioError(f"{where}: the translation and rotation must be finite numbers") from None
    _check(bool(np.all(np.isfinite(p)) and np.all(np.isfinite(R))),
           f"{where}: the translation and rotation must be finite numbers")
    _check(bool(np.all(np.abs(p) <= bound)),
           f"{where}.translation must be within {bound:g} m on each axis, got {shown(p)}")
    _check(bool(np.allclose(R @ R.T, np.eye(3), atol=1e-6)) and np.linalg.det(R) > 0,
           f"{where}.rotation is not a rotation")
    return X


def validate_scenario(s: Scenario, *, experiments: bool = False) -> None:
    """Rejects values the simulation cannot use, before anything is built: so no NaN, nonsense or
    Drake-internal failure reaches the systems. Checks, in order: the enum-like strings, every number
    finite and in its range (``RANGES``; seeds any integer >= 0), the fixed poses (``POSES``), the
    lists' shapes, the timeline against the tool, the math layer's own settings checks and, with
    ``experiments``, what each enabled experiment needs of the world (the images it uses). The
    loaders and ``with_seed`` check it all; ``build_station`` builds the world alone and an
    experiment checks its needs again when it is added. Raises a one-line ``ScenarioError`` naming
    the key."""
    try:
        _validate(s)
        if experiments:
            _check_experiments(s)
    except ScenarioError:
        raise
    except (TypeError, ValueError, AttributeError, OverflowError) as e:  # a value of the wrong type
        raise ScenarioError(f"a value has the wrong type: {one_line(e)}") from None


def _validate(s: Scenario) -> None:
    _check(isinstance(s.arm.model, str) and s.arm.model in ARMS,
           f"arm.model must be one of {', '.join(ARMS)}, got {shown(s.arm.model)}")
    _check(s.tool.model in TOOL_MODELS, f"tool.model must be one of {', '.join(TOOL_MODELS)}, "
           f"got {shown(s.tool.model)}")
    _check(s.kinesthetic.mode in PAYLOAD_MODES, f"kinesthetic.mode must be one of "
           f"{', '.join(PAYLOAD_MODES)}, got {shown(s.kinesthetic.mode)}")
    for key, accepted in PLANT_STRINGS.items():
        value = getattr(s.plant_config, key)
        _check(value in accepted, f"plant_config.{key} must be one of "
               f"{', '.join(repr(a) for a in accepted)}, got {shown(value)}")
    _check(isinstance(s.camera.renderer_class, str) and s.camera.renderer_class in ("", "RenderEngineVtk"),
           "camera.renderer_class: only Drake's VTK renderer is supported (headless): leave it out")
    _check_numbers(s, "")
    _check_lights(s.lights)

    m, n = arm_motion(s), len(ARMS[s.arm.model].joints)
    arm = f" (arm.model {s.arm.model} has {n} joints)" if s.arm.model != "arm" else ""
    _check(len(m.joint_ranges) == n and all(len(r) == 2 and r[0] <= r[1] for r in m.joint_ranges),
           f"motion.joint_ranges needs {n} [lower, upper] pairs with lower <= upper{arm}")
    _check(len(m.initial_posture) == n,
           f"motion.initial_posture needs {n} angles, got {len(m.initial_posture)}{arm}")
    _check(len(s.wrench_sensor.bias) == 6,
           "wrench_sensor.bias needs 6 numbers [tau_x, tau_y, tau_z, f_x, f_y, f_z]")
    p = s.distractor
    _check(len(p.waypoints) >= 2 and all(len(w) == 2 for w in p.waypoints),
           "distractor.waypoints needs at least 2 [x, y] points")
    _check(float(np.sum(np.linalg.norm(np.diff(np.asarray(p.waypoints, float), axis=0), axis=1))) > 1e-6,
           "distractor.waypoints are all the same point: give a path to walk")
    try:
        s.camera.MakeCameras()  # the intrinsics, the depth and clipping ranges
    except Exception as e:  # noqa: BLE001
        raise ScenarioError(f"camera: {one_line(e)}") from None
    b = s.body_detection
    _check(b.grid_rows <= s.camera.height and b.grid_cols <= s.camera.width,
           f"body_detection: a {b.grid_rows} x {b.grid_cols} grid is finer than the "
           f"{s.camera.width} x {s.camera.height} image (grid_rows <= camera.height, grid_cols <= "
           "camera.width)")
    _check_timeline(s)
    _check(not s.kinesthetic.enabled or s.tool.model == "box", "kinesthetic: needs tool.model: box "
           "(the tool with a collision shape to locate touches on)")
    # A static compensation leaves the gripper's inertial wrench in the reading; the dynamic payload
    # identification (the kinesthetic loop's dynamic mode, the hand-eye loop's wrench watch) models
    # everything outboard of the sensor.
    why = ("wrench_sensor.compensate_gripper: false (a static compensation leaves the gripper's inertial "
           "wrench in the reading; the dynamic mode identifies everything outboard)")
    dynamic = s.kinesthetic.enabled and s.kinesthetic.mode == "dynamic"
    _check(not (dynamic and s.wrench_sensor.compensate_gripper), f"kinesthetic.mode: dynamic needs {why}")
    watch = s.hand_eye.enabled and s.hand_eye.slip_from_wrench
    _check(not (watch and s.wrench_sensor.compensate_gripper), f"hand_eye.slip_from_wrench needs {why}")
    _check_math_layer(s)


def _check_lights(lights) -> None:
    """Each light's strings (Drake's), a direction for a light that shines along one, a spot's cone
    and a point or spot light's fall-off (its numbers' ranges are checked with the others)."""
    for i, light in enumerate(lights):
        where = f"lights[{i}]"
        for key, accepted in LIGHT_STRINGS.items():
            value = getattr(light, key)
            _check(value in accepted, f"{where}.{key} must be one of "
                   f"{', '.join(repr(a) for a in accepted)}, got {shown(value)}")
        if light.type != "point":
            _check(bool(np.linalg.norm(light.direction) > 1e-9),
                   f"{where}.direction must not be zero (a {light.type} light shines along it)")
        if light.type == "spot":
            _check(light.cone_angle > 0, f"{where}.cone_angle must be above 0 deg for a spot light, "
                   f"got {shown(light.cone_angle)}")
        if light.type != "directional":
            _check(bool(np.any(light.attenuation_values > 0)), f"{where}.attenuation_values: at "
                   "least one of [constant, linear, quadratic] must be above 0")


def _check_random(s: Scenario) -> None:
    """The random disturbances' ranges as pairs, their limits against their sizes, the timeline they
    join (the drawn slips and head moves within ToolSlip's and HeadMove's ranges)."""
    r, name = s.random_disturbances, "random_disturbances"
    for key in ("interval", "slide", "pivot", "turn"):
        pair = getattr(r, key)
        _check(len(pair) == 2 and pair[0] <= pair[1],
               f"{name}.{key} needs [min, max] with min <= max, got {shown(pair)}")
    for size, limit in (("slide", "slide_limit"), ("pivot", "pivot_limit"), ("turn", "turn_limit")):
        _check(getattr(r, size)[1] <= getattr(r, limit), f"{name}.{limit} must be at least {size}'s max "
               f"({shown(getattr(r, size)[1])}), got {shown(getattr(r, limit))}")
    if not r.enabled:
        return
    _check(r.slip_probability == 0.0 or s.tool.model != "none",
           f"{name}: there is no tool to slip (tool.model: none): set slip_probability: 0")
    _check(not any(isinstance(e, ToolSlip | HeadMove) for e in s.disturbances),
           f"{name}: the draw starts from the configured grasp and head, so disturbances must not also "
           "list !ToolSlip or !HeadMove (a !Touch is fine)")
    for i, e in enumerate(d for d in timeline(s) if isinstance(d, ToolSlip | HeadMove)):
        _check_numbers(e, f"{name} (drawn {i}, !{type(e).__name__} at {e.time:g} s)")


def _check_timeline(s: Scenario) -> None:
    _check_random(s)
    for i, e in enumerate(s.disturbances):
        name = f"disturbances[{i}] (!{type(e).__name__})"
        if isinstance(e, Touch):
            _check(len(e.p_TQ) == 3 and len(e.f_T) == 3, f"{name}: p_TQ and f_T need 3 numbers")
            _check(s.tool.model != "none", f"{name}: there is no tool to touch (tool.model: none)")
        elif isinstance(e, ToolSlip):
            _check(s.tool.model != "none", f"{name}: there is no tool to slip (tool.model: none)")
    tm = s.touch_motion
    if tm.enabled:
        _check(s.tool.model != "none", "touch_motion: there is no tool to touch with (tool.model: none)")
        _check(len(tm.targets) > 0, "touch_motion.targets: at least one target is needed")
        for i, g in enumerate(tm.targets):
            _check(len(g.p_TQ) == 3 and len(g.down_T) == 3 and len(g.p_WQ) == 2,
                   f"touch_motion.targets[{i}]: p_TQ and down_T need 3 numbers, p_WQ 2")
            _check(any(g.down_T), f"touch_motion.targets[{i}].down_T must not be zero")
        _check(tm.retreat_height >= tm.approach_height,
               "touch_motion.retreat_height must be >= approach_height")
        _check(tm.press_extra <= tm.approach_height + tm.press_depth,
               "touch_motion.press_extra must be within the descent (approach_height + press_depth)")


def _check_experiments(s: Scenario) -> None:
    """What each enabled experiment needs of the world: its images, the motion's confirm input."""
    cam, he, bd = s.camera, s.hand_eye, s.body_detection
    if he.enabled:
        _check(cam.rgb and cam.depth, "hand_eye needs the camera's color and depth images: set "
               "camera.rgb and camera.depth to true")
    if bd.enabled:
        _check(cam.rgb, "body_detection needs the camera's color image: set camera.rgb to true")
        _check(cam.label, "body_detection is scored against the label image: set camera.label to true")
        _check(not (he.enabled and bd.confirm), "body_detection.confirm: with hand_eye on too, only "
               "hand_eye drives the motion's confirming requests; set body_detection.confirm: false")


def _check_math_layer(s: Scenario) -> None:
    """The math layer's settings check their combinations on construction (e.g. move_px > still_px);
    a loaded file set their fields one by one, so construct them (whether or not the experiment is on)."""
    he, k, bd = s.hand_eye, s.kinesthetic, s.body_detection
    _check(bd.response_window is None or bd.response_window <= bd.tau_a,
           f"body_detection.response_window must be at most tau_a ({shown(bd.tau_a)} s) or null, got "
           f"{shown(bd.response_window)}")
    if he.identifying_motion_interval > 0:
        _check(he.identifying_motion_max_hold >= he.identifying_motion_interval,
               "hand_eye.identifying_motion_max_hold must be >= identifying_motion_interval, got "
               f"{shown(he.identifying_motion_max_hold)} < {shown(he.identifying_motion_interval)}")
    checks = (("body_detection", bd.coincidence_params), ("body_detection", bd.feature_params),
              ("body_detection", bd.tracker_params),
              ("hand_eye", lambda: hand_eye_parts(he).coordination.rule()),
              ("kinesthetic.coordination", lambda: k.coordination.criteria(has_rotation=False)),
              ("kinesthetic.coordination", k.coordination.rule),
              ("kinesthetic.dynamic", lambda: savitzky_golay_weights(
                  k.dynamic.encoder_window, k.dynamic.encoder_order, k.period, -k.dynamic.wrench_delay)))
    for name, make in checks:
        try:
            make()
        except (ValueError, TypeError) as e:
            raise ScenarioError(f"{name}: {one_line(e)}") from None
