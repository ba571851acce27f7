"""Sweeps: many runs of a scenario with some of its keys varied, on Dask ``distributed``.

The layer above the experiments: ``spec`` reads a sweep file into cells (whole scenarios),
``engine`` runs them on a Dask cluster into one results table (Parquet), ``summary`` reports each
target's pass rate per axis value. ``sustain-drake sweep`` and the end-to-end benches use it.
"""

from sustain_drake.sweeps.engine import SweepRunError, open_client, read_table, run_sweep
from sustain_drake.sweeps.spec import Cell, Sweep, SweepError, load_sweep
from sustain_drake.sweeps.summary import every_target_met, write_summary

__all__ = ["Cell", "Sweep", "SweepError", "SweepRunError", "every_target_met", "load_sweep",
           "open_client", "read_table", "run_sweep", "write_summary"]
