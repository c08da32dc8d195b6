"""The figures of a sweep's report, as PNG files (matplotlib, no screen needed).

Each takes series ``(label, xs, ys, (basis, mass))`` and writes one figure:
logarithmic axes with their units, a colour per basis and a marker and line
style per mass kind (so lines stay apart in grey print too), a legend outside
the data, sized and lettered to be read in print.
"""

from __future__ import annotations

import io
from pathlib import Path

from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter, NullFormatter

from ..output import atomic_write

MARKERS = "osD^v<>pPhX*"
LINE_STYLES = ("-", "--", "-.", ":")
SIZE = (7.0, 4.6)
DPI = 150
ERROR_LABEL = "relative error (-)"


def _axes(title: str, xlabel: str, ylabel: str):
    figure = Figure(figsize=SIZE, dpi=DPI)
    axes = figure.add_subplot()
    axes.set_xscale("log")
    axes.set_yscale("log")
    axes.set_title(title, fontsize=11)
    axes.set_xlabel(xlabel, fontsize=10)
    axes.set_ylabel(ylabel, fontsize=10)
    axes.grid(True, which="both", alpha=0.25)
    return figure, axes


def _lines(axes, series) -> None:
    bases = list(dict.fromkeys(group[0] for *_, group in series))
    masses = list(dict.fromkeys(group[1:] for *_, group in series))
    for label, xs, ys, group in series:
        basis, mass = bases.index(group[0]), masses.index(group[1:])
        shown = [(x, y) for x, y in zip(xs, ys) if x > 0 and y > 0]  # log axes: an error of 0 is not drawn
        xs, ys = [x for x, _ in shown], [y for _, y in shown]
        axes.plot(xs, ys, marker=MARKERS[mass % len(MARKERS)], linestyle=LINE_STYLES[mass % len(LINE_STYLES)],
                  markersize=5, linewidth=1.2, label=label, color=f"C{basis % 10}")


def _spacing_ticks(axes, series) -> None:
    """Ticks at the spacings run, written plainly (0.125, not 1.25e-1)."""
    spacings = sorted({x for _, xs, _, _ in series for x in xs})
    if spacings:
        axes.set_xticks(spacings)
        axes.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
        axes.xaxis.set_minor_formatter(NullFormatter())


def _save(figure, axes, path: Path) -> Path:
    if axes.get_legend_handles_labels()[0]:
        axes.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.02, 0.5), frameon=False)
    figure.tight_layout()
    image = io.BytesIO()
    figure.savefig(image, format="png")
    atomic_write(path, image.getvalue())  # a report cut short keeps the figure it had
    return path


def work_precision(series, front, path: Path) -> Path:
    """Error against wall time, one line per method across spacings; ``front`` the
    Pareto front's ``(costs, errors)``, drawn as a staircase."""
    figure, axes = _axes("Work and precision", "wall time of the run (s)", ERROR_LABEL)
    _lines(axes, series)
    shown = [(c, e) for c, e in zip(*front) if c > 0 and e > 0]  # log axes, as the lines
    costs, errors = [c for c, _ in shown], [e for _, e in shown]
    if costs:
        axes.step(costs, errors, where="post", color="black", linestyle="--", linewidth=1.0, label="Pareto front",
                  zorder=0)
    return _save(figure, axes, path)


def convergence(series, path: Path, slopes=(1, 2, 3, 4)) -> Path:
    """Error against spacing, one line per method, with reference slopes ``h^p``."""
    figure, axes = _axes("Convergence with the grid spacing", "grid spacing h (m)", ERROR_LABEL)
    _lines(axes, series)
    spacings = sorted({h for _, xs, _, _ in series for h in xs})
    errors = [e for _, _, ys, _ in series for e in ys if e > 0]
    if len(spacings) >= 2 and errors and min(errors) / 4 > 0:  # guides below the finest error (not a subnormal)
        fine, coarse = spacings[0], spacings[-1]
        low, top = min(errors), max(errors)
        for order in slopes:  # from below the finest error, rising with the slope h^p
            end = min(coarse, fine * (3 * top / (low / 2)) ** (1 / order))
            axes.plot([fine, end], [low / 2, low / 2 * (end / fine) ** order], color="0.45", linestyle=(0, (1, 2)),
                      linewidth=1.0)
            axes.annotate(f"h^{order}", (end, low / 2 * (end / fine) ** order), fontsize=8, color="0.3",
                          textcoords="offset points", xytext=(3, -3))
        axes.set_ylim(low / 4, top * 3)
    _spacing_ticks(axes, series)
    return _save(figure, axes, path)


def time_step(series, path: Path) -> Path:
    """Error against the time step, one line per method and spacing."""
    figure, axes = _axes("Error against the time step", "time step dt (s)", ERROR_LABEL)
    _lines(axes, series)
    return _save(figure, axes, path)


def cost(steps_series, time_series, path: Path) -> Path:
    """Two panels against spacing: the steps of each run (its stable step) and the wall time per step."""
    figure = Figure(figsize=(SIZE[0], SIZE[1] * 1.35), dpi=DPI)
    top, bottom = figure.subplots(2, 1, sharex=True)
    for axes, series, ylabel in ((top, steps_series, "steps of the run (-)"),
                                 (bottom, time_series, "wall time per step (ms)")):
        axes.set_xscale("log")
        axes.set_yscale("log")
        axes.set_ylabel(ylabel, fontsize=10)
        axes.grid(True, which="both", alpha=0.25)
        _lines(axes, series)
    top.set_title("What a run costs", fontsize=11)
    _spacing_ticks(bottom, time_series)
    bottom.set_xlabel("grid spacing h (m)", fontsize=10)
    return _save(figure, top, path)
