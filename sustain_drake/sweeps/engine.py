"""Running a sweep's cells on Dask ``distributed`` into one results table.

Each cell is one ``experiments.run.simulate_scenario`` run on a worker. The results table
(``results.parquet`` in the output folder) has a row per cell: its axes' values (``axis.<path>``),
the whole scenario text, every figure of its ``metrics.json`` (``metric.<dotted key>``; lists as
JSON text), each target's verdict and deciding value (``target.<experiment>.<name>.met`` and
``.worst``, from ``experiments.targets``), wall time, worker host, the commit, and the error of a
cell that failed (a failed cell is a row, never the end of the sweep). The table is rewritten
atomically after every cell, so an interrupted sweep keeps every finished cell and a re-run
skips them (cells are named by what they run: ``spec.Cell.id``).

Workers get plain data (the scenario's text), so a cell runs the same on a local cluster or a
remote one. Each cell's outputs (``log.npz``, ``metrics.json``, plots, ``scenario.yaml``) go to
``cells/<id>/`` under the output folder, as the worker sees that path (a shared file system
brings them back; the table always comes back through Dask).
"""

from __future__ import annotations

import io
import json
import logging
import math
import os
import socket
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm import tqdm

from sustain_drake.experiments.targets import check_targets
from sustain_drake.files import OutputPathError, prepare_folder, write_atomically
from sustain_drake.provenance import source_commit
from sustain_drake.station.scenario import one_line
from sustain_drake.sweeps.spec import Cell, Sweep

TABLE = "results.parquet"
CELLS = "cells"
# A worker is one process with one thread, and each renders on one llvmpipe thread, so a worker
# holds one core (Dask already limits OpenMP and BLAS threads in its workers).
WORKER_ENV = {"LP_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


class SweepRunError(RuntimeError):
    """The sweep cannot be run (no scheduler, an output folder that cannot be written); one line."""


@dataclass(frozen=True)
class CellJob:
    """What a worker needs for one cell: plain data, picklable to any machine."""
    cell_id: str
    label: str
    scenario_text: str
    duration: float
    out_dir: str


def run_cell(job: CellJob) -> dict:
    """Runs one cell (on a worker). Returns its metrics, wall time and host, or its error as one
    line (the traceback goes to ``error.txt`` in the cell's folder); never raises."""
    # Imported here: the client process need not build a Drake diagram to submit cells.
    from sustain_drake.experiments.run import simulate_scenario
    from sustain_drake.station.scenario_files import load_scenario_string

    start = time.perf_counter()
    out = Path(job.out_dir)
    result = {"host": socket.gethostname(), "metrics": {}, "error": None}
    try:
        scenario = load_scenario_string(job.scenario_text, job.label)
        run = simulate_scenario(scenario, out, label=job.label, duration=job.duration, replay=False)
        result["sim_wall_s"] = run.wall
        if run.metrics is not None:
            result["metrics"] = json.loads(run.metrics.read_text(encoding="utf-8"))
    except Exception as e:  # a failed cell is a row of the table
        result["error"] = f"{type(e).__name__}: {one_line(e)}"
        try:
            write_atomically(out / "error.txt", traceback.format_exc())
        except OSError:
            pass
    result["wall_s"] = time.perf_counter() - start
    return result


def open_client(workers: int | None = None, scheduler: str | None = None):
    """A Dask client (use it in a ``with``): on the scheduler at ``scheduler`` (an address such as
    tcp://host:8786), or on a new local cluster of ``workers`` single-threaded processes (default:
    one per core) that listens on this machine only."""
    import dask
    from distributed import Client

    if scheduler:
        try:
            return Client(scheduler)  # waits distributed.comm.timeouts.connect (Dask's config)
        except (OSError, TimeoutError, ValueError) as e:
            raise SweepRunError(f"no Dask scheduler at {scheduler}: {one_line(e)}") from None
    n = workers or len(os.sched_getaffinity(0))
    if n < 1:
        raise SweepRunError(f"workers must be >= 1, got {workers}")
    # A cell that kills its worker is a failed cell, not retried on another worker. The client
    # owns the cluster it starts: closing the client stops the workers.
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        return Client(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address="127.0.0.1:0", env=WORKER_ENV, silence_logs=logging.CRITICAL)


def run_sweep(sweep: Sweep, out: str | Path, client, *, retry_failed: bool = False,
              progress: bool = True, on_row: Callable[[dict], None] | None = None) -> pd.DataFrame:
    """Runs the cells of ``sweep`` not yet in ``out/results.parquet`` (failed ones too with
    ``retry_failed``) on ``client`` and returns the table of this sweep's cells. The table is
    rewritten after each cell; rows of cells that are not in ``sweep`` are kept."""
    from distributed import as_completed

    out = Path(out)
    try:
        prepare_folder(out / CELLS, "the sweep's output folder")
    except OutputPathError as e:
        raise SweepRunError(str(e)) from None
    table = read_table(out)
    done = set() if table.empty else set(
        table.loc[table["error"].isna() | (not retry_failed), "cell_id"])
    pending = [cell for cell in sweep.cells if cell.id not in done]
    commit = source_commit()
    futures = {}
    for cell in pending:
        folder = out / CELLS / cell.id
        write_atomically(folder / "scenario.yaml", cell.scenario_text)
        job = CellJob(cell.id, f"{sweep.path.name}:{cell.index}", cell.scenario_text, cell.duration,
                      str(folder.resolve()))
        futures[client.submit(run_cell, job, key=f"cell-{cell.id}", pure=False)] = cell
    rows = {} if table.empty else {r["cell_id"]: r for r in table.to_dict("records")}
    # The bar counts every cell of the sweep; those already in the table start it.
    bar = tqdm(total=len(sweep.cells), initial=len(sweep.cells) - len(pending), unit="cell",
               disable=not progress, smoothing=0.0, desc=sweep.path.name)
    try:
        for future in as_completed(futures):
            cell = futures.pop(future)
            try:
                result = future.result()
            except Exception as e:  # the worker died (KilledWorker) or the cluster went away
                result = {"metrics": {}, "error": f"{type(e).__name__}: {one_line(e)}",
                          "wall_s": math.nan, "host": None}
            row = cell_row(sweep, cell, result, commit)
            rows[cell.id] = row
            write_table(out, list(rows.values()))
            if row["error"] is not None:
                bar.write(f"cell {cell.index} failed: {row['error']}")
            if on_row is not None:
                on_row(row)
            bar.update(1)
    finally:
        bar.close()
        for future in futures:
            future.cancel()
    ids = {cell.id for cell in sweep.cells}
    return _frame([row for cell_id, row in rows.items() if cell_id in ids])


def cell_row(sweep: Sweep, cell: Cell, result: dict, commit: str) -> dict:
    """One row of the results table (see the module docstring)."""
    metrics = result.get("metrics") or {}
    row = {"cell": cell.index, "cell_id": cell.id, "sweep": str(sweep.path), "error": result.get("error"),
           **{f"axis.{axis}": value for axis, value in cell.overrides},
           "duration_s": cell.duration, "wall_s": result.get("wall_s"), "host": result.get("host"),
           "commit": commit, "finished": time.strftime("%Y-%m-%dT%H:%M:%S"),
           "scenario": cell.scenario_text, "metrics_json": json.dumps(metrics, allow_nan=True)}
    row.update({f"metric.{k}": v for k, v in flatten(metrics).items()})
    if row["error"] is None:
        for name, verdict in check_targets(metrics).items():
            row[f"target.{name}.met"] = verdict["met"]
            row[f"target.{name}.worst"] = verdict["worst"]
    return row


def flatten(metrics: dict, prefix: str = "") -> dict:
    """Nested mappings to dotted keys; lists and other containers as JSON text."""
    flat = {}
    for key, value in metrics.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten(value, name + "."))
        elif isinstance(value, list | tuple):
            flat[name] = json.dumps(value)
        else:
            flat[name] = value
    return flat


