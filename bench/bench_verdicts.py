"""Verdicts that degenerate or mis-scaled data cannot fool (issue 25): counts over random streams.

Run:  .venv/bin/python bench/bench_verdicts.py   (about 10 min of one core; --streams for fewer)

For every kind of stream in ``tests/verdict_streams.py`` it draws ``--streams`` random streams
(10 to 300 samples, random camera, tool point, workspace, noise up to 2 mm or 0.05 N / 1 mN m,
a fifth noise-free) and counts the converged verdicts, batch (``calibrate_eye_to_hand``,
``identify_payload``) and streaming (``add`` sample by sample, ``solve`` at four checkpoints; a
stream counts if any checkpoint says converged):

- degenerate eye-to-hand streams (pure translation, rotation about one axis, one pose repeated,
  two poses) and payload streams (one orientation, turns about gravity only, one sample repeated):
  the target is 0 converged;
- well-excited eye-to-hand streams in millimetres (hand, points, both) or with a left-handed or
  negated camera frame: the target is 0 cameras (0 converged);
- well-excited streams, and weak ones (wide turns about one axis, 0.003-0.3 rad about the others):
  how many converge, and how many converged ones are within 6 sd (Gauss-Newton's, from the true
  noise) of the truth (the target: all).

Then the covariances (``EyeToHandResult.covariance``, ``PayloadResult.covariance``): over
``--coverage`` runs, how often the truth lies inside their 95 % region (target: 93-97 %).

It also tallies the reasons (the ``observability`` constant each reason starts with). Exit status 1
if a target is missed.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # one core, before numpy loads OpenBLAS

import argparse  # noqa: E402
import re  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import numpy as np  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402
from scipy.stats import chi2  # noqa: E402
from verdict_streams import (  # noqa: E402  (tests/verdict_streams.py)
    EYE_DEGENERATE,
    EYE_UNITS_AND_FRAMES,
    PAYLOAD_DEGENERATE,
    eye_stream,
    eye_within_noise,
    payload_stream,
    payload_within_noise,
    stream_eye,
    stream_payload,
)

from sustain_drake.identification import calibrate_eye_to_hand, identify_payload, observability  # noqa: E402

NOISY = ("excited", "weak")  # well excited; wide turns about one axis with small ones about the others


def reason_key(verdict) -> str:
    if verdict.converged:
        return "converged"
    for constant in observability.REASONS:
        if verdict.reason.startswith(constant):
            return constant
    return re.split(r"[\d:(]", verdict.reason)[0].strip()  # the words before the figures


def _eye(seed: int, kind: str):
    stream = eye_stream(seed, kind)
    result = calibrate_eye_to_hand(stream.p_C, stream.X_WH)
    within = result.converged and kind in NOISY and eye_within_noise(stream, result.X_WC, result.p_HP)
    return result.verdict, within, any(s.verdict.converged for s in stream_eye(stream))


def _payload(seed: int, kind: str):
    stream = payload_stream(seed, kind)
    result = identify_payload(stream.wrench, stream.R_WK)
    within = result.converged and kind in NOISY and payload_within_noise(stream, result.mass, result.p_KCm)
    return result.verdict, within, any(s.verdict.converged for s in stream_payload(stream))


def count(one, kind: str, streams: int, seed0: int) -> dict:
    """Converged verdicts (batch, streaming), converged ones within the noise, and the reasons."""
    row = {"batch": 0, "streaming": 0, "within": 0, "reasons": Counter()}
    for seed in range(seed0, seed0 + streams):
        verdict, within, streamed = one(seed, kind)
        row["reasons"][reason_key(verdict)] += 1
        row["batch"] += verdict.converged
        row["within"] += within
        row["streaming"] += streamed
    return row


def coverage(runs: int, seed0: int) -> tuple[int, int]:
    """How often the truth lies inside the 95 % region of the batch results' covariance (chi-square
    of the error, 9 and 4 degrees of freedom): eye-to-hand (100 samples, 1 mm noise) and payload
    (100 samples, 0.02 N and 0.5 mN m, an ATI Mini40's) over ``runs`` random well-excited streams."""
    eye = payload = 0
    for seed in range(seed0, seed0 + runs):
        s = eye_stream(seed, "excited", n=100, noise=1e-3)
        r = calibrate_eye_to_hand(s.p_C, s.X_WH)
        turn = Rotation.from_matrix(r.X_WC[:3, :3].T @ s.X_WC[:3, :3]).as_rotvec()
        d = np.concatenate([turn, s.X_WC[:3, 3] - r.X_WC[:3, 3], s.p_HP - r.p_HP])
        eye += r.covariance is not None and d @ np.linalg.solve(r.covariance, d) <= chi2.ppf(0.95, 9)
        q = payload_stream(seed, "excited", n=100, noise=(0.02, 5e-4))
        r = identify_payload(q.wrench, q.R_WK)
        d = np.concatenate([[r.mass - q.mass], r.p_KCm - q.p_KCm])
        payload += r.covariance is not None and d @ np.linalg.solve(r.covariance, d) <= chi2.ppf(0.95, 4)
    return int(eye), int(payload)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    parser.add_argument("--streams", type=int, default=10_000, help="streams per degenerate kind")
    parser.add_argument("--excited", type=int, default=1_000, help="well-excited and weak streams per kind")
    parser.add_argument("--seed", type=int, default=0, help="first seed")
    parser.add_argument("--coverage", type=int, default=1_000, help="Monte-Carlo runs of the coverage check")
    args = parser.parse_args()
    plan = ([("eye-to-hand", _eye, k, args.streams) for k in EYE_DEGENERATE + EYE_UNITS_AND_FRAMES]
            + [("payload", _payload, k, args.streams) for k in PAYLOAD_DEGENERATE]
            + [(f, one, k, args.excited) for f, one in (("eye-to-hand", _eye), ("payload", _payload))
               for k in NOISY])  # fmt: skip
    missed = False
    print(f"{'formulation':12s} {'kind':17s} {'streams':>7s} {'batch':>6s} {'stream':>6s} {'within':>6s}"
          "  reasons")
    for formulation, one, kind, streams in plan:
        start = time.perf_counter()
        row = count(one, kind, streams, args.seed)
        if kind in NOISY:
            missed = missed or row["within"] < row["batch"]
        else:
            missed = missed or row["batch"] > 0 or row["streaming"] > 0
        reasons = ", ".join(f"{k!r}: {v}" for k, v in row["reasons"].most_common())
        within = str(row["within"]) if kind in NOISY else "-"
        print(f"{formulation:12s} {kind:17s} {streams:7d} {row['batch']:6d} {row['streaming']:6d} "
              f"{within:>6s}  {reasons}   ({time.perf_counter() - start:.0f} s)", flush=True)
    eye, payload = coverage(args.coverage, args.seed)
    low, high = 0.93 * args.coverage, 0.97 * args.coverage
    print(f"coverage of the 95 % regions over {args.coverage} runs: eye-to-hand {eye}, payload {payload} "
          f"(target {low:.0f}-{high:.0f})")
    missed = missed or not (low <= eye <= high and low <= payload <= high)
    print("targets:", "MISSED" if missed else "met (0 converged degenerate or mis-scaled streams, batch and "
          "streaming; every converged well-excited or weak stream within 6 sd of the truth; coverage)")
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
