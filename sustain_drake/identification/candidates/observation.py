"""Observation under the adopted model (paper Fig. 7, §4.3, beyond it where noted): once there is a
leader, its feature (the *observed* feature) gives one ``s_t`` (Eq. (2)) per frame under the reference
(adopted) estimate, confirmed by a witness. When the observed feature is lost, the body feature nearest
to where the adopted estimate puts the tracked point (within ``reacquire_radius``) takes its place, so a
re-seeded track of the same point keeps the observation going. Beyond the paper: extra observers, blind
evidence on frames with no observed point, and the depth check of the adopted tool point
(``free_space_radius``): a surface seen behind where the model puts it is a violation, tracked points or
not (and only a violation: the depth cannot confirm the model)."""

import math
from dataclasses import replace

import numpy as np

from sustain_drake.identification.candidates.admission import within_motion_gate
from sustain_drake.identification.candidates.bank import CandidateBank, mark_verified
from sustain_drake.identification.candidates.fitting import (
    own_fit,
    predicted_p_CP,
    rotation_spread,
    sample_error,
    x_is_set,
)
from sustain_drake.identification.candidates.frame import SeenFrame
from sustain_drake.identification.candidates.params import CandidateParams
from sustain_drake.identification.eye_to_hand import pack_x

# A single sample's squared error may exceed the mean squared limit by this much (its chi-square
# tail with three degrees of freedom: P(s > 10 mse) < 1e-3 for Gaussian noise).
_NOW_FACTOR = 10.0


def observe(bank: CandidateBank, params: CandidateParams, seen: SeenFrame) -> CandidateBank:
    """``observe_primary`` (the observed point and its witness), then the extra observers
    (``params.max_observers``, the points nearest the adopted tool point first): every consistent
    point tracked now gives its own ``s_t`` under the adopted camera with its own ``p_HP``. The
    points within ``observe_radius`` of the tool point (the tool's) and the others (the hand's) are
    two groups; the reported ``s_t`` is the larger of the groups' lower medians (the hand's, when it
    is one point, only in a frame without a tool point). A change of the body moves every point of
    its group (a slipped tool the tool's, a moved camera all), a tracking failure one; and while
    the observed point is lost (its face turned away, or its track ended in the change itself) the
    observers keep the observation going, so a change is not missed for want of the one point the
    paper observes.

    A frame whose sample includes a tool point within the allowable error *verifies* the model:
    every candidate's samples so far count as taken under a verified model (``verified_overlap``).
    A frame with no sample may count as a violation (``unverified_evidence``). The adopted tool
    point's depth check (``free_space_radius``) joins the frame's sample."""
    reference_x, allowable_error = seen.given.reference_x, seen.given.allowable_error
    depth_gap = seen.given.depth_gap
    before = bank.sample_count
    bank = _observe_points(bank, params, seen)
    if params.free_space_radius > 0 and depth_gap is not None:
        bank = _free_space_sample(bank, reference_x, seen.X_WH, depth_gap, before, allowable_error)
    if bank.leader < 0 or bank.sample_count > before:
        if bank.leader >= 0 and bank.tool_observed and bank.sample_error <= allowable_error:
            bank = mark_verified(bank)  # a tool point the model holds was seen where the model puts it
        return bank
    x = _model_in_use(bank, reference_x)
    if x is not None and params.unverified_evidence and _unverified_tool(bank, params, seen, x):
        return replace(bank, sample_count=before + 1, sample_error=math.inf, sample_errors=())
    return bank


