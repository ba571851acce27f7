"""Recovery after a camera move (beyond the paper): the points the abandoned model observed keep their
``p_HP`` (a moved camera leaves the held tool unchanged), so their samples since the move give the new
camera in closed form (``keep_tool_points``: 6 unknowns, not 15), and with the static scene's turn across
the move, the camera is the old one turned, placed by the tool points. Where none of those points is
found again (a tool without corners: its anchored points are wherever their tracks began), the turned
camera is placed by the points tracked since the move, each with a ``p_HP`` of its own (3 + 3K
unknowns). A turn too uncertain for the camera's rotation only finds the points: the known ones then
give the camera alone (6 unknowns), the others jointly with it (6 + 3K)."""

import math
from dataclasses import replace

import numpy as np

from sustain_drake.identification.camera_turn import MAX_TURN_ROTATION_SD, TurnAnchors, camera_after_turn
from sustain_drake.identification.candidates.bank import Adoption, CandidateBank, with_camera
from sustain_drake.identification.candidates.fitting import (
    FIRST_CHOICE_POINTS,
    REGION_95,
    S_of,
    best_p_HP_given_camera,
    camera_sd,
    explained,
    independent_of,
    mean_squared_error_of,
    points_in_camera,
    rotation_spread,
    sd_within_targets,
)
from sustain_drake.identification.candidates.frame import Pool, SeenFrame
from sustain_drake.identification.candidates.params import CandidateParams
from sustain_drake.identification.eye_to_hand import pack_x
from sustain_drake.identification.eye_to_hand_points import (
    camera_given_points,
    joint_covariance,
    points_given_camera,
    position_and_points_given_rotation,
    refine_joint,
    spread_off_line,
)


def with_scene_turn(bank: CandidateBank, scene_turn) -> CandidateBank:
    """The bank holding the static scene's turn (``FrameInput.scene_turn``) of the move that cleared
    the model, once it has come, with the camera turned as the scene shows: the turn of a move that
    started after the reset before the model was cleared (``moved_since``) and by the reset that
    cleared it. The known points are dropped if the reset they come from came before the move
    started (another change cleared that model: a slip moves the points)."""
    if (scene_turn is not None and bank.moved_from_x is not None and bank.turn is None and scene_turn.move > 0
            and bank.moved_since < scene_turn.start <= bank.moved_at):
        if not bank.known_at >= scene_turn.start:
            bank = replace(bank, known_points=(), known_corners=frozenset())
        # The turn of the move that cleared the model; the turned camera (at the old position) once,
        # to match new tracks to the known points on every frame until one leads; a turn less
        # certain than MAX_TURN_ROTATION_SD only finds them.
        x0 = bank.moved_from_x
        turned = camera_after_turn(x0[0:9].reshape(3, 3, order="F"), x0[9:12], scene_turn, [], [],
                                   max_rotation_sd=math.inf)
        bank = replace(bank, turn=scene_turn, turned_R_WC=None if turned is None else turned.R_WC,
                       turned_p_WC=turned.p_WC if turned is not None and turned.scene_shift else None,
                       turn_rotation_sd=math.inf if turned is None else turned.rotation_sd)
    return bank


def _turn_is_precise(bank: CandidateBank) -> bool:
    """Whether the turn's 1 sd is within ``MAX_TURN_ROTATION_SD``: the turned camera's rotation is then
    the adopted camera's; otherwise the turned camera only finds the known points again."""
    return bank.turn_rotation_sd <= MAX_TURN_ROTATION_SD


def _turn_finds(bank: CandidateBank, params: CandidateParams, p_CQ: np.ndarray) -> bool:
    """Whether the turned camera can find points at ``p_CQ`` (K x 3, in the camera frame): 3 sd of the
    turn move the farthest of them by at most the window they are looked for in (``_turn_window``)."""
    _, window = _turn_window(bank, params)
    depth = float(np.max(np.linalg.norm(p_CQ, axis=1), initial=0.0))
    return 3.0 * bank.turn_rotation_sd * depth <= window


