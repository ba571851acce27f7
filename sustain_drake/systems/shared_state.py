"""``Shared``: an immutable value held in a Drake abstract state without deep copies."""

from __future__ import annotations


class Shared:
    """Holds ``value``, which nobody mutates (an update stores a new one), in an abstract state.

    Drake deep-copies a Python abstract state twice per unrestricted update (into its scratch
    state and back) and on every context clone; a ``Shared`` copy is the same holder, so a value
    of many small objects (a candidate bank, a tracker state) costs nothing to copy and contexts
    share it safely."""

    __slots__ = ("value",)

    def __init__(self, value):
        self.value = value

    def __deepcopy__(self, memo):
        return self
