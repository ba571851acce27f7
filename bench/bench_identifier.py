"""Per-sample cost of the sustainable identifier (issue #24: add + solve <= 20 us at N = 16, one core).

Run:  .venv/bin/python bench/bench_identifier.py   (or: make bench)

Medians over repeated blocks; the bare LAPACK 16 x 16 symmetric eigen-solve is timed in the same
run, so the ratio is meaningful on a shared, noisy machine. Rows:

- ``eye_to_hand_add_solve_us``: add one sample and read the solution after every one (each read
  is a full solve: the add makes the cached solution stale);
- ``eye_to_hand_add_lazy_us``: add ``--lazy`` samples, then read once (per sample);
- ``eye_to_hand_solve_cached_us``: read again with no new sample (the cached solution);
- ``eye_to_hand_floor_us``: only the array calls that one add + solve makes (A_t's entries, A^T A
  and its check, the state sum, T, T^T S T, dsyev, T v_N, the 3 x 3 SVD, U V^T), with no Python
  logic around them: what Python + numpy/scipy can reach at best.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # one core, before numpy loads OpenBLAS

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.linalg import lapack  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from results_page import publish  # noqa: E402  (bench/results_page.py)

from sustain_drake.identification import EyeToHandIdentifier, PayloadIdentifier  # noqa: E402
from sustain_drake.identification.eye_to_hand import conditioning_transform, refine  # noqa: E402


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
    parser.add_argument("--lazy", type=int, default=10, help="samples per read in the lazy row")
    parser.add_argument("--json", help="also write the figures to this file")
    parser.add_argument("--results", action="store_true", help="also write the table on docs/results.md")
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

    def eye_add_lazy():
        for _ in range(args.lazy):
            i = counter[0] = (counter[0] + 1) % n
            eye.add(c[i], R[i], p[i])
        eye.solve(refine_estimate=False)

    def pay_add_solve():
        i = counter[0] = (counter[0] + 1) % n
        pay.add(wrench[i], R[i])
        pay.solve()

    # The floor: the same array calls on buffers of its own, nothing else.
    A, state, TtS, T = np.zeros((3, 16)), eye.state, np.empty((16, 16)), np.zeros((16, 16))
    S_floor = state[:256].reshape(16, 16)
    increment = np.zeros(258)
    increment[256:] = 1.0
    AtA = increment[:256].reshape(16, 16)
    A_c = np.lib.stride_tricks.as_strided(A, shape=(3, 3), strides=(17 * 8, 3 * 8))
    A_R, A_p = A[:, 12:15], A[:, 15]
    T_full = conditioning_transform(S_floor)
    T_index = np.flatnonzero(T_full)
    T_values = T_full.ravel()[T_index].tolist()
    sums_index = np.arange(10)

    def eye_floor():
        i = counter[0] = (counter[0] + 1) % n
        A_c[...] = c[i]
        np.negative(R[i], out=A_R)
        np.negative(p[i], out=A_p)
        np.dot(A.T, A, out=AtA)
        AtA.sum()
        state.__iadd__(increment)
        S_floor.take(sums_index).tolist()
        T.put(T_index, T_values)
        C = np.dot(np.dot(T.T, S_floor, out=TtS), T)
        _, V, _ = lapack.dsyev(C.T, overwrite_a=1)
        d = np.dot(T, V[:, 0])
        U, _, Vt, _ = lapack.dgesvd(d[0:9].reshape(3, 3, order="F"))
        np.dot(U, Vt)

    C16 = eye.core.C
    sol = eye.solve(refine_estimate=False)
    assert eye.solve(refine_estimate=False) is sol  # a read with no new sample is the cached one
    eye_add()
    assert eye.solve(refine_estimate=False) is not sol  # an add makes it stale: the rows are honest
    S, w = eye.core.S, eye.core.weight
    T16 = conditioning_transform(S)
    C16_conditioned = T16.T @ (S / w) @ T16
    R0, pWC, pHP = sol.projected.R_WC, sol.projected.p_WC.copy(), sol.projected.p_HP.copy()
    b, k = args.blocks, args.calls
    figures = {
        "lapack_dsyev_16x16_us": median_us(lambda: lapack.dsyev(C16), 1, b, k),
        "lapack_dsyev_16x16_conditioned_us": median_us(lambda: lapack.dsyev(C16_conditioned), 1, b, k),
        "eye_to_hand_add_us": median_us(eye_add, 1, b, k),
        "eye_to_hand_add_solve_us": median_us(eye_add_solve, 1, b, k),
        "eye_to_hand_add_lazy_us": median_us(eye_add_lazy, args.lazy, b, max(k // args.lazy, 5)),
        "eye_to_hand_solve_cached_us": median_us(lambda: eye.solve(refine_estimate=False), 1, b, k),
        "eye_to_hand_floor_us": median_us(eye_floor, 1, b, k),
        "payload_add_solve_us": median_us(pay_add_solve, 1, b, k),
        "eye_to_hand_refinement_us": median_us(lambda: refine(S, w, R0, pWC, pHP), 1, b, max(k // 10, 5)),
    }
    dsyev_us = figures["lapack_dsyev_16x16_us"]
    figures["add_solve_over_dsyev"] = figures["eye_to_hand_add_solve_us"] / dsyev_us
    figures["add_lazy_over_dsyev"] = figures["eye_to_hand_add_lazy_us"] / dsyev_us
    figures["floor_over_dsyev"] = figures["eye_to_hand_floor_us"] / dsyev_us
    width = max(map(len, figures))
    for name, value in figures.items():
        print(f"{name:{width}s}  {value:8.2f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(figures, f, indent=2)
    if args.results:
        publish("bench_identifier", results_table(figures, args.lazy))


# Result-page rows: figure -> what it measures.
ROWS = {
    "lapack_dsyev_16x16_us": "LAPACK `dsyev` 16 x 16 alone (through scipy)",
    "lapack_dsyev_16x16_conditioned_us": "`dsyev` on the conditioned matrix the solve factorises",
    "eye_to_hand_add_us": "eye-to-hand add",
    "eye_to_hand_add_solve_us": "eye-to-hand add + solve after every sample (eigen-solve, SO(3) projection, "
                                "verdict), N = 16",
    "eye_to_hand_add_lazy_us": "eye-to-hand, {lazy} adds then one read, per sample",
    "eye_to_hand_solve_cached_us": "a read with no new sample (the cached solution)",
    "eye_to_hand_floor_us": "the numpy/LAPACK calls of one add + solve alone (no package code around them)",
    "payload_add_solve_us": "payload add + solve, N = 5",
    "eye_to_hand_refinement_us": "eye-to-hand Gauss-Newton refinement from the statistic",
}


def results_table(figures: dict, lazy: int) -> list[str]:
    dsyev = figures["lapack_dsyev_16x16_us"]
    lines = ["| what | median |", "|---|---|"]
    for key, text in ROWS.items():
        ratio = "" if key == "lapack_dsyev_16x16_us" else f" ({figures[key] / dsyev:.2f}x `dsyev`)"
        lines.append(f"| {text.format(lazy=lazy)} | {figures[key]:.1f} us{ratio} |")
    return lines


if __name__ == "__main__":
    main()
