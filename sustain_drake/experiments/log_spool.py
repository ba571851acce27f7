"""The logs of a run kept on disk while it goes on: a long run's resident memory stays flat.

Drake's ``VectorLogSink`` keeps every sample in its context's ``VectorLog``, whose buffer doubles
when full: a 30-minute run's logs grow by megabytes a minute. ``LogSpool.drain`` moves each log's
samples into a file of a temporary folder and clears the log (its buffer keeps its capacity, so
after the first drain the logs allocate nothing more); ``LogSpool.restore`` puts every sample back,
in order, before the run's outputs are read, so whoever reads a log at the end sees the whole run.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from pydrake.systems.primitives import VectorLogSink


def log_sinks(system) -> list:
    """Every ``VectorLogSink`` in a diagram (nested diagrams included), in a fixed order."""
    sinks = []
    for child in system.GetSystems() if hasattr(system, "GetSystems") else ():
        if isinstance(child, VectorLogSink):
            sinks.append(child)
        else:
            sinks.extend(log_sinks(child))
    return sinks


class LogSpool:
    """Moves the logs of ``diagram``'s sinks to a temporary folder (``drain``) and back
    (``restore``); ``close`` removes the folder. Use as a context manager."""

    def __init__(self, diagram):
        self._sinks = log_sinks(diagram)
        self._folder = tempfile.TemporaryDirectory(prefix="sustain_drake_logs_")
        self._chunks: list[Path] = []

    def __enter__(self) -> LogSpool:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._folder.cleanup()

    def _log(self, sink, root_context):
        return sink.GetMutableLog(sink.GetMyContextFromRoot(root_context))

    def drain(self, root_context) -> None:
        """Every sink's samples so far into one file; the logs are left empty."""
        arrays = {}
        for k, sink in enumerate(self._sinks):
            log = self._log(sink, root_context)
            if log.num_samples():
                arrays[f"t{k}"] = log.sample_times().copy()
                arrays[f"x{k}"] = log.data().copy()
                log.Clear()
        if arrays:
            path = Path(self._folder.name) / f"chunk{len(self._chunks)}.npz"
            np.savez(path, **arrays)
            self._chunks.append(path)

    def restore(self, root_context) -> None:
        """Every sink's log holds all its samples again, the drained ones first, in order."""
        times = {k: [] for k in range(len(self._sinks))}
        data = {k: [] for k in range(len(self._sinks))}
        for path in self._chunks:  # each file read once
            with np.load(path) as chunk:
                for k in times:
                    if f"t{k}" in chunk:
                        times[k].append(chunk[f"t{k}"])
                        data[k].append(chunk[f"x{k}"])
        for k, sink in enumerate(self._sinks):
            log = self._log(sink, root_context)
            if not times[k]:
                continue
            times[k].append(log.sample_times().copy())
            data[k].append(log.data().copy())
            t, x = np.concatenate(times[k]), np.concatenate(data[k], axis=1)
            log.Clear()
            log.Reserve(t.size)
            for i in range(t.size):
                log.AddData(t[i], x[:, i])
        self._chunks = []