def _free_space_sample(bank, reference_x, X_WH, depth_gap, before: int,
                       allowable_error: float) -> CandidateBank:
    """``free_space_radius``: the depth behind the adopted tool point gives ``s_t = max(gap, 0)^2``,
    the larger with the points' sample of this frame. On a frame with no point's sample it is a
    sample only when it violates ``allowable_error``: the depth can show that the tool is not where
    the model puts it (a surface clearly behind), never that it is (a surface at or in front of the
    point is the tool, or the arm, or a person passing, and a model off along the surface finds one
    there too), so a silent depth check must not keep a changed model alive while no point is seen."""
    x = _model_in_use(bank, reference_x)
    if x is None:
        return bank
    gap = depth_gap(predicted_p_CP(x, X_WH))
    if math.isnan(gap):
        return bank  # the tool point out of view: no evidence either way
    s_t = max(gap, 0.0) ** 2
    if bank.sample_count > before:
        return replace(bank, sample_error=max(bank.sample_error, s_t))
    if not s_t > allowable_error:
        return bank
    return replace(bank, sample_count=before + 1, sample_error=s_t, sample_errors=())


def _unverified_tool(bank, params, seen: SeenFrame, x) -> bool:
    """``unverified_evidence``: whether a tool candidate (within ``observe_radius`` of the adopted
    tool point) is explained by the adopted camera with its own ``p_HP`` but lacks the
    ``verified_overlap`` samples to observe."""
    if params.verified_overlap == 0:
        return False
    options = _near_tool(consistent(bank, params, seen, x), x[12:15].copy(), params)
    return any(bank.find(o[1]).verified_samples < params.verified_overlap for o in options)


def _observe_points(bank, params, seen: SeenFrame) -> CandidateBank:
    """The observed, witness and observer points' ``s_t`` (see ``observe``); ``tool_observed``
    says whether a tool point gave one this frame."""
    X_WH, p_CP, usable = seen.X_WH, seen.p_CP, seen.usable
    before = bank.sample_count
    bank = observe_primary(bank, params, seen)
    bank = replace(bank, tool_observed=bank.sample_count > before)  # the observed point is the tool's
    if params.max_observers == 0:
        return bank
    x = _model_in_use(bank, seen.given.reference_x)
    if x is None:
        return bank
    anchor = x[12:15].copy()  # the adopted tool point
    errors, observers = [], []  # errors: (s_t, on the tool)
    for feature_id, p_HP, last in bank.observers:
        k = _gated_row(feature_id, last, seen, params)
        if k is None or feature_id in (bank.observed, bank.witness):
            continue  # lost, jumped, or observed already: dropped
        if usable[k]:
            x[12:15] = p_HP
            errors.append((sample_error(p_CP[k], X_WH, x), _on_tool(p_HP, anchor, params)))
            last = (p_CP[k].copy(), X_WH)
        observers.append((feature_id, p_HP, last))
    if len(observers) < params.max_observers:
        taken = {o[0] for o in observers} | {bank.observed, bank.witness}
        options = consistent(bank, params, seen, x, exclude=tuple(taken), verified=True)
        # The tool's points first (nearest the adopted tool point), then the hand's.
        for _, feature_id, p_HP, k in sorted(options, key=lambda o: float(np.linalg.norm(o[2] - anchor))):
            if len(observers) >= params.max_observers:
                break
            observers.append((feature_id, p_HP, (p_CP[k].copy(), X_WH)))
    bank = replace(bank, observers=tuple(observers))
    if not errors and bank.sample_count == before and params.blind_min_samples > 0:
        return _blind_evidence(bank, params, seen, x, before)
    if bank.sample_count > before:  # the observed point (or its witness) gave a sample too
        primary = [bank.observed_p_HP if bank.observed_p_HP is not None else anchor, bank.witness_p_HP]
        errors += [(e, p is not None and _on_tool(p, anchor, params))
                   for e, p in zip(bank.sample_errors, primary, strict=False)]
    if not errors:
        return bank
    # Per group (the tool's points, the hand's), the lower median: one point (the smallest of
    # two) is the paper's; with three or more, a point that fails alone (a track that slid, a
    # point re-acquired near the prediction by chance) moves it neither up nor down. The larger of
    # the two groups' is reported: a slipped tool moves the tool's points only, a moved camera all.
    # The hand's points fail only with a moved camera, which moves the tool's too: while a tool
    # point is seen, a hand group of one point speaks only with the tool's (its track sliding onto
    # the background is not a change).
    tool = [e for e, on_tool in errors if on_tool]
    hand = [e for e, on_tool in errors if not on_tool]
    reported = max(_lower_median(tool), _lower_median(hand) if len(hand) >= 2 or not tool else -math.inf)
    return replace(bank, sample_count=before + 1, sample_error=reported,
                   tool_observed=bool(tool))


