"""Batch API for recorded data: the sustainable identifiers run over arrays of samples.

The samples stream through the same constant-memory identifiers that the Drake systems use; the
arrays are only kept here to report per-sample residuals. ``calibrate_eye_to_hand`` fits one point
fixed on the hand (§3.4), ``calibrate_eye_to_hand_points`` several at once (one camera, one ``p_HP``
per point), ``identify_payload`` the payload (§4.4).

Every public function raises ``IdentificationError`` (a ``ValueError``, see ``errors``) with a
one-line message for an argument of the wrong type, shape or value.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from sustain_drake.identification import eye_to_hand, eye_to_hand_points, observability, payload
from sustain_drake.identification.errors import (
    ROTATION_TOLERANCE,
    VECTOR3,
    describe,
    instance,
    real_array,
    to_float_array,
)
from sustain_drake.identification.observability import (
    AGREEMENT_FACTOR,
    AGREEMENT_FLOOR,
    FIT_DISAGREES,
    HAND_NOT_IN_METRES,
    LEFT_HANDED,
    LINE_FLOOR,
    NOISE_MARGIN,
    POINTS_NOT_IN_METRES,
    POINTS_ON_A_LINE,
    SCALE_MISMATCH,
    UNDETERMINED,
    WEAKLY_DETERMINED,
    _mm,
    _rotation_problem,
    _units_problem,
)
from sustain_drake.identification.rotation import rotation_angle
from sustain_drake.identification.sustainable_identifier import (
    ConvergenceCriteria,
    IdentificationError,
    Verdict,
)


def _check_finite(name: str, a: np.ndarray) -> None:
    bad = ~np.isfinite(a)
    if bad.any():
        index = np.argwhere(bad)[0]
        raise IdentificationError(f"{name} is not finite (NaN or inf) at index {tuple(index.tolist())}")


def check_rotations(name: str, R: np.ndarray) -> None:
    """Raises IdentificationError if any ``R[i]`` is not a proper rotation to ROTATION_TOLERANCE
    (each entry of ``R^T R - I``), or if ``R`` is not a finite (n, 3, 3) array."""
    if type(name) is not str:
        raise IdentificationError(f"name must be a string, got {type(name).__name__}")
    name = " ".join(name.split()) or "R"  # the caller's text: its message stays one line
    R = real_array(name, R, (None, 3, 3))
    err = np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(R)
    bad = np.flatnonzero((err > ROTATION_TOLERANCE) | (det < 0.0))
    if bad.size:
        i = int(bad[0])
        raise IdentificationError(
            f"{name}[{i}] is not a rotation (|R^T R - I| = {err[i]:.2g}, det = {det[i]:.3g})"
        )


def _as_array(name: str, a, shape_tail: tuple[int, ...]) -> np.ndarray:
    try:
        a = to_float_array(name, a, "an array")
    except IdentificationError:
        raise IdentificationError(f"{name} is not a numeric array of real numbers: {describe(a)}") from None
    if a.ndim != 1 + len(shape_tail) or a.shape[1:] != shape_tail:
        want = "(n, " + ", ".join(str(s) for s in shape_tail) + ")"
        raise IdentificationError(f"{name} must have shape {want}, got {a.shape}")
    _check_finite(name, a)
    return a


@dataclass(frozen=True)
class EyeToHandResult:
    """The result of ``calibrate_eye_to_hand``.

    Attributes:
        X_WC: 4 x 4 pose of the camera in the world (the refined estimate).
        p_HP: the point in the hand frame, metres (refined).
        residuals: per-sample distance ``|R_WC p_CP + p_WC - R_WH p_HP - p_WH|``, metres, under the
            refined estimate, in the order of the input.
        rms: root mean square of ``residuals``, metres.
        eigenvalues: ``lambda_1 >= ... >= lambda_16`` of the conditioned statistic.
        gap_ratio: ``lambda_15 / lambda_16``.
        ssd: closeness of the TLS rotation block to a rotation (§3.2).
        expected_rms: ``sqrt(a^2 lambda_16)``, the identification's own error prediction, metres.
        verdict: converged or not, with the reason.
        projected: the TLS estimate projected onto SO(3) (``eye_to_hand.EyeToHandEstimate``).
        refined: its Gauss-Newton refinement (what ``X_WC`` and ``p_HP`` report).
        covariance: Gauss-Newton's covariance (9 x 9) of the refined estimate in ``(omega, p_WC,
            p_HP)``, ``omega`` the camera's turn in its own frame (rad; the truth is
            ``R_WC exp([omega x])``), positions in m (``observability.eye_to_hand_covariance``);
            None without a refined estimate or when it is undetermined.
    """

    X_WC: np.ndarray
    p_HP: np.ndarray
    residuals: np.ndarray
    rms: float
    eigenvalues: np.ndarray
    gap_ratio: float
    ssd: float
    expected_rms: float
    verdict: Verdict
    projected: eye_to_hand.EyeToHandEstimate | None
    refined: eye_to_hand.EyeToHandEstimate | None
    covariance: np.ndarray | None = None

    @property
    def converged(self) -> bool:
        return self.verdict.converged

    @property
    def standard_errors(self) -> tuple[float, float, float] | None:
        """1 sd (the RMS of the 3-D error) of the camera rotation (rad), the camera position and
        ``p_HP`` (m), from ``covariance``; None without it."""
        if self.covariance is None:
            return None
        d = np.diagonal(self.covariance)
        return tuple(math.sqrt(float(d[k:k + 3].sum())) for k in (0, 3, 6))


def eye_to_hand_residuals(X_WC: np.ndarray, p_HP: np.ndarray, p_C: np.ndarray, X_WH: np.ndarray):
    """Per-sample distances ``|R_WC p_CP + p_WC - (R_WH p_HP + p_WH)|`` in metres.
    IdentificationError unless ``X_WC`` is a real 4 x 4 matrix, ``p_HP`` a real 3-vector, ``p_C``
    (n, 3) and ``X_WH`` (n, 4, 4) real arrays (NaN or inf give non-finite distances)."""
    X_WC = real_array("X_WC", X_WC, (4, 4), finite=False)
    p_HP = real_array("p_HP", p_HP, VECTOR3, finite=False)
    p_C = real_array("p_C", p_C, (None, 3), finite=False)
    X_WH = real_array("X_WH", X_WH, (None, 4, 4), finite=False)
    if len(p_C) != len(X_WH):
        raise IdentificationError(
            f"p_C has {len(p_C)} samples but X_WH has {len(X_WH)}: they must pair one to one"
        )
    p_W_cam = p_C @ X_WC[:3, :3].T + X_WC[:3, 3]
    p_W_hand = np.einsum("nij,j->ni", X_WH[:, :3, :3], p_HP) + X_WH[:, :3, 3]
    return np.linalg.norm(p_W_cam - p_W_hand, axis=1)


def calibrate_eye_to_hand(p_C, X_WH, criteria: ConvergenceCriteria | None = None) -> EyeToHandResult:
    """Eye-to-hand calibration from recorded data (paper §3.4, with conditioning and refinement).

    Args:
        p_C: (n, 3) positions of one point fixed on the hand (or held tool), measured in the
            camera frame C, metres.
        X_WH: (n, 4, 4) poses of the hand frame H in the world W (forward kinematics), metres.
        criteria: convergence criteria (``eye_to_hand.default_criteria()`` if None).

    Returns:
        An ``EyeToHandResult``. Degenerate data (too few samples, pure translation, ...) is not an
        error: the verdict says "not converged" and why.

    Raises:
        IdentificationError (a ValueError): wrong types or shapes, mismatched lengths, NaN/inf, a
            pose whose rotation block is not a rotation, or ``criteria`` not a ConvergenceCriteria.
    """
    instance("criteria", criteria, ConvergenceCriteria, "a ConvergenceCriteria or None", optional=True)
    p_C = _as_array("p_C", p_C, (3,))
    X_WH = _poses(X_WH)
    if len(p_C) != len(X_WH):
        raise IdentificationError(
            f"p_C has {len(p_C)} samples but X_WH has {len(X_WH)}: they must pair one to one"
        )
    return _calibrate_one(p_C, X_WH, criteria)[0]


def _poses(X_WH) -> np.ndarray:
    """``X_WH`` checked: an (n, 4, 4) array of finite homogeneous transforms with rotation blocks."""
    X_WH = _as_array("X_WH", X_WH, (4, 4))
    if not np.allclose(X_WH[:, 3, :], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        i = int(np.flatnonzero(np.abs(X_WH[:, 3, :] - [0, 0, 0, 1]).max(axis=1) > 1e-9)[0])
        raise IdentificationError(f"X_WH[{i}] is not a homogeneous transform: last row is not 0 0 0 1")
    check_rotations("X_WH", X_WH[:, :3, :3])
    return X_WH


def _calibrate_one(p_C: np.ndarray, X_WH: np.ndarray, criteria: ConvergenceCriteria | None):
    """``calibrate_eye_to_hand`` of checked arrays, and the raw 16 x 16 statistic ``S`` behind it."""
    identifier = eye_to_hand.EyeToHandIdentifier(criteria=criteria)
    for c, X in zip(p_C, X_WH, strict=True):
        identifier.add(c, X[:3, :3], X[:3, 3])
    solution = identifier.solve(refine_estimate=True)
    estimate = solution.estimate
    if estimate is None:
        X_WC = np.eye(4)
        p_HP = np.zeros(3)
        residuals = np.full(len(p_C), math.inf)
    else:
        X_WC = estimate.X_WC
        p_HP = estimate.p_HP
        residuals = eye_to_hand_residuals(X_WC, p_HP, p_C, X_WH)
    rms = float(np.sqrt(np.mean(residuals**2))) if len(residuals) else math.inf
    covariance = (None if solution.refined is None
                  else observability.eye_to_hand_covariance(identifier.core.S, solution.refined.R_WC))
    if covariance is not None and not np.all(np.diagonal(covariance) >= 0.0):
        covariance = None  # a negative variance (round-off of a singular fit): undetermined
    result = EyeToHandResult(X_WC=X_WC, p_HP=p_HP, residuals=residuals, rms=rms, ssd=solution.ssd,
                             projected=solution.projected, refined=solution.refined, covariance=covariance,
                             **_statistics(solution))  # fmt: skip
    return result, identifier.core.S.copy()


# ---- several points fixed on the hand (beyond the paper) ------------------------------------------
OUTLIER_FACTOR = 3.0  # a residual this many times its point's RMS is flagged (a mis-paired sample)
MIN_POINT_SAMPLES = 4  # per point: its own fit takes 9 unknowns from 3 samples; a fourth checks it
MAX_POINTS = 100  # the joint normal equations are (6 + 3K) square, solved a few dozen times
MAX_LABEL_CHARACTERS = 100  # a label is named in one-line messages


@dataclass(frozen=True)
class EyeToHandPointsResult:
    """The result of ``calibrate_eye_to_hand_points``: one camera, one ``p_HP`` per point.

    Attributes:
        X_WC: 4 x 4 pose of the camera in the world, the joint fit of every point.
        labels: the points' labels, in the order of the mapping given.
        p_HP: (K, 3) each point in the hand frame, metres (the joint fit).
        samples: each point's samples (0-based indices into ``X_WH``, ascending).
        residuals: each point's per-sample distances ``|R_WC p_CP + p_WC - R_WH p_HP - p_WH|`` under
            the joint fit, metres, in the order of its ``samples``.
        rms: (K,) each point's RMS residual, metres.
        weights: (K,) each point's weight in the joint fit, the inverse of its residual variance,
            scaled so that the weighted samples number as many as the samples (1 for one point).
        verdict: converged or not, with the reason.
        single: each point's own ``EyeToHandResult`` (the paper's TLS, projection and Gauss-Newton on
            that point's samples alone).
        seed: the index of the point whose own camera started the joint fit (None without one).
        num_samples: the poses in which at least one point was seen.
        covariance: Gauss-Newton's covariance ((6 + 3K) square) of the joint fit in ``(omega, p_WC,
            p_HP_1, ..., p_HP_K)`` (``eye_to_hand_points.joint_covariance``; ``omega`` the camera's turn in
            its own frame, rad); None without a joint fit or when it is undetermined.
    """

    X_WC: np.ndarray
    labels: tuple
    p_HP: np.ndarray
    samples: tuple
    residuals: tuple
    rms: np.ndarray
    weights: np.ndarray
    verdict: Verdict
    single: tuple
    seed: int | None
    num_samples: int
    covariance: np.ndarray | None = None

    @property
    def converged(self) -> bool:
        return self.verdict.converged

    @property
    def standard_errors(self) -> tuple[float, float, np.ndarray] | None:
        """1 sd (the RMS of the 3-D error) of the camera rotation (rad), the camera position (m) and
        each point's ``p_HP`` ((K,), m), from ``covariance``; None without it."""
        if self.covariance is None:
            return None
        d = np.diagonal(self.covariance)
        points = np.sqrt(d[6:].reshape(-1, 3).sum(axis=1))
        return math.sqrt(float(d[0:3].sum())), math.sqrt(float(d[3:6].sum())), points

    def outliers(self) -> tuple:
        """Each point's samples whose residual is over ``OUTLIER_FACTOR`` times that point's RMS (a
        position paired with another sample's pose, or mislabelled, stands out so)."""
        pairs = zip(self.samples, self.residuals, self.rms, strict=True)
        return tuple(s[r > OUTLIER_FACTOR * rms] for s, r, rms in pairs)

    def single_offsets(self) -> np.ndarray:
        """(K, 2): how far each point's own camera (``single``) is from the joint one, position (m)
        and rotation (rad); NaN for a point without its own camera."""
        offsets = np.full((len(self.labels), 2), math.nan)
        for k, r in enumerate(self.single):
            if r.refined is not None:
                offsets[k] = (np.linalg.norm(r.X_WC[:3, 3] - self.X_WC[:3, 3]),
                              rotation_angle(r.X_WC[:3, :3].T @ self.X_WC[:3, :3]))  # fmt: skip
        return offsets


