"""Drake ``LeafSystem``s: each owns its ports and state (in the context) and calls the math layers.

Import the systems from their modules, e.g. ``from sustain_drake.systems.wrench_sensor import ...``.
"""