def recover(bank: CandidateBank, params: CandidateParams, seen: SeenFrame, pool: Pool) -> Pool:
    """With no leader and known points: a candidate leads with the camera that the known points give
    (``_camera_from_turn``, else ``_camera_from_known_points``), its ``p_HP`` kept. The pool
    unchanged when none does."""
    kept = pool.kept
    # A moved camera: the points the abandoned model observed kept their p_HP; the static scene
    # turned with the camera.
    found, kind = None, "scene turn, tool points kept"
    if bank.turn is not None:
        found = _camera_from_turn(kept, pool.archive, bank, params)
    if found is None:
        kind = "previous tool points"
        found = _camera_from_known_points(kept, dict(bank.known_points), params, bank.adopted_mse)
    if found is None and bank.turned_R_WC is not None:
        precise = _turn_is_precise(bank)
        kind = ("scene turn, points since the move" if precise
                else "points since the move, near the scene turn")
        # The joint fit (a few ms) only when a sample came: else the statistics are as they were.
        found = (_camera_from_turn_and_new_points(kept, bank, params) if precise
                 else _camera_near_turn_from_new_points(kept, pool.archive, bank, params) if pool.fed
                 else None)
    if found is None:
        return pool
    x, mse, leader = found
    if kind == "scene turn, tool points kept" and not _turn_is_precise(bank):
        kind = "tool points found by the scene turn"
    best = next(c for c in kept if c.feature_id == leader)
    expected = min(mse, bank.adopted_mse) if params.keep_allowable_error else mse
    verdict = {"scene turn, points since the move":
               "converged: the camera turned as the scene shows, placed by the points since the move",
               "points since the move, near the scene turn":
               "converged: the camera re-identified jointly from the points since the move"}.get(
        kind, "converged: the tool points kept, the camera re-identified")
    best = with_camera(best, x, x[12:15].copy(), expected, verdict)
    kept = [best if c.feature_id == leader else c for c in kept]
    adoptions = pool.adoptions + (Adoption(float(seen.time), leader, best.statistic.copy(),
                                           best.admitted, pool.round_start, best.solution.estimate, kind),)
    return replace(pool, kept=kept, leader=leader, adoptions=adoptions)


def model_points(bank: CandidateBank, params: CandidateParams) -> tuple:
    """``(feature_id, p_HP)`` of every point the adopted model holds (``keep_tool_points``): the
    leader first (the adopted tool point), the observed point, the witness, the observers, then
    every other candidate, tracked or archived (its track ended: a mark out of view now, which a
    new track may find again after the move), that the model's camera explains (``fitting.explained``,
    with ``observe_min_samples`` samples and ``min_rotation_spread``) with its best ``p_HP`` under
    that camera: points of the hand as well as of the tool, all fixed in H, and the more of them,
    the more spread."""
    x = bank.model_x
    anchor = x[12:15].copy()
    points = [(bank.leader, anchor),
              (bank.observed, anchor if bank.observed_p_HP is None else bank.observed_p_HP),
              (bank.witness, bank.witness_p_HP)] + [(o[0], o[1]) for o in bank.observers]
    R_WC, p_WC = x[0:9].reshape(3, 3, order="F"), x[9:12]
    points += [(c.feature_id, best_p_HP_given_camera(c.statistic, R_WC, p_WC))
               for c in bank.candidates + bank.archive
               if c.frames >= params.observe_min_samples
               and rotation_spread(c.statistic) >= params.min_rotation_spread
               and explained(c, x, bank.adopted_mse, params)]
    known = {}
    for feature_id, p_HP in points:
        if feature_id >= 0 and p_HP is not None and feature_id not in known:
            known[feature_id] = np.array(p_HP, dtype=float)
    return tuple(known.items())


