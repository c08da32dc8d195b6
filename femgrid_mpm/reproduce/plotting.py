"""Matplotlib helpers shared by the reproduction scripts (Agg backend, no screen).

Every figure is drawn inside :func:`styled` (type sizes that stay legible when
a figure is printed at column width) and written by :func:`save`.  Energy
curves carry the column names of ``energy.csv`` as their labels, so that a
figure, a table and the CSV name a quantity the same way.
"""

from __future__ import annotations

import functools

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

#: type sizes for print: a figure 7 in wide printed at 3.5 in keeps 7-pt labels
STYLE = {
    "font.size": 11,
    "axes.titlesize": 11,
    "axes.labelsize": 11,
    "xtick.labelsize": 10,
    "ytick.labelsize": 10,
    "legend.fontsize": 9,
    "lines.linewidth": 1.5,
    "axes.grid": True,
    "grid.alpha": 0.3,
}
DPI = 150

#: energy.csv's columns drawn in the energy figures (Figs. 4-7, 14-16): column, colour, line style
ENERGY_COLUMNS = (
    ("kinetic", "tab:blue", "-"),
    ("kinetic_grid", "tab:orange", "--"),
    ("strain", "tab:green", "-"),
    ("total", "tab:red", "-"),
)
#: the error columns, two orders smaller, drawn on a panel of their own
ERROR_COLUMNS = (
    ("interpolation_error", "tab:blue", ":"),
    ("algorithm_error", "tab:orange", ":"),
    ("total_error", "tab:green", "-."),
)
ENERGY_UNIT = "J/m"  # per metre of thickness: the runs are 2D
#: how a run that stopped before its end is marked where it stopped
STOP_MARKER = dict(marker="X", markersize=10, markeredgecolor="black", markeredgewidth=0.8, linestyle="none", zorder=5)


def styled(draw):
    """Run a drawing function under :data:`STYLE` without changing matplotlib's global settings."""

    @functools.wraps(draw)
    def inside(*args, **kwargs):
        with plt.rc_context(STYLE):
            return draw(*args, **kwargs)

    return inside


def save(figure, path) -> None:
    """Write ``figure`` to ``path`` (PNG), legends outside the axes included, and close it."""
    figure.savefig(path, dpi=DPI, bbox_inches="tight")
    plt.close(figure)


def legend_outside(axes, **kwargs) -> None:
    """The legend right of the axes, where it hides no curve."""
    axes.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, **kwargs)


def stop_reason(message: str, time: float) -> str:
    """A stop in a few words: ``step 44 (t = 0.22 s): the energy ran away: ...`` at 0.22 gives
    ``the energy ran away at t = 0.22 s``."""
    parts = message.split(": ")
    return f"{parts[1] if len(parts) > 1 else message} at t = {time:.2f} s"


def mark_stop(axes, time: float, value: float, color, label: str | None = None) -> None:
    """A cross where a stopped run's series ends."""
    axes.plot([time], [value], color=color, label=label, **STOP_MARKER)


#: a stopped run's records are drawn while its total energy stays within this fraction above
#: its initial energy plus the work put in: the runs that complete rise by 4.1% at most
ENERGY_CREATED = 0.10


def valid_records(energy: dict) -> int:
    """How many leading records of a stopped run to draw: those before its total energy first
    exceeds ``(1 + ENERGY_CREATED) (initial + work put in)``, the records before the run
    created energy (the runaway guard's bound, with 10% in place of 10x)."""
    total = np.asarray(energy["total"])
    bound = (1 + ENERGY_CREATED) * (total[0] + np.maximum(np.asarray(energy["external_work"]), 0.0))
    created = np.flatnonzero(total > bound)
    return int(created[0]) if created.size else len(total)


@styled
def energy_figure(energy: dict, title: str, path, stopped: str | None = None) -> None:
    """One of the paper's energy-measure figures, written to ``path`` (PNG).

    The paper draws energies and errors on one axis; the errors are two
    orders smaller, so they get a second panel of their own here.  A run that
    stopped (``stopped`` is its reason) gets a cross on each curve where it
    stopped and the reason in the title, and a line where it began to create
    energy (:func:`valid_records`).
    """
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True, height_ratios=(3, 2))
    time = energy["time"]
    for axes, columns in ((top, ENERGY_COLUMNS), (bottom, ERROR_COLUMNS)):
        for key, color, style in columns:
            axes.plot(time, energy[key], style, color=color, label=key)
            if stopped is not None:
                mark_stop(axes, time[-1], energy[key][-1], color)
        if stopped is not None:
            axes.plot([], [], color="0.3", label="last record before the stop", **STOP_MARKER)
            valid = valid_records(energy)
            if valid < len(time):
                axes.axvline(time[valid], color="0.4", linestyle="--", linewidth=1,
                             label=f"energy created from t = {time[valid]:.2f} s")
        legend_outside(axes)
    top.set_ylabel(f"energy ({ENERGY_UNIT})")
    bottom.set_ylabel(f"error ({ENERGY_UNIT})")
    bottom.set_xlabel("time (s)")
    top.set_title(title if stopped is None else f"{title}\n(stopped: {stopped})")
    figure.tight_layout()
    save(figure, path)


@styled
def energy_overlay_figure(pairs: dict, title: str, path) -> None:
    """Lumped against consistent mass, one row per basis, written to ``path`` (PNG).

    ``pairs`` maps a row title to ``(lumped, consistent)`` energy records.  Left:
    ``strain`` and ``total`` (the period and the balance); right:
    ``interpolation_error`` and ``total_error`` (what the mass matrix changes).
    Lumped is drawn solid, consistent dashed, one colour per column.
    """
    figure, axes = plt.subplots(len(pairs), 2, figsize=(12, 2.6 * len(pairs) + 0.6), sharex=True, squeeze=False)
    panels = ((("strain", "tab:green"), ("total", "tab:red")),
              (("interpolation_error", "tab:blue"), ("total_error", "tab:purple")))
    for row, (name, (lumped, consistent)) in enumerate(pairs.items()):
        for column, columns in enumerate(panels):
            ax = axes[row, column]
            for key, color in columns:
                ax.plot(lumped["time"], lumped[key], "-", color=color, label=f"{key}, lumped")
                ax.plot(consistent["time"], consistent[key], "--", color=color, label=f"{key}, consistent")
            ax.set_title(name)
            ax.set_ylabel(("energy" if column == 0 else "error") + f" ({ENERGY_UNIT})")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    handles = [h for ax in axes[0] for h in ax.get_legend_handles_labels()[0]]
    figure.suptitle(title)
    figure.tight_layout(rect=(0, 0.07, 1, 1))
    # one legend for every panel, under them, where it hides nothing
    figure.legend(handles=handles, loc="lower center", ncol=4, bbox_to_anchor=(0.5, 0.0))
    save(figure, path)


def shared_limits(*arrays: np.ndarray) -> tuple[float, float]:
    """The smallest and largest finite value over several arrays (one colour scale for all)."""
    values = np.concatenate([np.ravel(a)[np.isfinite(np.ravel(a))] for a in arrays])
    return float(values.min()), float(values.max())


def markdown_table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"