def calibrate_eye_to_hand_points(points, X_WH, criteria: ConvergenceCriteria | None = None
                                 ) -> EyeToHandPointsResult:  # fmt: skip
    """Eye-to-hand calibration from several points fixed on the hand at once: one camera ``X_WC``
    and one ``p_HP`` per point (beyond the paper, which identifies from one point, §3.4).

    1. Each point alone: its own statistic of Eqs. (30)-(35), TLS, the §3.2 projection, Gauss-Newton
       and verdict (``calibrate_eye_to_hand`` on its samples; ``single``).
    2. The start: the point whose own camera is best determined (converged points first, then the
       smallest 1 sd displacement of its samples by its camera's uncertainty, ``sqrt(sd_p^2 +
       (sd_omega L)^2)`` with ``L`` its points' RMS distance from the camera). Not a combination of
       the points' cameras: Gauss-Newton converges to the joint optimum from any start near it, and
       the best-determined camera is, in expectation, the nearest; a combination would need each
       camera's covariance to weigh it, which the joint fit uses anyway.
    3. The joint fit: Gauss-Newton on SO(3) x R^3 x (R^3)^K of the sum of every point's Eq. (30)
       residuals, each point weighted by the inverse of its own residual variance
       (``eye_to_hand_points.refine_joint_weighted``: a corner measured to 0.5 mm is not pulled off by
       codes measured to 4 mm), and its covariance (``eye_to_hand_points.joint_covariance``).

    The verdict applies the single-point checks (``observability``) to the union of the points, in
    this order: at least ``criteria.min_samples`` poses; the units and the hand's rotations on the
    sum of the points' statistics; a point whose own verdict finds the camera frame left-handed or
    the units wrong refuses them all; each point's RMS residual per axis under the joint camera
    within ``AGREEMENT_FACTOR`` (3) times its own fit's (each over its degrees of freedom, ``3 m - 3``
    and ``3 m - 9``; plus ``AGREEMENT_FLOOR`` of criterion (a)): points that disagree about the
    camera (one in another camera's frame, labels mixed up) are not averaged, and the point that
    disagrees most is named; every point's RMS residual within criterion (a) (one not fixed on the
    hand); the camera points not on a line; the 1 sd of the camera position, of every ``p_HP`` and of
    the camera rotation (times the points' RMS distance from the camera) within criterion (a). No
    point needs to converge alone: points seen over few poses or hand rotations each can determine
    the camera together. One point gives exactly ``calibrate_eye_to_hand``'s result.

    Args:
        points: a mapping from each point's label (a string or an integer) to ``(samples, p_C)``:
            ``samples`` the (m,) 0-based indices into ``X_WH`` of the poses at which it was seen
            (distinct, ``m >= MIN_POINT_SAMPLES``), ``p_C`` (m, 3) its positions in the camera
            frame C, metres. At most ``MAX_POINTS`` points; a point may miss any sample.
        X_WH: (n, 4, 4) poses of the hand frame H in the world W, metres.
        criteria: convergence criteria (``eye_to_hand.default_criteria()`` if None).

    Returns:
        An ``EyeToHandPointsResult``; degenerate data is a "not converged" verdict with the reason.

    Raises:
        IdentificationError (a ValueError): ``points`` not such a mapping (a label that is not a
            non-empty printable string or an integer, a sample index out of range or repeated, too
            few samples for a point, arrays of the wrong shape, NaN/inf), ``X_WH`` as in
            ``calibrate_eye_to_hand``, or ``criteria`` not a ConvergenceCriteria.
    """
    instance("criteria", criteria, ConvergenceCriteria, "a ConvergenceCriteria or None", optional=True)
    X_WH = _poses(X_WH)
    tracks = _tracks(points, len(X_WH))
    labels = tuple(label for label, _, _ in tracks)
    samples = tuple(s for _, s, _ in tracks)
    fits = [_calibrate_one(p_C, X_WH[s], criteria) for _, s, p_C in tracks]
    single = tuple(result for result, _ in fits)
    num_samples = int(np.unique(np.concatenate(samples)).size)
    if len(tracks) == 1:  # the single-point path itself
        r = single[0]
        return EyeToHandPointsResult(r.X_WC, labels, r.p_HP[None], samples, (r.residuals,), np.array([r.rms]),
                                     np.ones(1), r.verdict, single, 0 if r.refined is not None else None,
                                     num_samples, r.covariance)  # fmt: skip
    S_list = [S for _, S in fits]
    seed = _seed(single, [p_C for _, _, p_C in tracks])
    fit = None
    if seed is not None:
        start = single[seed].refined
        fit = eye_to_hand_points.refine_joint_weighted(S_list, start.R_WC, start.p_WC)
    if fit is None:
        X_WC = single[seed].X_WC if seed is not None else np.eye(4)
        p_HP = eye_to_hand_points.points_given_camera(S_list, X_WC[:3, :3], X_WC[:3, 3])
        weights, covariance = np.ones(len(tracks)), None
    else:
        R_WC, p_WC, p_HP, weights = fit
        X_WC = eye_to_hand._pose(R_WC, p_WC)
        covariance = eye_to_hand_points.joint_covariance(S_list, R_WC, p_WC, p_HP, weights)
    residuals = tuple(eye_to_hand_residuals(X_WC, p, p_C, X_WH[s])
                      for p, (_, s, p_C) in zip(p_HP, tracks, strict=True))  # fmt: skip
    rms = np.array([math.sqrt(float(np.mean(r**2))) for r in residuals])
    result = EyeToHandPointsResult(X_WC, labels, p_HP, samples, residuals, rms, weights, Verdict(False, ""),
                                   single, seed, num_samples, covariance)  # fmt: skip
    verdict = _judge_points(result, S_list, fit is not None, criteria or eye_to_hand.default_criteria())
    return dataclasses.replace(result, verdict=verdict)