def read_table(out: str | Path) -> pd.DataFrame:
    """The results table in ``out`` (empty if there is none yet)."""
    path = Path(out) / TABLE
    if not path.exists():
        return pd.DataFrame()
    try:
        return pd.read_parquet(path)
    except Exception as e:  # pyarrow raises its own errors on a damaged file
        raise SweepRunError(f"{path} is not a readable results table ({one_line(e)}): move it "
                            "away to start again") from None


def write_table(out: Path, rows: list[dict]) -> None:
    buffer = io.BytesIO()
    _frame(rows).to_parquet(buffer, index=False)
    write_atomically(out / TABLE, buffer.getvalue())


def _frame(rows: list[dict]) -> pd.DataFrame:
    """Rows to a table Parquet can store: a column of mixed kinds (numbers and text) becomes text."""
    frame = pd.DataFrame(rows)
    if frame.empty:
        return frame
    frame = frame.sort_values("cell", kind="stable").reset_index(drop=True)
    for column in frame.columns:
        values = [v for v in frame[column] if not _missing(v)]
        kinds = {_kind(v) for v in values}
        if kinds in ({"int", "float"}, {"float"}):
            frame[column] = pd.to_numeric(frame[column], errors="coerce").astype(float)
        elif kinds == {"int"}:
            frame[column] = frame[column].astype("Int64")
        elif len(kinds) > 1:
            frame[column] = [None if _missing(v) else
                             (v if isinstance(v, str) else json.dumps(v)) for v in frame[column]]
        elif kinds == {"bool"}:
            frame[column] = frame[column].astype("boolean")
    return frame


def _kind(value) -> str:
    if isinstance(value, bool | np.bool_):
        return "bool"
    if isinstance(value, int | np.integer):
        return "int"
    if isinstance(value, float | np.floating):
        return "float"
    return type(value).__name__


def _missing(value) -> bool:
    """None, NaN or pandas' NA (a table read back has the last two)."""
    return value is None or (not isinstance(value, str | list | dict) and bool(pd.isna(value)))
