"""Per-sample cost of the sustainable identifier (issue: add + solve <= 30 us at N = 16, one core).

Run:  .venv/bin/python bench/bench_identifier.py   (or: make bench)

Medians over repeated blocks; the bare LAPACK 16 x 16 symmetric eigen-solve is timed in the same
run, so the ratio is meaningful on a shared, noisy machine.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # one core, before numpy loads OpenBLAS

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from scipy.linalg import lapack  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from sustain_drake.identification import EyeToHandIdentifier, PayloadIdentifier  # noqa: E402
from sustain_drake.identification.eye_to_hand import refine  # noqa: E402


def median_us(fn, per_call: int, blocks: int, calls_per_block: int) -> float:
    """Median over ``blocks`` of the mean time per call, microseconds."""
    times = []
    for _ in range(blocks):
        t0 = time.perf_counter_ns()
        for _ in range(calls_per_block):
            fn()
        times.append((time.perf_counter_ns() - t0) / calls_per_block / per_call / 1e3)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--blocks", type=int, default=21)
    parser.add_argument("--calls", type=int, default=500)
    parser.add_argument("--json", help="also write the figures to this file")
    args = parser.parse_args()
    try:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    except (AttributeError, OSError):
        pass
    # Consistent samples with sensor-like noise (1 mm camera, Mini40-like F/T), so the refinement
    # is timed on a realistic problem.
    rng = np.random.default_rng(0)
    n = 1000
    R = Rotation.random(n, random_state=rng).as_matrix()
    p = rng.uniform(-0.3, 0.3, (n, 3)) + [0.4, 0.0, 0.3]
    R_WC = Rotation.random(random_state=rng).as_matrix()
    p_WC, p_HP = np.array([0.5, -0.4, 1.0]), np.array([0.0, 0.02, 0.2])
    c = (np.einsum("nij,j->ni", R, p_HP) + p - p_WC) @ R_WC + rng.normal(0, 1e-3, (n, 3))
    mass, p_KCm = 0.6, np.array([0.01, -0.02, 0.08])
    f = np.einsum("nji,j->ni", R, [0.0, 0.0, mass * 9.81])
    wrench = np.hstack([np.cross(p_KCm, f) + rng.normal(0, 5e-4, (n, 3)), f + rng.normal(0, 0.02, (n, 3))])

    eye = EyeToHandIdentifier()
    for i in range(n):
        eye.add(c[i], R[i], p[i])
    pay = PayloadIdentifier()
    for i in range(n):
        pay.add(wrench[i], R[i])
    counter = [0]

    def eye_add_solve():
        i = counter[0] = (counter[0] + 1) % n
        eye.add(c[i], R[i], p[i])
        eye.solve(refine_estimate=False)

    def eye_add():
        i = counter[0] = (counter[0] + 1) % n
        eye.add(c[i], R[i], p[i])

    def pay_add_solve():
        i = counter[0] = (counter[0] + 1) % n
        pay.add(wrench[i], R[i])
        pay.solve()

    C16 = eye.core.C
    sol = eye.solve(refine_estimate=False)
    S, w = eye.core.S, eye.core.weight
    R0, pWC, pHP = sol.projected.R_WC, sol.projected.p_WC.copy(), sol.projected.p_HP.copy()
    b, k = args.blocks, args.calls
    figures = {
        "lapack_dsyev_16x16_us": median_us(lambda: lapack.dsyev(C16), 1, b, k),
        "eye_to_hand_add_us": median_us(eye_add, 1, b, k),
        "eye_to_hand_add_solve_us": median_us(eye_add_solve, 1, b, k),
        "payload_add_solve_us": median_us(pay_add_solve, 1, b, k),
        "eye_to_hand_refinement_us": median_us(lambda: refine(S, w, R0, pWC, pHP), 1, b, max(k // 10, 5)),
    }
    figures["add_solve_over_dsyev"] = figures["eye_to_hand_add_solve_us"] / figures["lapack_dsyev_16x16_us"]
    width = max(map(len, figures))
    for name, value in figures.items():
        print(f"{name:{width}s}  {value:8.2f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(figures, f, indent=2)


if __name__ == "__main__":
    main()