def _tracks(points, n: int) -> list[tuple]:
    """``points`` checked against ``n`` poses: ``[(label, samples, p_C)]``, samples ascending."""
    if not isinstance(points, Mapping) or not 1 <= len(points) <= MAX_POINTS:
        size = f" of {len(points)}" if isinstance(points, Mapping) else ""
        raise IdentificationError(f"points must be a mapping of 1 to {MAX_POINTS} labels to (samples, p_C), "
                                  f"got {describe(points)}{size}")  # fmt: skip
    tracks = []
    for label, value in points.items():
        text = isinstance(label, str) and label and label.isprintable() and len(label) <= MAX_LABEL_CHARACTERS
        if not (text or (isinstance(label, numbers.Integral) and not isinstance(label, (bool, np.bool_)))):
            raise IdentificationError("points: a label must be a non-empty printable string (at most "
                                      f"{MAX_LABEL_CHARACTERS} characters) or an integer, got "
                                      f"{describe(label)}")  # fmt: skip
        name = f"points[{label!r}]"
        if not isinstance(value, (tuple, list)) or len(value) != 2:
            raise IdentificationError(f"{name} must be a pair (samples, p_C), got {describe(value)}")
        index = _as_array(f"{name} samples", value[0], ())
        p_C = _as_array(f"{name} p_C", value[1], (3,))
        if len(index) != len(p_C):
            raise IdentificationError(f"{name} has {len(index)} samples but {len(p_C)} points: they must "
                                      "pair one to one")  # fmt: skip
        if len(index) < MIN_POINT_SAMPLES:
            raise IdentificationError(f"{name} has {len(index)} samples: a point needs at least "
                                      f"{MIN_POINT_SAMPLES}")  # fmt: skip
        bad = np.flatnonzero((index != np.round(index)) | (index < 0) | (index >= n))
        if bad.size:
            raise IdentificationError(f"{name} samples[{bad[0]}] = {index[bad[0]]:g} is not an index of "
                                      f"X_WH (an integer from 0 to {n - 1})")  # fmt: skip
        index = index.astype(np.int64)
        order = np.argsort(index, kind="stable")
        repeated = np.flatnonzero(np.diff(index[order]) == 0)
        if repeated.size:
            raise IdentificationError(f"{name} has sample {index[order[repeated[0]]]} twice: one position "
                                      "per sample and point")  # fmt: skip
        tracks.append((label, index[order], p_C[order]))
    return tracks