def _fit_dropping_misfits(pairs: list, solve, limit: float):
    """Fit a camera to ``pairs`` (``(candidate, p_HP)``) with ``solve(pairs) -> (R_WC, p_WC, ...)``
    or None; while a point misfits (mean squared error over ``limit``: a track that slid onto
    another point, a point of a link that moved), leave out the worst and fit again, as long as the
    points that fit are more than half of them (a lone survivor fits anything near). Returns
    ``(found, pairs, errors)`` or None."""
    total = len(pairs)
    while 2 * len(pairs) > total:
        found = solve(pairs)
        if found is None:
            return None
        errors = [mean_squared_error_of(c.statistic, pack_x(found[0], found[1], p)) for c, p in pairs]
        if max(errors) <= limit:
            return found, pairs, errors
        pairs = [pair for k, pair in enumerate(pairs) if k != int(np.argmax(errors))]
    return None


def _leading(pairs: list, errors: list, found, anchor: np.ndarray, tracked: set | None = None):
    """``(x, mse, feature_id)`` of the fitted point nearest the adopted tool point ``anchor`` in H,
    with the fitted camera, among the candidates whose ids are in ``tracked`` (None: all); None if
    none is."""
    among = [i for i in range(len(pairs)) if tracked is None or pairs[i][0].feature_id in tracked]
    if not among:
        return None
    k = min(among, key=lambda i: float(np.linalg.norm(pairs[i][1] - anchor)))
    return pack_x(found[0], found[1], pairs[k][1]), errors[k], pairs[k][0].feature_id


def _camera_from_known_points(kept, known: dict, params: CandidateParams, adopted_mse: float):
    """``keep_tool_points``: the camera that the known points' samples since the reset give
    (``camera_given_points``; ``known`` in the order of ``model_points``, the adopted tool point
    first), from the points with ``observe_min_samples`` samples that fit it within
    ``observe_consistency`` of the adopted RMS error (``_fit_dropping_misfits``), if they spread
    ``min_point_spread`` off a line. Returns ``(x, mse, feature_id)`` (the estimate with the ``p_HP``
    of the point nearest the adopted tool point in H, its mean squared error, that point) or None."""
    pairs = [(c, known[c.feature_id]) for c in kept
             if c.feature_id in known and c.solution.num_samples >= params.observe_min_samples]
    fit = _fit_dropping_misfits(pairs, lambda ps: camera_given_points(
        [S_of(c.statistic) for c, _ in ps], np.array([p for _, p in ps])),
        params.observe_consistency**2 * adopted_mse)  # fmt: skip
    if fit is None or not fit[0][2] >= params.min_point_spread:
        return None
    return _leading(fit[1], fit[2], fit[0], next(iter(known.values())))


