"""Examples a user starts from: whole scripts built from the package's public API only (the
``loops`` diagram, the ``systems``' documented LeafSystems, Drake), each shown on a docs page and
run by a test.

- ``on_your_robot``: the coordination wired to an arm of one's own with its default settings
  (docs/on_your_robot.md).
"""