def _seed(single: tuple, p_C: list[np.ndarray]) -> int | None:
    """The point whose own camera is best determined (``calibrate_eye_to_hand_points``, step 2)."""
    best, best_key = None, None
    for k, r in enumerate(single):
        if r.refined is None:
            continue
        errors = r.standard_errors
        lever = math.sqrt(float(np.mean(np.sum(p_C[k] ** 2, axis=1))))
        spread = math.inf if errors is None else math.hypot(errors[1], errors[0] * lever)
        key = (not r.converged, spread)
        if best_key is None or key < best_key:
            best, best_key = k, key
    return best


# Reasons a point's own verdict gives that hold for every point of the one camera and hand.
_INPUT_REASONS = (POINTS_NOT_IN_METRES, HAND_NOT_IN_METRES, LEFT_HANDED, SCALE_MISMATCH)


def _judge_points(result: EyeToHandPointsResult, S_list: list[np.ndarray], fitted: bool,
                  criteria: ConvergenceCriteria) -> Verdict:  # fmt: skip
    """The verdict of ``calibrate_eye_to_hand_points`` (its docstring lists the checks, in order)."""
    if result.num_samples < criteria.min_samples:
        return Verdict(False, f"too few samples: {result.num_samples} < {criteria.min_samples}")
    S = np.sum(S_list, axis=0)  # the units and the hand's rotations read sums over every sample
    reason = _units_problem(S, float(S[9, 9])) or _rotation_problem(S, float(S[9, 9]))
    if reason is not None:
        return Verdict(False, reason)
    for label, r in zip(result.labels, result.single, strict=True):
        if r.verdict.reason.startswith(_INPUT_REASONS):
            return Verdict(False, f"{r.verdict.reason} (point {label!r} alone)")
    if not fitted and result.seed is None:
        k = int(np.argmax([len(r.residuals) for r in result.single]))
        return Verdict(False, f"no point gives a camera alone (point {result.labels[k]!r}: "
                              f"{result.single[k].verdict.reason})")  # fmt: skip
    if not fitted:
        return Verdict(False, f"{UNDETERMINED} (the joint fit's normal equations are singular): rotate "
                              "the hand about two different axes")  # fmt: skip
    problem = _points_problem(result, S, criteria)
    return Verdict(True, "converged") if problem is None else problem