def _camera_from_turn(kept, archive, bank: CandidateBank, params: CandidateParams):
    """``keep_tool_points`` with the scene's turn: the camera that the move left turned as the
    static scene shows and placed where the known points' samples since the move put it
    (``camera_after_turn``). The points: candidates with ``turn_min_samples`` samples that are a
    known point, by id (tracked through the move) or by ``p_HP`` (``turn_radius``, see
    ``CandidateParams``), fitted with ``_fit_dropping_misfits``. Returns ``(x, mse, feature_id)``
    as ``_camera_from_known_points`` or None. With the scene's shift (``turned_p_WC``), the tracks
    are matched under the camera there, within ``turn_scene_shift``, one new track sufficing.
    A turn less certain than ``MAX_TURN_ROTATION_SD`` only matches the tracks, the archived ones
    since the move too (a person walking past ends every track within seconds): the camera is then
    the one the matched points' samples give alone (``camera_given_points``), within the turned
    camera's window, with its 95 % region within ``camera_accuracy`` and
    ``camera_rotation_accuracy`` (which measures how well the views pin its rotation, as
    ``min_point_spread`` does where there is no such gate); a tracked one of them leads."""
    if bank.turned_R_WC is None:
        return None  # too few anchors in the turn
    known = dict(bank.known_points)
    x0, turn, R_turned = bank.moved_from_x, bank.turn, bank.turned_R_WC
    R_WC0, p_WC0 = x0[0:9].reshape(3, 3, order="F"), x0[9:12]
    shifted, precise = bank.turned_p_WC is not None, _turn_is_precise(bank)
    p_turned, window = _turn_window(bank, params)
    pool = kept if precise else [*kept, *archive]
    ready = [c for c in pool if c.solution.num_samples >= params.turn_min_samples]
    if not precise and not _turn_finds(bank, params, np.array([c.last_p_CP for c in ready]).reshape(-1, 3)):
        return None
    pairs = [(c, known[c.feature_id]) for c in ready if c.feature_id in known]
    # A new track (the turn ended the old one) on a known corner is that corner seen from the
    # turned camera at the old position: off by the camera's unknown shift, the same for every
    # track (over the same time), so the shift is the offset most new tracks agree on. Only corners
    # are matched so: an anchored point is wherever its track began, a new one a few millimetres
    # from a known one is another point.
    known_p = np.array([p for i, p in bank.known_points if i in bank.known_corners]).reshape(-1, 3)
    new = [c for c in ready if c.feature_id not in known and c.symmetric
           and rotation_spread(c.statistic) >= params.min_rotation_spread]  # else a point of any link fits
    guesses = np.array([best_p_HP_given_camera(c.statistic, R_turned, p_turned) for c in new]).reshape(-1, 3)
    tracked = [best_p_HP_given_camera(c.statistic, R_turned, p_turned) - p for c, p in pairs]
    offset = _common_offset(guesses, known_p, tracked, params, window, 1 if shifted else 2)
    if offset is not None and len(known_p):
        for c, guess in zip(new, guesses, strict=True):
            distance = np.linalg.norm(known_p - (guess - offset), axis=1)
            j = int(np.argmin(distance))
            # The nearest other mark (known points within turn_radius of it are tracks of it).
            others = distance[np.linalg.norm(known_p - known_p[j], axis=1) > params.turn_radius]
            if distance[j] <= params.turn_radius and not np.any(others <= 2.0 * params.turn_radius):
                pairs.append((c, known_p[j]))
    limit = params.observe_consistency**2 * bank.adopted_mse
    if not precise:
        fit = _fit_dropping_misfits(pairs, lambda ps: camera_given_points(
            [S_of(c.statistic) for c, _ in ps], np.array([p for _, p in ps])), limit)  # fmt: skip
        if fit is None or not (np.linalg.norm(fit[0][1] - p_turned) <= window
                               and _within_accuracy_given_points(fit[1], fit[0], params)):
            return None
        return _leading(fit[1], fit[2], fit[0], next(iter(known.values())), {c.feature_id for c in kept})
    fit = _fit_dropping_misfits(pairs, lambda ps: camera_after_turn(
        R_WC0, p_WC0, TurnAnchors(turn.b0, turn.q0, turn.b1), [S_of(c.statistic) for c, _ in ps],
        np.array([p for _, p in ps])), limit)  # fmt: skip
    if fit is None:
        return None
    if not shifted and not tracked and _on_a_line([p for _, p in fit[1]], params.turn_radius):
        # Matched by the offset most new tracks agree on, with the shift unknown: along a row of
        # marks (the rod's) an offset of one spacing maps tracks of marks never known onto their
        # known neighbours and the camera follows it (17.7 mm in the tests); points off the line
        # leave no such offset.
        return None
    return _leading(fit[1], fit[2], fit[0], next(iter(known.values())))


