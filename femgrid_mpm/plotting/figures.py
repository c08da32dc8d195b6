"""The pictures of a run: the points coloured by a field, the energies against time, the
series as an animation.  Each figure has a fixed size (:data:`SIZE`, :data:`DPI`) and one
colour scale for all the frames of an animation, so that frames and runs compare."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..output.files import atomic_path
from .run_directory import FIELDS, Frame, RunDirectory

#: figure size (inches) and resolution: 800 x 600 pixels
SIZE, DPI = (8.0, 6.0), 100
#: the columns of energy.csv drawn as energies (J per unit thickness), and as errors of the balance
ENERGIES = ("kinetic", "kinetic_grid", "strain", "total", "external_work")
ERRORS = ("interpolation_error", "algorithm_error", "total_error", "reference_error")
#: lattice lines are drawn up to this many per direction (beyond, the outline only)
MAX_LATTICE_LINES = 120


def atomic_file(path: Path):
    """:func:`~femgrid_mpm.output.files.atomic_path` keeping ``path``'s suffix (the image
    writers choose the format by it)."""
    return atomic_path(path, keep_suffix=True)


def _figure():
    from matplotlib.figure import Figure

    return Figure(figsize=SIZE, dpi=DPI, layout="constrained")


def save(figure, path: Path) -> None:
    """``figure`` as a PNG at ``path`` (atomically), exactly :data:`SIZE` x :data:`DPI` pixels."""
    with atomic_file(path) as temporary:
        figure.savefig(temporary, format="png", dpi=DPI)


def _label(field: str) -> str:
    return f"{field} ({FIELDS[field]})"


def _body_count(values: np.ndarray, most: int) -> int:
    """The bodies numbered in ``values``: the largest finite number + 1, at most ``most`` (every
    body has a point).  A damaged file's 2e9 sized a colour map of as many colours (a hang), its
    NaN or infinity failed with a traceback; the norm clips such numbers to the ends."""
    finite = values[np.isfinite(values)]
    top = float(finite.max()) if len(finite) else 0.0
    return int(min(max(top, 0.0), max(most - 1, 0))) + 1


def _scale(field: str, values: np.ndarray, bodies: int | None = None):
    """Colour map and range: diverging and centred on zero for a stress that changes sign,
    one of tab10's colours a body (the colour bar a band each; ``bodies``, the count, else
    :func:`_body_count` of ``values``), viridis otherwise; a constant field gets a range
    around its value."""
    low, high = (float(np.min(values)), float(np.max(values))) if len(values) else (0.0, 1.0)
    if field == "body":
        from matplotlib import colormaps
        from matplotlib.colors import ListedColormap

        # tab10 itself spread over the bodies' range drew ten bands for two bodies
        bodies = bodies or _body_count(values, len(values))
        return ListedColormap([colormaps["tab10"](body % 10) for body in range(bodies)]), -0.5, bodies - 0.5
    if field.startswith("stress") and low < 0 < high:
        bound = max(-low, high)
        return "RdBu_r", -bound, bound
    if not high > low:
        pad = abs(low) * 1e-3 or 1.0
        return "viridis", low - pad, high + pad
    return "viridis", low, high


def _outline(axes, run: RunDirectory) -> None:
    """The grid's domain, and its lattice lines when there are not too many."""
    if run.box is None:
        return
    lower, upper, spacing = run.box
    counts = np.rint((upper - lower) / spacing).astype(int)
    if max(counts) <= MAX_LATTICE_LINES:
        for x in lower[0] + spacing * np.arange(1, counts[0]):
            axes.plot([x, x], [lower[1], upper[1]], color="0.85", lw=0.5, zorder=0)
        for y in lower[1] + spacing * np.arange(1, counts[1]):
            axes.plot([lower[0], upper[0]], [y, y], color="0.85", lw=0.5, zorder=0)
    corners = np.array([lower, [upper[0], lower[1]], upper, [lower[0], upper[1]], lower])
    axes.plot(corners[:, 0], corners[:, 1], color="0.3", lw=1.0, zorder=1)


def _limits(run: RunDirectory, frames_x: list[np.ndarray]) -> tuple[tuple[float, float], tuple[float, float]]:
    """The axes' extent: the grid's domain (or the points') with a small margin."""
    if run.box is not None:
        lower, upper = run.box[0], run.box[1]
    else:
        stacked = np.concatenate(frames_x)
        lower, upper = stacked.min(axis=0), stacked.max(axis=0)
    margin = 0.03 * float(np.max(upper - lower) or 1.0)
    return (lower[0] - margin, upper[0] + margin), (lower[1] - margin, upper[1] + margin)


def _marker_area(figure, axes, x0: np.ndarray, spacing: float | None) -> float:
    """Scatter marker area (points^2) of a disc as wide as 0.9 x the points' initial spacing
    (the median distance to the nearest point), on the axes as drawn."""
    if len(x0) > 1:
        from scipy.spatial import cKDTree

        distances, _ = cKDTree(x0).query(x0, k=2)
        gap = float(np.median(distances[:, 1]))
    else:
        gap = 0.5 * (spacing or 1.0)
    figure.canvas.draw()  # the axes' box is known once laid out
    box = axes.get_window_extent()
    width = np.diff(axes.get_xlim())[0]
    points_per_metre = box.width / width * 72.0 / figure.dpi
    return max(0.5, (0.9 * gap * points_per_metre) ** 2)


