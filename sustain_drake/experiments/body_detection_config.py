"""The ``body_detection`` scenario section (paper §4.2). No pydrake systems imported here."""

# No "from __future__ import annotations": yaml_load_typed needs the real field types.
import dataclasses
from dataclasses import field

from sustain_drake.perception.body_features import FeatureParams
from sustain_drake.perception.coincidence import CoincidenceParams
from sustain_drake.perception.optical_flow import TrackerParams

_RULE = CoincidenceParams()
_TRACKER = TrackerParams()


@dataclasses.dataclass
class BodyDetectionConfig:
    """Body detection by motion coincidence: the tracker, the detector and their evaluation.

    The detector's settings are those of ``CoincidenceParams`` (see
    ``sustain_drake.perception.coincidence`` for the rule; the defaults are its defaults,
    except where a comment says otherwise); times in s, angles in rad, pixels in px.
    """

    enabled: bool = False
    # The grid of cells j over the image (rows x cols).
    grid_rows: int = 12
    grid_cols: int = 16
    # Tracker (Shi-Tomasi + pyramidal Lucas-Kanade).
    max_corners: int = _TRACKER.max_corners
    min_distance_px: float = _TRACKER.min_distance_px
    predict_flow: bool = _TRACKER.predict_flow  # Lucas-Kanade started at the previous flow
    quality_level: float = _TRACKER.quality_level
    # Eq. (27): onset windows and what counts as motion.
    tau_a: float = _RULE.tau_a
    tau_s: float = _RULE.tau_s
    adot_threshold: float = _RULE.adot_threshold
    sdot_threshold: float = _RULE.sdot_threshold
    # The body rule: false-body rate, response probability, counter-evidence.
    alpha: float = _RULE.alpha
    p_response: float = _RULE.p_response
    body_onset_rate: float = _RULE.body_onset_rate
    memory: float = _RULE.memory
    response_window: float | None = _RULE.response_window  # None: tau_s
    # Confirming motions (the hold at q* is the station's motion.confirm_hold).
    confirm: bool = True  # wire the detector's confirm request to the station's motion_confirm
    posture_tolerance: float = _RULE.posture_tolerance
    confirm_timeout: float = _RULE.confirm_timeout
    request_interval: float = _RULE.request_interval
    single_joint_confirm: bool = _RULE.single_joint_confirm
    max_sequence_trials: int = _RULE.max_sequence_trials
    stop_requests: bool = _RULE.stop_requests
    skip_busy_cells: bool = _RULE.skip_busy_cells
    # Body features: confirming-trial hits that make a tracked feature body, and the per-frame
    # flow (px) at or above which a feature moves (its onset "rises up from" below it).
    feature_hits: int = FeatureParams().hits
    feature_flow_threshold_px: float = FeatureParams().flow_threshold_px
    # Cells holding a confirmed body feature raise no confirming request.
    skip_feature_cells: bool = FeatureParams().skip_known_cells
    # Evaluation (label image, for evaluation only): a cell is true body where the robot's
    # moving bodies cover at least body_cover of it. The scored mask is the detector's body
    # cells, with the cells holding a confirmed body feature when score_features.
    body_cover: float = 0.10
    score_features: bool = True
    # Likelihood maps (PNG) are saved at these times (s) and at the end.
    snapshot_times: list[float] = field(default_factory=lambda: [10.0, 30.0])

    def coincidence_params(self) -> CoincidenceParams:
        """The detector's parameters (raises ``ValueError`` with one line on bad values)."""
        return CoincidenceParams(
            tau_a=self.tau_a, tau_s=self.tau_s, adot_threshold=self.adot_threshold,
            sdot_threshold=self.sdot_threshold, alpha=self.alpha, p_response=self.p_response,
            body_onset_rate=self.body_onset_rate, memory=self.memory,
            response_window=self.response_window, posture_tolerance=self.posture_tolerance,
            confirm_timeout=self.confirm_timeout, request_interval=self.request_interval,
            single_joint_confirm=self.single_joint_confirm,
            max_sequence_trials=self.max_sequence_trials, stop_requests=self.stop_requests,
            skip_busy_cells=self.skip_busy_cells)

    def feature_params(self) -> FeatureParams:
        return FeatureParams(hits=self.feature_hits, skip_known_cells=self.skip_feature_cells,
                             flow_threshold_px=self.feature_flow_threshold_px)

    def tracker_params(self) -> TrackerParams:
        return TrackerParams(max_corners=self.max_corners, min_distance_px=self.min_distance_px,
                             quality_level=self.quality_level, predict_flow=self.predict_flow)