def _camera_from_turn_and_new_points(kept, bank: CandidateBank, params: CandidateParams):
    """The camera turned as the static scene shows (``bank.turned_R_WC``), placed with the points
    tracked since the move, each with its own ``p_HP`` (``position_and_points_given_rotation``):
    candidates with ``observe_min_samples`` samples over ``min_rotation_spread`` of hand rotation
    (else a point of any link fits), at least ``FIRST_CHOICE_POINTS`` of them (one point fits a
    camera that another must confirm), while one misfits (over ``observe_consistency`` of the
    adopted RMS error: a point of the static scene or of another link) the worst left out, as long
    as more than half are left. The position's 95 % region must lie within ``camera_accuracy``
    and the position within the turned camera's window (``_turn_window``). Returns
    ``(x, mse, feature_id)`` (the point with the most samples) or None."""
    points = [c for c in kept if c.solution.num_samples >= params.observe_min_samples
              and rotation_spread(c.statistic) >= params.min_rotation_spread]
    total, limit = len(points), params.observe_consistency**2 * bank.adopted_mse
    while len(points) >= FIRST_CHOICE_POINTS and 2 * len(points) > total:
        S_list = [S_of(c.statistic) for c in points]
        found = position_and_points_given_rotation(S_list, bank.turned_R_WC)
        if found is None:
            return None
        worst = int(np.argmax(found.mean_squared_errors))
        if found.mean_squared_errors[worst] <= limit:
            break
        points = points[:worst] + points[worst + 1:]
    else:
        return None
    # The same fit, its covariance counting each point's independent samples at it.
    found = position_and_points_given_rotation(
        S_list, bank.turned_R_WC, independent_of(points, bank.turned_R_WC, found.p_WC, params))
    if found is None:
        return None
    p_turned, window = _turn_window(bank, params)
    if not (REGION_95 * math.sqrt(float(np.trace(found.covariance))) <= params.camera_accuracy
            and np.linalg.norm(found.p_WC - p_turned) <= window):
        return None
    k = max(range(len(points)), key=lambda i: points[i].solution.num_samples)
    return (pack_x(bank.turned_R_WC, found.p_WC, found.p_HP[k]), float(found.mean_squared_errors[k]),
            points[k].feature_id)


def _camera_near_turn_from_new_points(kept, archive, bank: CandidateBank, params: CandidateParams):
    """A turn less certain than ``MAX_TURN_ROTATION_SD``: the camera and a ``p_HP`` per point fitted
    jointly (``refine_joint``, 6 + 3K unknowns) to the points tracked since the move, the archived
    ones too (a person walking past ends every track within seconds), from the turned camera
    (``_turn_window``'s position): candidates with ``joint_min_samples`` samples over
    ``min_rotation_spread``, at least ``FIRST_CHOICE_POINTS``, misfits left out as in
    ``_camera_from_turn_and_new_points``. The camera must lie within the turned camera's window
    and its 95 % region (``joint_covariance``, each ``p_HP`` free) within ``camera_accuracy`` and
    ``camera_rotation_accuracy``. Returns ``(x, mse, feature_id)`` (the tracked point with the
    most samples) or None."""
    points = [c for c in [*kept, *archive] if c.solution.num_samples >= params.joint_min_samples
              and rotation_spread(c.statistic) >= params.min_rotation_spread]
    p_turned, window = _turn_window(bank, params)
    total, limit = len(points), params.observe_consistency**2 * bank.adopted_mse
    while len(points) >= FIRST_CHOICE_POINTS and 2 * len(points) > total:
        S_list = [S_of(c.statistic) for c in points]
        start = points_given_camera(S_list, bank.turned_R_WC, p_turned)
        fit = refine_joint(S_list, bank.turned_R_WC, p_turned, start)
        if fit is None:
            return None
        errors = [mean_squared_error_of(c.statistic, pack_x(fit[0], fit[1], p))
                  for c, p in zip(points, fit[2], strict=True)]
        worst = int(np.argmax(errors))
        if errors[worst] <= limit:
            break
        points = points[:worst] + points[worst + 1:]
    else:
        return None
    R_WC, p_WC, P = fit
    independent = independent_of(points, R_WC, p_WC, params)
    covariance = joint_covariance(S_list, R_WC, p_WC, P, independent=independent)
    ids = {c.feature_id for c in kept}
    tracked = [k for k in range(len(points)) if points[k].feature_id in ids]
    if not (tracked and np.linalg.norm(p_WC - p_turned) <= window
            and sd_within_targets(camera_sd(covariance), params)):
        return None
    k = max(tracked, key=lambda i: points[i].solution.num_samples)
    return pack_x(R_WC, p_WC, P[k]), float(errors[k]), points[k].feature_id


