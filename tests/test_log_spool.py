"""A run's logs go to disk while it runs (``experiments.log_spool``) and come back whole: the outputs
are those of a run that kept them in memory, and the logs in memory stay one interval long."""

import json
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, Sine

from sustain_drake.experiments import run
from sustain_drake.experiments.log_spool import LogSpool, log_sinks
from sustain_drake.station import load_scenario

ROOT = Path(__file__).resolve().parents[1]


def _sine_diagram():
    builder = DiagramBuilder()
    sine = builder.AddSystem(Sine(np.array([1.0, 2.0]), np.array([3.0, 5.0]), np.zeros(2)))
    fast = LogVectorOutput(sine.get_output_port(0), builder, 0.01)
    slow = LogVectorOutput(sine.get_output_port(1), builder, 0.05)
    return builder.Build(), (fast, slow)


def test_drained_logs_come_back_whole_and_in_order():
    kept, (kept_fast, kept_slow) = _sine_diagram()
    reference = Simulator(kept)
    reference.AdvanceTo(1.0)
    diagram, (fast, slow) = _sine_diagram()
    assert log_sinks(diagram) == [fast, slow]
    simulator = Simulator(diagram)
    context = simulator.get_context()
    with LogSpool(diagram) as spool:
        for t in (0.23, 0.5, 0.77):
            simulator.AdvanceTo(t)
            spool.drain(context)
            assert fast.FindLog(context).num_samples() == 0  # the samples are on disk now
        simulator.AdvanceTo(1.0)
        spool.restore(context)
    for ours, theirs in ((fast, kept_fast), (slow, kept_slow)):
        a, b = ours.FindLog(context), theirs.FindLog(reference.get_context())
        assert a.num_samples() == b.num_samples() > 10
        assert np.array_equal(a.sample_times(), b.sample_times())
        assert np.array_equal(a.data(), b.data())


def test_a_run_writes_the_same_outputs_with_its_logs_drained(tmp_path, monkeypatch):
    """``simulate_scenario`` drains every ``LOG_SPOOL_INTERVAL``: drained every 0.3 s, 2 s of
    ``inertia_touch`` (the payload experiment's logs and ``log.npz``'s) give the same files."""
    scenario = load_scenario(ROOT / "diagrams" / "inertia_touch.yaml")
    outputs = {}
    for name, interval in (("kept", 1e9), ("drained", 0.3)):
        monkeypatch.setattr(run, "LOG_SPOOL_INTERVAL", interval)
        result = run.simulate_scenario(scenario, tmp_path / name, duration=2.0, replay=False, log_rate=50.0)
        metrics = json.loads(result.metrics.read_text())
        metrics.pop("wall_s")
        with np.load(result.log) as log:
            outputs[name] = (metrics, {k: log[k] for k in log.files})
    (m_kept, log_kept), (m_drained, log_drained) = outputs["kept"], outputs["drained"]
    assert m_kept == m_drained
    assert log_kept.keys() == log_drained.keys() and log_kept["time"].size == 101
    for key, value in log_kept.items():
        assert np.array_equal(value, log_drained[key]), key
