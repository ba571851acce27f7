"""What the end-to-end benches share: run one scenario per seed in parallel processes, and
check a figure against its target."""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor


def run_seeds(run_seed, seeds: list[int], jobs: int, *args) -> list:
    """``[run_seed(*args, seed) ...]`` for each seed, ``jobs`` at a time (each run in its own
    process: a Drake simulation holds one core)."""
    with ProcessPoolExecutor(max_workers=max(1, jobs)) as pool:
        n = len(seeds)
        columns = [[a] * n for a in args]
        return list(pool.map(run_seed, *columns, seeds))


def meets(value, op: str, bound: float) -> bool:
    """Whether ``value`` (None: not measured, so not met) satisfies ``op bound``."""
    if value is None:
        return False
    return {">=": value >= bound, "<=": value <= bound, "==": value == bound}[op]
