"""How a tracked point's measurement error repeats with its view, on rendered scenes: the model behind
``CandidateParams.view_angle`` and ``view_correlation`` (the cameras' 95 % regions count a point's
samples by how much of its error repeats within a view).

    .venv/bin/python bench/bench_view_correlation.py --cells 6 10 [--duration 40] [--split tuning]

Runs each scene-matrix cell for ``--duration`` s with every sample the candidate identifiers take
recorded, then, per track of at least ``MIN_SAMPLES`` samples that is fixed on the hand (its RMS
error under the true camera, with its own best ``p_HP``, at most ``MAX_RMS``): its error vector at
each sample (Eq. (30)'s residual in W), and for every pair of its samples the view distance
(``admission.view_distance``: the hand's turn between them plus the angle between their rays). It
prints the mean of ``e_i . e_j`` over ``mean |e|^2`` per bin of view distance (1 at a repeated
error, 0 at an independent one; a track's own ``p_HP`` absorbs its mean, so far pairs go slightly
negative) and, per track, its samples, its distinct views at the measured ``view_angle`` and the
share of its error that repeats within them as the loop estimates it (``view_correlation.
repeated_share`` at the true camera) with the independent samples that gives.
Scenes only (tuning cells); the figures go to docs/hand_eye_record.md.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from make_scene_matrix import ROOT  # noqa: E402

from sustain_drake.experiments.run import simulate_scenario  # noqa: E402
from sustain_drake.identification import EyeToHandIdentifier, view_correlation  # noqa: E402
from sustain_drake.identification.candidates import admission  # noqa: E402
from sustain_drake.identification.candidates.fitting import S_of  # noqa: E402
from sustain_drake.loops.hand_eye import HandEyeConfig, hand_eye_parts  # noqa: E402
from sustain_drake.station.scenario_files import load_scenario_string  # noqa: E402
from sustain_drake.sweeps.spec import load_sweep  # noqa: E402

MIN_SAMPLES = 100  # a track with fewer says little about its own correlation
MAX_RMS = 2.5e-3  # m: a point of another link (not fixed in H) has structured errors of its own
BINS = (0.0, 0.01, 0.02, 0.04, 0.06, 0.08, 0.12, 0.16, 0.24, math.inf)  # rad of view distance
MAX_PAIRS = 1_000_000  # per track, drawn at random beyond this


def record(cell, duration: float) -> tuple[list, np.ndarray]:
    """Every sample the candidates took in ``cell`` over ``duration`` s, ``(time, feature id, p_CP,
    X_WH, symmetric)``, and the true camera pose at the start (4 x 4)."""
    samples, feed = [], admission.feed

    def recording_feed(c, params, criteria, time, p_CP, X_WH, *rest, **keywords):
        fed = feed(c, params, criteria, time, p_CP, X_WH, *rest, **keywords)
        if fed.statistic is not c.statistic:
            samples.append((float(time), c.feature_id, np.array(p_CP), np.array(X_WH), c.symmetric))
        return fed

    X_WC = []

    def on_step(t, simulator):
        if not X_WC:
            station = [s for s in simulator.get_system().GetSystems() if s.HasOutputPort("true_X_WC")][0]
            context = station.GetMyContextFromRoot(simulator.get_context())
            X_WC.append(station.GetOutputPort("true_X_WC").Eval(context).GetAsMatrix4())

    admission.feed = recording_feed
    try:
        with tempfile.TemporaryDirectory() as out:
            simulate_scenario(load_scenario_string(cell.scenario_text), out, duration=duration,
                              replay=False, on_step=on_step)
    finally:
        admission.feed = feed
    return samples, X_WC[0]


def own_p_HP(P: np.ndarray, X_WH: np.ndarray, X_WC: np.ndarray) -> np.ndarray:
    """A track's best ``p_HP`` under the true camera: the mean of ``R_WH^T (p_WP - p_WH)``."""
    p_WP = P @ X_WC[:3, :3].T + X_WC[:3, 3]
    return np.einsum("tji,tj->ti", X_WH[:, :3, :3], p_WP - X_WH[:, :3, 3]).mean(axis=0)


def errors_of(P: np.ndarray, X_WH: np.ndarray, X_WC: np.ndarray) -> np.ndarray:
    """Each sample's Eq. (30) residual in W (n x 3, m) under the true camera and the track's own best
    ``p_HP`` (``own_p_HP``)."""
    p_WP = P @ X_WC[:3, :3].T + X_WC[:3, 3]
    return p_WP - X_WH[:, :3, 3] - np.einsum("tij,j->ti", X_WH[:, :3, :3], own_p_HP(P, X_WH, X_WC))


