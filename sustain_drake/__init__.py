"""sustain_drake: sustainable sensory-motor coordination on Drake's systems framework.

Layers (data flows one way, top to bottom):

- ``sustain_drake.identification``: the paper's equations in pure numpy/scipy (no pydrake).
- ``sustain_drake.systems``: thin Drake ``LeafSystem``s that own ports and state and call the math.
- ``sustain_drake.station``: scenario files -> Diagrams.
- ``sustain_drake.cli``: the ``sustain-drake`` command line.
"""

__version__ = "0.1.0"
