"""A sweep's summary: per axis value, the pass rate of each target and the spread of its figure.

Writes ``summary.md`` (tables) and ``summary_<axis>.png`` (one panel per target: each cell's
deciding value against the axis's values, the bound dashed) into the sweep's output folder.
"""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np
import pandas as pd

from sustain_drake.experiments.targets import TARGETS
from sustain_drake.files import write_atomically
from sustain_drake.sweeps.spec import Sweep

EVERY = "every target"


def target_names(table: pd.DataFrame) -> list[str]:
    """The ``<experiment>.<name>`` targets checked in the table, in the order of ``TARGETS``."""
    return [f"{e}.{t.name}" for e, targets in TARGETS.items() for t in targets
            if f"target.{e}.{t.name}.met" in table.columns]


def every_target_met(table: pd.DataFrame) -> pd.Series:
    """Per row: the cell ran and met each of its targets (a cell with none checked: False)."""
    names = target_names(table)
    if not names:
        return pd.Series(False, index=table.index)
    met = table[[f"target.{n}.met" for n in names]]
    return table["error"].isna() & met.notna().any(axis=1) & met.fillna(True).astype(bool).all(axis=1)


def summary_text(table: pd.DataFrame, sweep: Sweep) -> str:
    """The markdown summary of this sweep's rows of the results table."""
    if table.empty:
        return f"# Sweep {sweep.path.name}\n\nNo cell has finished yet.\n"
    names = target_names(table)
    failed = int(table["error"].notna().sum())
    lines = [f"# Sweep {sweep.path.name}", "",
             f"{len(table)} of {len(sweep.cells)} cells in the table, {failed} failed "
             f"(`error` column); base scenario `{sweep.base.name}`"
             + (f" ({sweep.scenario_name})" if sweep.scenario_name else "")
             + f"; commit(s) {', '.join(sorted(set(table['commit'].dropna())))}.",
             ""]
    lines += _rate_table(table, names, None)
    for axis in sweep.axes:
        lines += ["", f"## {axis}", ""] + _rate_table(table, names, f"axis.{axis}")
    if failed:
        lines += ["", "## Failed cells", "", "| cell | error |", "|---|---|"]
        for _, row in table[table["error"].notna()].iterrows():
            lines.append(f"| {row['cell']} | {_cell_text(row['error'])} |")
    return "\n".join(lines) + "\n"


def _rate_table(table: pd.DataFrame, names: list[str], column: str | None) -> list[str]:
    """Rows: all cells (``column`` None) or each value of an axis. Columns: cells, failed, every
    target met, then per target ``met k/n`` and the median and worst deciding value."""
    head = ["value" if column else "cells", "n", "failed", EVERY] + names
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    groups = [("all", table)] if column is None else _groups(table, column)
    every = every_target_met(table)
    for value, rows in groups:
        cells = [_cell_text(value), str(len(rows)), str(int(rows["error"].notna().sum())),
                 f"{int(every[rows.index].sum())}/{len(rows)}"]
        for name in names:
            met = rows[f"target.{name}.met"].dropna()
            worst = rows[f"target.{name}.worst"].dropna().astype(float)
            spread = "" if worst.empty else f" ({worst.median():.3g}; {_decider(name)(worst):.3g})"
            cells.append(f"{int(met.astype(bool).sum())}/{len(met)}{spread}" if len(met) else "-")
        out.append("| " + " | ".join(cells) + " |")
    if names:
        out += ["", "Per target: cells met / cells checked (median; worst of the deciding value)."]
    return out


def _groups(table: pd.DataFrame, column: str) -> list[tuple[str, pd.DataFrame]]:
    values = table[column].astype(str)
    return [(value, table[values == value]) for value in dict.fromkeys(values)]


def _target(name: str):
    experiment, target = name.split(".", 1)
    return next(t for t in TARGETS[experiment] if t.name == target)


def _decider(name: str):
    """How a column of deciding values is summed up as its worst (``Target.worst`` across cells)."""
    target = _target(name)
    if target.op == "<=":
        return np.max
    if target.op == ">=":
        return np.min
    return lambda v: v.iloc[int(np.argmax(np.abs(v - target.bound)))]


def _cell_text(value) -> str:
    return str(value).replace("|", "\\|").replace("\n", " ")


def plot_axis(table: pd.DataFrame, axis: str) -> bytes | None:
    """PNG: one panel per target, each cell's deciding value at its axis value, the bound dashed."""
    names = [n for n in target_names(table) if table[f"target.{n}.worst"].notna().any()]
    if not names:
        return None
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = _groups(table, f"axis.{axis}")
    columns = min(3, len(names))
    rows = -(-len(names) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(4.2 * columns, 3.0 * rows), squeeze=False)
    for ax, name in zip(axes.flat, names, strict=False):
        for i, (_, cells) in enumerate(groups):
            values = cells[f"target.{name}.worst"].dropna().astype(float).to_numpy()
            met = cells.loc[cells[f"target.{name}.worst"].notna(), f"target.{name}.met"].astype(bool)
            jitter = np.linspace(-0.15, 0.15, len(values)) if len(values) > 1 else np.zeros(1)
            ax.scatter(i + jitter[:len(values)], values, s=14,
                       c=np.where(met.to_numpy(), "tab:green", "tab:red"))
        ax.axhline(_target(name).bound, color="k", linestyle="--", linewidth=0.8)
        ax.set_title(name, fontsize=9)
        ax.set_xticks(range(len(groups)))
        ax.set_xticklabels([_short(v) for v, _ in groups], rotation=30, ha="right", fontsize=7)
    for ax in axes.flat[len(names):]:
        ax.set_visible(False)
    fig.suptitle(f"{axis} (green: met, red: not met; dashed: the bound)", fontsize=10)
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90)
    plt.close(fig)
    return buffer.getvalue()


def _short(text: str, n: int = 24) -> str:
    return text if len(text) <= n else text[: n - 1] + "…"


def write_summary(table: pd.DataFrame, sweep: Sweep, out: str | Path) -> Path:
    """Writes ``summary.md`` and a PNG per axis into ``out``; returns the markdown's path."""
    out = Path(out)
    for axis in sweep.axes:
        png = plot_axis(table, axis) if not table.empty else None
        if png is not None:
            write_atomically(out / f"summary_{_file_name(axis)}.png", png)
    path = out / "summary.md"
    write_atomically(path, summary_text(table, sweep))
    return path


def _file_name(axis: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]", "_", axis)
