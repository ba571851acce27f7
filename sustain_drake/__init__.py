"""sustain_drake: sustainable sensory-motor coordination on Drake's systems framework.

Layers (data flows one way, top to bottom; ``tests/test_layers.py`` checks the imports):

- ``sustain_drake.cli``: the ``sustain-drake`` command line.
- ``sustain_drake.experiments``: the paper's experiments on the simulated world, their metrics.
- ``sustain_drake.station``: scenario files -> the simulated world's Diagram.
- ``sustain_drake.loops``: the identify <-> observe loops wired from the systems, their settings,
  ``make_sustainable_coordination`` for one's own controller.
- ``sustain_drake.systems``: thin Drake ``LeafSystem``s that own ports and state and call the math.
- ``sustain_drake.identification``, ``sustain_drake.perception``: the paper's equations in
  numpy, scipy and OpenCV (no pydrake).
- ``sustain_drake.files``: atomic writes, shared by all.
"""

__version__ = "0.1.0"
