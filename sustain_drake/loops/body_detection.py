"""Body detection by motion coincidence (paper §3.3, §4.2): its settings as a scenario section, and
the tracker -> detector wiring that the body-detection experiment and the hand-eye loop share."""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import dataclasses
from dataclasses import dataclass, field

from sustain_drake.loops.pixel_scale import pixel_scale, scaled
from sustain_drake.perception.body_features import FeatureParams
from sustain_drake.perception.coincidence import CoincidenceParams
from sustain_drake.perception.optical_flow import TrackerParams
from sustain_drake.systems.motion_coincidence_detector import MotionCoincidenceDetector
from sustain_drake.systems.optical_flow_tracker import OpticalFlowTracker

_RULE = CoincidenceParams()
_TRACKER = TrackerParams()


@dataclasses.dataclass
class BodyDetectionConfig:
    """Body detection by motion coincidence: the tracker, the detector and their evaluation.

    The detector's settings are those of ``CoincidenceParams`` (see
    ``sustain_drake.perception.coincidence`` for the rule; the defaults are its defaults,
    except where a comment says otherwise); times in s, angles in rad, pixels in px of the measured
    camera (640 x 480, 45 deg vertical field of view), scaled to the camera in use by its focal
    length (``loops.pixel_scale``).
    """

    enabled: bool = False  # run the body-detection experiment on the scenario's world
    # count: rows of the grid of cells j over the image (40 px cells on a 640 x 480 image)
    grid_rows: int = 12
    grid_cols: int = 16  # count: columns of the grid of cells j over the image
    max_corners: int = _TRACKER.max_corners  # count: Shi-Tomasi features tracked at most
    min_distance_px: float = _TRACKER.min_distance_px  # px: least spacing of Shi-Tomasi features
    # start Lucas-Kanade at the previous frame's flow, so a periodic texture cannot make it jump a period
    predict_flow: bool = True
    # fraction of the best corner's quality a Shi-Tomasi corner needs
    quality_level: float = _TRACKER.quality_level
    tau_a: float = _RULE.tau_a  # s: window of the actuator onset detector rho_a (Eq. (27))
    tau_s: float = _RULE.tau_s  # s: window of the visual onset detector rho_s (Eq. (27))
    adot_threshold: float = _RULE.adot_threshold  # rad/s: a joint speed above this is actuator motion
    sdot_threshold: float = _RULE.sdot_threshold  # px/s: a cell's visual speed above this is visual motion
    alpha: float = _RULE.alpha  # false-body rate: a cell is body when L_j >= ln(1/alpha)
    p_response: float = _RULE.p_response  # probability that a body cell responds to its actuator's onset
    body_onset_rate: float = _RULE.body_onset_rate  # 1/s: spontaneous onsets of a still body cell (noise)
    memory: float = _RULE.memory  # s: time constant that forgets unexplained onsets and still time
    # s: a hit's visual onset follows the actuator's within this; None: tau_s
    response_window: float | None = _RULE.response_window
    # wire the detector's confirm request to the station's motion_confirm (hold: motion.confirm_hold)
    confirm: bool = True
    # rad (max-norm): a confirming trial starts within this of q*
    posture_tolerance: float = _RULE.posture_tolerance
    confirm_timeout: float = _RULE.confirm_timeout  # s after which an unanswered confirming request expires
    # s after a request ends before a new coincidence raises one (the babbling explores)
    request_interval: float = _RULE.request_interval
    # confirm by moving only the most proximal candidate actuator, not all joints
    single_joint_confirm: bool = _RULE.single_joint_confirm
    # count: trials of one follow-up sequence at a posture before babbling on; 0: no limit
    max_sequence_trials: int = _RULE.max_sequence_trials
    # also request a confirmation where the arm stops, for the cells that moved last
    stop_requests: bool = _RULE.stop_requests
    # a cell moving when its trial starts is not tested: no hit, no miss
    skip_busy_cells: bool = _RULE.skip_busy_cells
    feature_hits: int = FeatureParams().hits  # count: confirming-trial hits that make a tracked feature body
    # px: per-frame flow at or above which a feature moves (its onset rises from below)
    feature_flow_threshold_px: float = FeatureParams().flow_threshold_px
    # cells holding a confirmed body feature raise no confirming request
    skip_feature_cells: bool = FeatureParams().skip_known_cells
    # fraction of a cell the robot's moving bodies must cover for it to be true body (evaluation)
    body_cover: float = 0.10
    # the scored mask also holds the cells with a confirmed body feature (evaluation)
    score_features: bool = True
    # s: times the likelihood maps are saved as PNG (and at the end)
    snapshot_times: list[float] = field(default_factory=lambda: [10.0, 30.0])

    def coincidence_params(self, scale: float = 1.0) -> CoincidenceParams:
        """The detector's parameters, pixel thresholds times ``scale`` (``loops.pixel_scale``; raises
        ``ValueError`` with one line on bad values)."""
        return scaled(CoincidenceParams(
            tau_a=self.tau_a, tau_s=self.tau_s, adot_threshold=self.adot_threshold,
            sdot_threshold=self.sdot_threshold, alpha=self.alpha, p_response=self.p_response,
            body_onset_rate=self.body_onset_rate, memory=self.memory,
            response_window=self.response_window, posture_tolerance=self.posture_tolerance,
            confirm_timeout=self.confirm_timeout, request_interval=self.request_interval,
            single_joint_confirm=self.single_joint_confirm,
            max_sequence_trials=self.max_sequence_trials, stop_requests=self.stop_requests,
            skip_busy_cells=self.skip_busy_cells), scale, lengths=("sdot_threshold",))

    def feature_params(self, scale: float = 1.0) -> FeatureParams:
        return scaled(FeatureParams(hits=self.feature_hits, skip_known_cells=self.skip_feature_cells,
                                    flow_threshold_px=self.feature_flow_threshold_px),
                      scale, lengths=("flow_threshold_px",))

    def tracker_params(self, scale: float = 1.0) -> TrackerParams:
        return scaled(TrackerParams(max_corners=self.max_corners, min_distance_px=self.min_distance_px,
                                    quality_level=self.quality_level, predict_flow=self.predict_flow),
                      scale, lengths=("min_distance_px", "fb_threshold_px", "min_flow_px"),
                      windows=("block_size", "lk_window_px"), odd_windows=("ncc_patch_px",))