def _points_problem(result: EyeToHandPointsResult, S: np.ndarray, criteria: ConvergenceCriteria):
    """The joint fit's residuals and uncertainty judged (``_judge_points``), a Verdict if wrong."""
    bound, mm = criteria.max_expected_rms, _mm
    worst, excess = None, 1.0  # the point whose residuals grow most over its own fit's, beyond the limit
    for k, r in enumerate(result.single):
        if r.refined is not None:
            m = len(r.residuals)
            joint = math.sqrt(float(np.sum(result.residuals[k] ** 2)) / (3.0 * m - 3.0))
            own = math.sqrt(float(np.sum(r.residuals**2)) / (3.0 * m - 9.0))
            ratio = joint / (AGREEMENT_FACTOR * own + AGREEMENT_FLOOR * bound)
            if ratio > excess:
                worst, excess = (k, joint, own), ratio
    if worst is not None:
        k, joint, own = worst
        seed = result.labels[result.seed]
        return Verdict(False, f"{FIT_DISAGREES} (point {result.labels[k]!r}: {mm(joint)} RMS per axis under "
                              f"the joint camera, {mm(own)} under its own; the joint fit started from point "
                              f"{seed!r}): the points disagree about the camera: is every point fixed on the "
                              "hand, seen by this camera and labelled alike in every sample?")  # fmt: skip
    for k, label in enumerate(result.labels):
        if not result.rms[k] <= bound:
            return Verdict(False, f"{FIT_DISAGREES} (point {label!r}: residuals {mm(result.rms[k])} RMS, "
                                  f"over the {mm(bound)} allowed): is it fixed on the hand, and is each of "
                                  "its positions paired with its own pose?")  # fmt: skip
    n = float(S[9, 9])
    dof = max(3.0 * n - 6.0 - 3.0 * len(result.labels), 1.0)
    sigma2 = sum(float(np.sum(r**2)) for r in result.residuals) / dof  # pooled, per axis
    mean = S[0:9:3, 9] / n
    scatter = S[0:9:3, 0:9:3] / n - np.outer(mean, mean)  # the camera points' covariance
    off = eye_to_hand_points.spread_off_line(scatter)
    along = math.sqrt(max(float(np.linalg.eigvalsh(scatter)[2]), 0.0))
    if not (off >= NOISE_MARGIN * math.sqrt(2.0 * sigma2) and off >= LINE_FLOOR * along):
        return Verdict(False, f"{POINTS_ON_A_LINE} ({mm(off)} RMS off it, {mm(along)} along it): move "
                              "the hand so that the points sweep an area of the view")  # fmt: skip
    errors = result.standard_errors
    if errors is None:
        return Verdict(False, f"{UNDETERMINED} (the joint fit's covariance): rotate the hand about two "
                              "different axes")  # fmt: skip
    rotation, position, point_errors = errors
    lever = math.sqrt(max(float(S[0, 0] + S[3, 3] + S[6, 6]) / n, 0.0))
    k = int(np.argmax(point_errors))
    if not max(rotation * lever, position, float(point_errors[k])) <= bound:
        return Verdict(False, f"{WEAKLY_DETERMINED} (1 sd: camera position {mm(position)}, point "
                              f"{result.labels[k]!r} {mm(point_errors[k])}, camera rotation "
                              f"{math.degrees(rotation):.2g} deg ({mm(rotation * lever)} at the points), "
                              f"over the {mm(bound)} allowed): rotate the hand more widely about two axes, "
                              "take more samples")  # fmt: skip
    return None


