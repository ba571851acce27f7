"""Meshcat for the station: bound to this machine only, and recorded for a self-contained replay."""

from __future__ import annotations

from pydrake.geometry import Meshcat, MeshcatParams


def make_local_meshcat() -> Meshcat:
    """A Meshcat server that listens on the loopback interface only.

    Drake's default (``host="*"``) listens on all interfaces, which would show the scene to the
    whole network; ``localhost`` keeps it on this machine (use an SSH tunnel to view it from
    elsewhere)."""
    return Meshcat(MeshcatParams(host="localhost", show_stats_plot=False))
