"""Experiments: the paper's §4 experiments as blocks added to the station's diagram.

Each experiment is a module whose settings are a section of the scenario file (the loop's settings
dataclass in ``sustain_drake.loops``), with two functions that ``run.simulate_scenario`` calls:

- ``add_to_diagram(builder, station, scenario, meshcat) -> handle``: adds the experiment's
  systems (perception, identifiers, state machines, evaluation loggers) to ``builder``, wired to
  the ``station`` diagram's exported ports; ``meshcat`` may be None (headless, no replay).
- ``finish(handle, diagram, context, out_dir) -> dict``: after the simulation, computes the
  experiment's metrics (JSON-serialisable), writes its pictures into ``out_dir`` and returns the
  metrics; ``simulate`` writes all experiments' metrics to ``out_dir/metrics.json`` and prints
  them.

An experiment runs when its scenario section says ``enabled: true``.
"""

# Scenario section name -> module implementing the experiment.
EXPERIMENTS = {
    "body_detection": "sustain_drake.experiments.body_detection",
    "hand_eye": "sustain_drake.experiments.hand_eye",
    "kinesthetic": "sustain_drake.experiments.kinesthetic",
}