def _within_accuracy_given_points(pairs: list, found, params: CandidateParams) -> bool:
    """Whether the 95 % region of the camera ``found`` (``R_WC, p_WC, ...``) that ``pairs``
    (``(candidate, p_HP)``) give with their ``p_HP`` fixed lies within ``camera_accuracy`` and
    ``camera_rotation_accuracy`` (``joint_covariance`` with ``points_known``)."""
    return sd_within_targets(camera_sd(joint_covariance(
        [S_of(c.statistic) for c, _ in pairs], found[0], found[1], np.array([p for _, p in pairs]),
        points_known=True, independent=independent_of([c for c, _ in pairs], found[0], found[1], params))),
        params)


def _turn_window(bank: CandidateBank, params: CandidateParams) -> tuple[np.ndarray, float]:
    """Where the turned camera is taken to be and how far off that may be (m): at the shift the
    scene's depth gave, within ``turn_scene_shift``, else at the old position, within
    ``turn_max_shift``."""
    if bank.turned_p_WC is not None:
        return bank.turned_p_WC, params.turn_scene_shift
    return bank.moved_from_x[9:12], params.turn_max_shift


def near_known_points(bank: CandidateBank, params: CandidateParams, X_WH: np.ndarray, p_CP: np.ndarray,
                       usable: np.ndarray) -> np.ndarray:
    """``turn_admit_known``: per tracked feature (``usable``: the symmetric ones), whether its point
    lies within the turned camera's window plus ``turn_radius`` of where that camera, posed as
    ``_turn_window`` says, sees a known corner of the hand at ``X_WH`` (all False before a turn).
    The detector's body cells are fixed in the image, so after a camera move they hold the static
    scene and its trials must find the body's features again, which can take seconds while the
    tracks already lie a few mm from where the known marks are predicted (docs/hand_eye_record.md);
    the model says where they are. A point of the static scene admitted so is left out by the
    camera's fit: with the hand turning, its samples fit no point of H."""
    near = np.zeros(len(usable), bool)
    corners = [p for i, p in bank.known_points if i in bank.known_corners]
    if bank.turned_R_WC is None or not corners or not np.any(usable):
        return near
    p_WC, window = _turn_window(bank, params)
    p_CQ = points_in_camera(bank.turned_R_WC, p_WC, np.array(corners), X_WH)
    if not _turn_finds(bank, params, p_CQ):
        return near
    distance = np.linalg.norm(p_CP[usable][:, None, :] - p_CQ[None, :, :], axis=2).min(axis=1)
    near[usable] = distance <= window + params.turn_radius
    return near


def _on_a_line(points: list, tolerance: float) -> bool:
    """Whether the points lie within ``tolerance`` (RMS, m) of one line (one or two always do)."""
    return len(points) < 3 or spread_off_line(np.cov(np.array(points).T, bias=True)) <= tolerance


def _common_offset(guesses: np.ndarray, known_p: np.ndarray, tracked: list, params: CandidateParams,
                   max_shift: float, min_support: int):
    """The offset (in H) between new tracks' ``p_HP`` under the turned camera (``guesses``) and the
    known points: the median offset of the points tracked through the move (``tracked``, their
    own offsets) if any; else, among the offsets within ``max_shift`` of a guess to a known
    point, the one that the most guesses fit within ``turn_radius`` (at least ``min_support``: with
    the camera's shift unknown, two, as one track fits some mark for many shifts), the smallest of
    those. None if none."""
    if tracked:
        return np.median(np.array(tracked), axis=0)
    options = (guesses[:, None, :] - known_p[None, :, :]).reshape(-1, 3)
    options = options[np.linalg.norm(options, axis=1) <= max_shift]
    best, support = None, min_support - 1
    for o in sorted(options, key=lambda o: float(np.linalg.norm(o))):
        fits = np.linalg.norm(guesses[:, None, :] - o - known_p[None, :, :], axis=2).min(axis=1)
        n = int(np.count_nonzero(fits <= params.turn_radius))
        if n > support:
            best, support = o, n
    return best