def _blind_evidence(bank, params, seen: SeenFrame, x, before: int) -> CandidateBank:
    """No observed point this frame (``blind_min_samples``): the candidates tracked now with at
    least that many samples are asked instead. When at least two are and NONE is explained by the
    adopted camera within the allowable error (its mean squared error with its own best ``p_HP``),
    the frame counts as a sample of that size (the smallest): every point in view disagrees with
    the model, as after a moved camera; one point of the hand or tool that fits (any point fits
    while the hand only translates) keeps the frame silent."""
    row, usable, allowable_error = seen.row, seen.usable, seen.given.allowable_error
    R_WC, p_WC = x[0:9].reshape(3, 3, order="F"), x[9:12]
    misfits = []
    for c in bank.candidates:
        k = row.get(c.feature_id)
        if k is None or not usable[k] or c.frames < params.blind_min_samples:
            continue
        misfits.append(own_fit(c.statistic, R_WC, p_WC)[1])
    if len(misfits) < 2 or not min(misfits) > allowable_error:
        return bank
    return replace(bank, sample_count=before + 1, sample_error=float(min(misfits)))


def _on_tool(p_HP, anchor, params: CandidateParams) -> bool:
    return float(np.linalg.norm(np.asarray(p_HP) - anchor)) <= params.observe_radius