@dataclass(frozen=True)
class PayloadResult:
    """The result of ``identify_payload``.

    Attributes:
        mass: kg.
        p_KCm: centre of mass in the sensor frame K, metres.
        force_residuals: per-sample ``|R_WK f_K + m g_W|``, N.
        torque_residuals: per-sample ``|tau_K - p_KCm x f_K|``, N m.
        eigenvalues: ``lambda_1 >= ... >= lambda_5`` of the conditioned statistic.
        gap_ratio: ``lambda_4 / lambda_5``.
        expected_rms: ``sqrt(a^2 lambda_5)`` (m/s^2 and N m rows together).
        verdict: converged or not, with the reason.
        covariance: the covariance (4 x 4) of ``(mass, p_KCm)`` in kg and m
            (``observability.payload_covariance``); None without a positive mass.
    """

    mass: float
    p_KCm: np.ndarray
    force_residuals: np.ndarray
    torque_residuals: np.ndarray
    eigenvalues: np.ndarray
    gap_ratio: float
    expected_rms: float
    verdict: Verdict
    covariance: np.ndarray | None = None

    @property
    def converged(self) -> bool:
        return self.verdict.converged


def identify_payload(
    wrench_K, R_WK, gravity_W=payload.STANDARD_GRAVITY_W, criteria: ConvergenceCriteria | None = None
) -> PayloadResult:
    """Mass and centre of mass of the outboard payload from quasi-static F/T samples (§4.4).

    Args:
        wrench_K: (n, 6) wrenches ``[tau_x, tau_y, tau_z, f_x, f_y, f_z]`` in N m and N, applied by
            the sensor on the payload, in the sensor frame K (see ``payload`` for the convention).
        R_WK: (n, 3, 3) orientations of the sensor frame in the world.
        gravity_W: gravity in the world, m/s^2.
        criteria: convergence criteria (``payload.default_criteria()`` if None).

    Raises:
        IdentificationError (a ValueError): wrong types or shapes, mismatched lengths, NaN/inf, an
            orientation that is not a rotation, ``gravity_W`` not a finite non-zero 3-vector or
            ``criteria`` not a ConvergenceCriteria.
    """
    instance("criteria", criteria, ConvergenceCriteria, "a ConvergenceCriteria or None", optional=True)
    wrench_K = _as_array("wrench_K", wrench_K, (6,))
    R_WK = _as_array("R_WK", R_WK, (3, 3))
    if len(wrench_K) != len(R_WK):
        raise IdentificationError(
            f"wrench_K has {len(wrench_K)} samples but R_WK has {len(R_WK)}: they must pair one to one"
        )
    check_rotations("R_WK", R_WK)
    identifier = payload.PayloadIdentifier(gravity_W=gravity_W, criteria=criteria)
    for w, R in zip(wrench_K, R_WK, strict=True):
        identifier.add(w, R)
    solution = identifier.solve()
    tau, f = wrench_K[:, 0:3], wrench_K[:, 3:6]
    f_W = np.einsum("nij,nj->ni", R_WK, f)
    force_res = np.linalg.norm(f_W + solution.mass * identifier.g_W, axis=1)
    torque_res = np.linalg.norm(tau - np.cross(solution.p_KCm, f), axis=1)
    covariance = observability.payload_covariance(identifier.core.S, identifier.core.weight, solution.x,
                                                  identifier.g_W)  # fmt: skip
    return PayloadResult(mass=solution.mass, p_KCm=solution.p_KCm, force_residuals=force_res,
                         torque_residuals=torque_res, covariance=covariance, **_statistics(solution))


def _statistics(solution) -> dict:
    """What every batch result reports of its identification: the eigenvalues of C, the gap
    ``lambda_{N-1} / lambda_N`` (1 without an eigen-decomposition), the expected RMS error and the
    verdict."""
    gap = solution.eigen.gap_ratio if solution.eigen is not None else 1.0
    return {"eigenvalues": solution.eigenvalues, "gap_ratio": gap, "expected_rms": solution.expected_rms,
            "verdict": solution.verdict}