@dataclass
class BodyDetection:
    """The tracker and the detector of ``add_body_detection``, connected to each other."""

    tracker: OpticalFlowTracker
    detector: MotionCoincidenceDetector


def add_body_detection(builder, info, num_joints: int, fps: float,
                       config: BodyDetectionConfig) -> BodyDetection:
    """Adds the optical-flow tracker (images of the camera with intrinsics ``info`` at ``fps``) and the
    Eq. (27) motion coincidence detector of ``num_joints`` actuators, the tracker's flow and features
    connected to the detector. The tracker runs a quarter frame after the camera samples and the
    detector half a frame after, so the detector sees this frame's flow with the encoders half a frame
    later: the visual response lags the actuator by the physics only, not by two frames of pipeline.
    Pixel settings are scaled to the camera (``loops.pixel_scale``).
    Left for the caller: the tracker's images and the detector's ``actuator_positions``. Raises
    ``ValueError`` (one line) on bad settings."""
    period, scale = 1.0 / fps, pixel_scale(info)
    tracker = builder.AddSystem(OpticalFlowTracker(
        info, (config.grid_rows, config.grid_cols), period=period, offset=0.25 * period,
        params=config.tracker_params(scale)))  # fmt: skip
    tracker.set_name("optical_flow_tracker")
    detector = builder.AddSystem(MotionCoincidenceDetector(
        num_joints, tracker.grid.num_cells, period=period, offset=0.5 * period,
        params=config.coincidence_params(scale), feature_params=config.feature_params(scale)))  # fmt: skip
    detector.set_name("motion_coincidence_detector")
    for name in ("visual_change", "tracked_features"):
        builder.Connect(tracker.GetOutputPort(name), detector.GetInputPort(name))
    return BodyDetection(tracker, detector)