def correlation(samples: list, X_WC: np.ndarray, view_angle: float, rng) -> tuple[np.ndarray, list]:
    """Per point kind (0 anchored on its patch, 1 centrally symmetric corner) and ``BINS`` bin,
    ``(sum of e_i . e_j / mean |e|^2, pairs)`` over the tracks fixed on the hand, and per such track
    ``(id, symmetric, samples, distinct views, RMS error m, repeated share, independent samples)``."""
    tracks, kinds = {}, {}
    for _, i, p, X, symmetric in samples:
        tracks.setdefault(i, []).append((p, X))
        kinds[i] = bool(symmetric)
    sums, tracks_out = np.zeros((2, len(BINS) - 1, 2)), []
    for i, s in tracks.items():
        if len(s) < MIN_SAMPLES:
            continue
        P, X = np.array([p for p, _ in s]), np.array([x for _, x in s])
        e = errors_of(P, X, X_WC)
        power = float((e**2).sum(axis=1).mean())
        if power > MAX_RMS**2:
            continue
        views = np.array([admission.view_of(p, x) for p, x in s])
        share, independent, kept = _as_the_loop_counts(P, X, X_WC, view_angle)
        tracks_out.append((i, kinds[i], len(s), kept, math.sqrt(power), share, independent))
        a, b = np.triu_indices(len(s), 1)
        if len(a) > MAX_PAIRS:
            pick = rng.choice(len(a), MAX_PAIRS, replace=False)
            a, b = a[pick], b[pick]
        distance = admission.view_distance(views[a], views[b])
        k = np.digitize(distance, BINS) - 1
        np.add.at(sums[int(kinds[i]), :, 0], k, (e[a] * e[b]).sum(axis=1) / power)
        np.add.at(sums[int(kinds[i]), :, 1], k, 1.0)
    return sums, tracks_out


def _as_the_loop_counts(P: np.ndarray, X: np.ndarray, X_WC: np.ndarray, view_angle: float):
    """A track's samples grouped into views as the loop groups them (``admission.with_view``), and
    at the true camera with the track's own ``p_HP``: ``(repeated share, independent samples,
    views)``."""
    views, sums = np.zeros((0, 12)), np.zeros((0, view_correlation.VIEW_ROW))
    identifier = EyeToHandIdentifier()
    for p, x in zip(P, X, strict=True):
        identifier.add(p, x[:3, :3], x[:3, 3])
        views, sums = admission.with_view(views, sums, p, x, view_angle)
    S, R_WC, p_WC, p_HP = S_of(identifier.state), X_WC[:3, :3], X_WC[:3, 3], own_p_HP(P, X, X_WC)
    return (view_correlation.repeated_share(sums, S, R_WC, p_WC, p_HP),
            view_correlation.independent_samples(sums, S, R_WC, p_WC, p_HP), len(views))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cells", type=int, nargs="+", required=True)
    p.add_argument("--split", default="tuning", choices=("tuning",), help="tuning cells only")
    p.add_argument("--duration", type=float, default=40.0)
    args = p.parse_args(argv)
    sweep = load_sweep(ROOT / "diagrams" / "sweeps" / f"scene_matrix_{args.split}.yaml")
    view_angle = hand_eye_parts(HandEyeConfig(enabled=True)).candidates.view_angle
    rng = np.random.default_rng(0)
    for index in args.cells:
        samples, X_WC = record(sweep.cells[index], args.duration)
        sums, tracks = correlation(samples, X_WC, view_angle, rng)
        print(f"cell {index} ({args.duration:g} s): {len(tracks)} tracks fixed on the hand")
        for i, symmetric, n, v, rms, share, independent in tracks:
            kind = "symmetric" if symmetric else "anchored"
            print(f"  track {i} ({kind}): {n} samples, {v} views at {view_angle:g} rad, "
                  f"RMS {rms * 1e3:.2f} mm, repeated share {share:.2f}: {independent:.0f} independent")
        for kind, by_bin in zip(("anchored", "symmetric"), sums, strict=True):
            if not by_bin[:, 1].any():
                continue
            print(f"  {kind} points: view distance (rad) | correlation | pairs")
            for lo, hi, (total, pairs) in zip(BINS[:-1], BINS[1:], by_bin, strict=True):
                if pairs:
                    print(f"    {lo:.2f}-{hi:.2f} | {total / pairs:+.2f} | {int(pairs)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