def _title(run: RunDirectory) -> str:
    name = run.title or run.path.resolve().name
    status = run.summary.get("status")
    return f"{name} ({status})" if status in ("stopped", "interrupted", "running") else name


def _when(run: RunDirectory, frame: Frame, index: int) -> str:
    count = len(run.records)
    if not run.series:
        return f"final state, t = {frame.time:.6g} s"
    return f"t = {frame.time:.6g} s (record {index} of 0-{count - 1})"


class PointsPicture:
    """The points of a run coloured by ``field`` on one colour scale, with the grid's outline;
    :meth:`show` draws one frame, and again for the next (an animation's)."""

    def __init__(self, run: RunDirectory, field: str, values: np.ndarray, frames_x: list[np.ndarray], x0: np.ndarray):
        from matplotlib.colors import Normalize

        self.run, self.field = run, field
        self.figure = figure = _figure()
        self.axes = axes = figure.add_subplot()
        axes.set_aspect("equal")
        axes.set_xlabel("x (m)")
        axes.set_ylabel("y (m)")
        _outline(axes, run)
        xlim, ylim = _limits(run, frames_x)
        axes.set_xlim(*xlim)
        axes.set_ylim(*ylim)
        # the scene's bodies, else those of the numbers (``values`` may be an animation's extremes)
        bodies = len(run.bodies) or _body_count(values, len(x0)) if field == "body" else None
        colours, low, high = _scale(field, values, bodies)
        self.points = axes.scatter(x0[:, 0], x0[:, 1], c=np.zeros(len(x0)), cmap=colours,
                                   norm=Normalize(low, high), s=1.0, linewidths=0, zorder=2)
        # a wide domain takes its colour bar below, where it is as wide as the domain
        wide = np.diff(xlim)[0] > 1.6 * np.diff(ylim)[0]
        bar = figure.colorbar(self.points, ax=axes, shrink=0.85, location="bottom" if wide else "right")
        bar.set_label(_label(field))
        if field == "body" and run.bodies:
            bar.set_ticks(range(len(run.bodies)), labels=run.bodies)
        self.points.set_sizes([_marker_area(figure, axes, x0, run.box[2] if run.box else None)])

    def show(self, frame: Frame, index: int) -> None:
        self.points.set_offsets(frame.x)
        self.points.set_array(frame.fields[self.field])
        self.axes.set_title(f"{_title(self.run)}: {self.field}, {_when(self.run, frame, index)}", fontsize=10)


def points_figure(run: RunDirectory, field: str, index: int):
    """The points at record ``index`` coloured by ``field``."""
    frame = run.frame(index)
    picture = PointsPicture(run, field, frame.fields[field], [frame.x], frame.x0)
    picture.show(frame, index)
    return picture.figure


def energy_figure(run: RunDirectory, table: dict[str, np.ndarray]):
    """The energies of ``energy.csv`` against time and, below, the errors of the balance,
    named as its columns; a run that stopped is marked where it stopped."""
    figure = _figure()
    top, bottom = figure.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    time = table["time"]
    for axes, names, label in ((top, ENERGIES, "energy (J per unit thickness)"), (bottom, ERRORS, "error (J per unit thickness)")):
        for name in names:
            if name in table:
                axes.plot(time, table[name], label=name, marker="." if len(time) < 40 else None)
        axes.set_ylabel(label)
        axes.grid(True, color="0.9")
        axes.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=False)
    stop = run.summary.get("stop")
    if (run.summary.get("status") == "stopped" and isinstance(stop, dict) and isinstance(stop.get("time"), (int, float))
            and abs(stop["time"]) < 1e300):  # a number the axis can take (an edited 10**400 overflows)
        for axes in (top, bottom):
            axes.axvline(stop["time"], color="crimson", ls="--", lw=1)
        top.annotate(f"stopped: {stop.get('reason', '')}", (stop["time"], 1.0), xycoords=("data", "axes fraction"),
                     ha="right", va="top", color="crimson", fontsize=9)
    bottom.set_xlabel("time (s)")
    top.set_title(f"{_title(run)}: energies ({len(time)} records)", fontsize=10)
    return figure


def series_picture(run: RunDirectory, field: str) -> PointsPicture:
    """The picture of an animation of the particle series: every record is read (and
    checked) to find the extent and one colour scale for ``field`` over all of them."""
    low, high, extents, first = np.inf, -np.inf, [], None
    for index in range(len(run.records)):
        frame = run.frame(index)
        values = frame.fields[field]
        if len(values):
            low, high = min(low, float(values.min())), max(high, float(values.max()))
            extents.append(np.array([frame.x.min(axis=0), frame.x.max(axis=0)]))
        if first is None:
            first = frame
    extremes = np.array([low, high]) if np.isfinite(low) else np.zeros(0)
    return PointsPicture(run, field, extremes, extents or [np.zeros((0, 2))], first.x0)


def write_animation(picture: PointsPicture, path: Path, writer) -> int:
    """Every record of the particle series drawn on ``picture`` and written with the
    matplotlib ``writer`` to ``path`` (atomically); returns the number of frames."""
    run = picture.run
    with atomic_file(path) as temporary, writer.saving(picture.figure, str(temporary), dpi=DPI):
        for index in range(len(run.records)):
            picture.show(run.frame(index), index)
            writer.grab_frame()
    return len(run.records)