def _lower_median(values: list) -> float:
    """The lower median (-inf for none): the smaller of two, the middle of three."""
    if not values:
        return -math.inf
    values = sorted(v if math.isfinite(v) else math.inf for v in values)
    return values[(len(values) - 1) // 2]


def _model_in_use(bank: CandidateBank, reference_x) -> np.ndarray | None:
    """The model observations are judged against: the adopted ``x`` (reference) if set, else the
    leader's solution; None when there is no leader or no model yet. A copy."""
    if bank.leader < 0:
        return None
    x = reference_x if x_is_set(reference_x) else bank.find(bank.leader).solution.x
    return np.array(x, dtype=float) if x_is_set(x) else None


def observe_primary(bank: CandidateBank, params: CandidateParams, seen: SeenFrame) -> CandidateBank:
    """The observed point's ``s_t`` (Eq. (2)) under the reference estimate, confirmed by a witness;
    when it is lost, re-acquisition near the prediction or another consistent candidate.

    The witness is a second candidate consistent with the adopted camera (nearest in H to the
    observed point, so on the same part of the tool when there is one). The reported ``s_t`` is
    the smaller of the two: a change of the body (the tool slipped, the camera moved) moves both
    points, a tracking failure (a corner sliding along a silhouette onto the background) only one.
    When the observed point alone violates ``allowable_error`` for ``primary_failures`` samples
    while the witness does not, the witness becomes the observed point."""
    X_WH, p_CP, usable, row = seen.X_WH, seen.p_CP, seen.usable, seen.row
    allowable_error = seen.given.allowable_error
    x = _model_in_use(bank, seen.given.reference_x)
    if x is None:
        return bank
    anchor = x[12:15].copy()  # the adopted tool point
    if bank.observed_p_HP is not None:
        x[12:15] = bank.observed_p_HP
    k = _gated_row(bank.observed, bank.observed_last, seen, params)
    if k is None:
        return _reacquire(bank, params, seen, x, anchor)
    if not usable[k]:
        return bank
    error = sample_error(p_CP[k], X_WH, x)
    bank = replace(bank, observed_last=(p_CP[k].copy(), X_WH))
    if bank.witness < 0 or bank.witness not in row:
        bank = _choose_witness(bank, params, seen, x, anchor)
    w = _witness_row(bank, seen, params)
    reported, failures, errors = error, 0, (error,)
    if w is not None and usable[w]:
        x_w = x.copy()
        x_w[12:15] = bank.witness_p_HP
        witness_error = sample_error(p_CP[w], X_WH, x_w)
        bank = replace(bank, witness_last=(p_CP[w].copy(), X_WH))
        reported = min(error, witness_error)
        errors = (error, witness_error)
        if error > allowable_error >= witness_error:
            failures = bank.primary_failures + 1
    elif w is None and bank.witness >= 0:
        bank = replace(bank, witness=-1, witness_p_HP=None, witness_last=None)
    bank = replace(bank, sample_count=bank.sample_count + 1, primary_failures=failures,
                   sample_error=reported if math.isfinite(reported) else math.inf, sample_errors=errors)
    if failures >= params.primary_failures:
        bank = replace(bank, observed=bank.witness, observed_p_HP=bank.witness_p_HP,
                       observed_last=bank.witness_last, witness=-1, witness_p_HP=None,
                       witness_last=None, primary_failures=0)
    return bank


def _witness_row(bank: CandidateBank, seen: SeenFrame, params):
    """The witness's row if there is one, tracked and not jumped (``_gated_row``), else None."""
    return _gated_row(bank.witness, bank.witness_last, seen, params) if bank.witness >= 0 else None


def _gated_row(feature_id, last, seen: SeenFrame, params):
    """The feature's row if tracked and its point did not jump (a tracking failure), else None."""
    p_CP, X_WH = seen.p_CP, seen.X_WH
    k = seen.row.get(feature_id)
    if k is not None and last is not None:
        p_prev, X_prev = last
        jump = replace(params, gate_margin=params.gate_margin + params.observation_jump)
        if not within_motion_gate(p_prev, X_prev, p_CP[k], X_WH, jump):
            return None
    return k


def consistent(bank, params, seen: SeenFrame, x, exclude=(), verified=False, min_samples=None):
    """Candidates tracked now with ``min_samples`` samples (None: ``observe_min_samples``) whose
    samples the adopted camera explains (each with its own best ``p_HP``, least squares from its
    statistic), and whose point in this frame (``seen``) too (a frozen candidate's track
    may have slid onto the background since): ``[(mse, feature_id, p_HP, row)]``. ``verified``:
    only candidates with ``verified_overlap`` samples taken while the adopted model was verified
    (the points that may observe it)."""
    p_now, X_now, row, usable = seen.p_CP, seen.X_WH, seen.row, seen.usable
    R_WC, p_WC = x[0:9].reshape(3, 3, order="F"), x[9:12]
    limit = params.observe_consistency**2 * bank.adopted_mse
    out = []
    for c in bank.candidates:
        k = row.get(c.feature_id)
        if k is None or not usable[k] or c.feature_id in exclude:
            continue
        if verified and c.verified_samples < params.verified_overlap:
            continue  # first tracked while the model was not verified: its p_HP is unchecked
        fit = _own_fit_within(c, params, R_WC, p_WC, limit, min_samples)
        now = None if fit is None else sample_error(p_now[k], X_now, pack_x(R_WC, p_WC, fit[0]))
        if now is not None and now <= _NOW_FACTOR * limit:
            out.append((fit[1], c.feature_id, fit[0], k))
    return out


def _own_fit_within(c, params, R_WC, p_WC, limit: float, min_samples=None):
    """``(p_HP, mse)`` of the candidate's own fit under the camera (``fitting.own_fit``) when it has
    ``min_samples`` frames (None: ``observe_min_samples``) over ``min_rotation_spread`` of hand
    rotation (else any point, even on another link, would fit) and fits within ``limit`` (m^2);
    else None."""
    if c.frames < (params.observe_min_samples if min_samples is None else min_samples):
        return None
    if rotation_spread(c.statistic) < params.min_rotation_spread:
        return None
    p_HP, mse = own_fit(c.statistic, R_WC, p_WC)
    return (p_HP, mse) if mse <= limit else None


def witnessed_by(c, params: CandidateParams, x, adopted_mse: float) -> bool:
    """Whether the candidate's samples alone (no frame of now: its track may have ended) fit the
    camera of ``x`` with its own ``p_HP`` within ``observe_consistency`` times the RMS error
    ``adopted_mse`` (m^2), with ``observe_min_samples`` frames over ``min_rotation_spread``."""
    R_WC, p_WC = np.asarray(x)[0:9].reshape(3, 3, order="F"), np.asarray(x)[9:12]
    return _own_fit_within(c, params, R_WC, p_WC, params.observe_consistency**2 * adopted_mse) is not None


def _near_tool(options, anchor, params: CandidateParams) -> list:
    """The consistent points (``consistent``'s options) within ``observe_radius`` of the adopted
    tool point ``anchor`` in H, nearest first: a change of the held tool moves only the tool's
    points (a point of the gripper stays where the model puts it after the tool slipped)."""
    near = [(float(np.linalg.norm(o[2] - anchor)), o) for o in options]
    return [o for d, o in sorted(near, key=lambda n: n[0]) if d <= params.observe_radius]


def _choose_witness(bank, params, seen: SeenFrame, x, anchor) -> CandidateBank:
    """A witness for the observed point (see ``observe_primary``), or none."""
    options = consistent(bank, params, seen, x, exclude=(bank.observed, bank.leader), verified=True)
    options = _near_tool(options, anchor, params)
    if not options:
        return replace(bank, witness=-1, witness_p_HP=None, witness_last=None)
    _, feature_id, p_HP, _ = options[0]
    return replace(bank, witness=feature_id, witness_p_HP=p_HP, witness_last=None)


def _reacquire(bank, params, seen: SeenFrame, x, anchor) -> CandidateBank:
    """A new observed point: a body feature where ``x`` puts the observed point (a new track of
    the same point), else the witness if still tracked, else the consistent candidate nearest to
    it in H (with its own ``p_HP``), else none."""
    X_WH, ids, p_CP, usable = seen.X_WH, seen.ids, seen.p_CP, seen.usable
    near = np.flatnonzero(usable & seen.body)
    if near.size:
        distance = np.linalg.norm(p_CP[near] - predicted_p_CP(x, X_WH), axis=1)
        best = int(np.argmin(distance))
        if distance[best] <= params.reacquire_radius:
            k = int(near[best])
            bank = replace(bank, observed=int(ids[k]), observed_last=(p_CP[k].copy(), X_WH))
            if bank.observed == bank.witness:
                bank = replace(bank, witness=-1, witness_p_HP=None, witness_last=None)
            return bank
    w = _witness_row(bank, seen, params)
    if w is not None and usable[w]:
        # The witness, chosen while it fitted the model, takes over whether or not it fits now: a
        # change that ended the observed point's track (a slip moves a mark by centimetres in a
        # tenth of a second) moved the witness too, and its error is the evidence.
        return replace(bank, observed=bank.witness, observed_p_HP=bank.witness_p_HP,
                       observed_last=bank.witness_last, witness=-1, witness_p_HP=None, witness_last=None)
    options = consistent(bank, params, seen, x, exclude=(bank.observed,), verified=True)
    # The consistent point nearest in H to the adopted tool point: the observation stays on the
    # tool (a chain of hand-overs must not drift onto the hand, which does not see the tool slip).
    options = _near_tool(options, anchor, params)
    if not options:
        return replace(bank, observed=-1, observed_last=None)
    _, feature_id, p_HP, k = options[0]
    witness = (dict(witness=-1, witness_p_HP=None, witness_last=None) if feature_id == bank.witness else {})
    return replace(bank, observed=feature_id, observed_p_HP=p_HP, observed_last=(p_CP[k].copy(), X_WH),
                   **witness)
