"""What accuracy costs in time: the bundled sweeps behind the README's headline figure.

Each sweep (``femgrid_mpm/sweeps/NAME.toml``) runs into ``OUT/NAME/`` as
``femgrid-mpm sweep`` runs it (finished runs are reused on a second call) and
gets its report (``report.md``, ``report.html``, the figures); ``OUT/table.md``
lists, per sweep, the fitted order of convergence of every basis and mass kind
with its errors at each spacing, and for the drifting bar the energy balance's
largest error over the vibration energy (:func:`energy_table`).
"""

from __future__ import annotations

import math
from pathlib import Path

from .timing import report_run

#: the sweeps run, in order: the bar and the manufactured solution over every basis and mass
#: kind, the quasi-static cantilever, the bar's time-step sweep, the manufactured mode on rollers
#: over every basis, mass kind and scheme, the same mode with open knots over the force's and the
#: mass's quadrature, the bar with the mixed mass and with the iterated mass, and the two where
#: points cross cells (the manufactured solution at large amplitude, the drifting bar)
SWEEPS = ("bar_convergence", "manufactured_convergence", "cantilever_convergence", "bar_time_steps",
          "manufactured_rollers", "rollers_quadrature", "mixed_mass", "iterated_mass",
          "manufactured_large_convergence", "drifting_bar_convergence")
#: sweeps of a body that vibrates about a rigid motion: their energy table too
ENERGY_SWEEPS = ("drifting_bar_convergence",)


def planned_runs() -> int:
    """The runs of its sweeps (on Dask's workers; each counted as it ends, :class:`SweepFollower`)."""
    from ..sweep import plan, read_sweep
    from ..sweep.spec import BUNDLED_SWEEPS

    return sum(len(plan(read_sweep(path), path)) for path in (BUNDLED_SWEEPS / f"{name}.toml" for name in SWEEPS))


class SweepFollower:
    """A sweep's progress (:class:`~femgrid_mpm.sweep.runner.SweepProgress`) told to whoever follows
    the cases, a run at a time: without it the command line's count stood still for the whole
    study (~12 of its 16 minutes)."""

    def __init__(self, sweep: str):
        self.sweep = sweep

    def started(self, total: int, reused: int, running: list[str]) -> None:
        for _ in range(reused):  # finished by an earlier call: counted at once
            report_run(f"{self.sweep}, reused")

    def finished(self, key: str, status: str, running: list[str]) -> None:
        report_run(f"{self.sweep}, {key}")


def run(out, workers: int | None = None) -> dict:
    """Run :data:`SWEEPS` into ``out``; the fitted orders, ``{sweep: {method: order}}``."""
    from ..output import atomic_write
    from ..sweep import plan, read_sweep, run_sweep
    from ..sweep.report import write_report
    from ..sweep.spec import BUNDLED_SWEEPS

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    orders, sections = {}, ["# What accuracy costs in time\n"]
    for name in SWEEPS:
        path = BUNDLED_SWEEPS / f"{name}.toml"
        directory = out / name
        directory.mkdir(parents=True, exist_ok=True)
        atomic_write(directory / "sweep.toml", path.read_bytes())
        run_sweep(plan(read_sweep(path), path), directory, workers=workers, progress=SweepFollower(name))
        write_report(directory)
        orders[name], section = order_table(directory)
        if name in ENERGY_SWEEPS:
            section += "\n" + energy_table(directory)
        sections.append(f"## {name}\n\nReport: `{name}/report.md`.\n\n{section}")
    atomic_write(out / "table.md", "\n".join(sections))
    return orders


def order_table(directory: Path) -> tuple[dict, str]:
    """The fitted orders of a sweep's ``runs.csv`` per (basis, mass) over its spacings, and
    their Markdown table (empty when the sweep varies no spacing)."""
    from ..sweep import RUNS_FILE, read_runs
    from ..sweep.analysis import fitted_order
    from ..sweep.spec import read_sweep

    spec = read_sweep(directory / "sweep.toml")
    error = spec.report.error
    varied, rows = read_runs(directory / RUNS_FILE)
    if "grid.spacing" not in varied:
        return {}, "(a time-step sweep: see its report)\n"
    methods: dict[str, list[tuple[float, float]]] = {}
    for row in rows:
        if row["status"] != "completed" or row[error] is None or not row[error] > 0:
            continue
        method = ", ".join(str(row[key]) for key in varied if key != "grid.spacing")
        methods.setdefault(method, []).append((float(row["grid.spacing"]), row[error]))
    spacings = sorted({float(row["grid.spacing"]) for row in rows}, reverse=True)
    lines = ["| " + " / ".join(k for k in varied if k != "grid.spacing") + " | "
             + " | ".join(f"{error} at h = {h:g}" for h in spacings) + " | fitted order |",
             "|---" * (len(spacings) + 2) + "|"]
    orders = {}
    for method, points in methods.items():
        found = dict(points)
        order = fitted_order(*zip(*points))[0] if len(found) >= 2 else math.nan
        orders[method] = order
        cells = [f"{found[h]:.3g}" if h in found else "" for h in spacings]
        lines.append(f"| {method} | " + " | ".join(cells) + f" | {order:.2f} |")
    return orders, "\n".join(lines) + "\n"


def vibration_energy_error(energy_csv: Path) -> float:
    """The largest ``|total_error|`` of a run's energy record over its largest ``strain``:
    for a free body vibrating in one mode about a rigid motion, the largest strain energy
    is the vibration's energy (all of it is strain at the turning points), which the rigid
    motion's kinetic energy would swamp as a scale."""
    import csv

    with open(energy_csv, newline="") as handle:
        rows = list(csv.DictReader(handle))
    error = max(abs(float(row["total_error"])) for row in rows)
    strain = max(float(row["strain"]) for row in rows)
    return error / strain if strain > 0 else math.nan


def energy_table(directory: Path) -> str:
    """Markdown: :func:`vibration_energy_error` per (basis, mass) and spacing of a sweep's
    completed runs (``runs/RUN/energy.csv``)."""
    from ..sweep import RUNS_FILE, read_runs
    from ..sweep.runner import RUNS_DIRECTORY

    varied, rows = read_runs(directory / RUNS_FILE)
    spacings = sorted({float(row["grid.spacing"]) for row in rows}, reverse=True)
    found: dict[str, dict[float, float]] = {}
    for row in rows:
        if row["status"] != "completed":
            continue
        method = ", ".join(str(row[key]) for key in varied if key != "grid.spacing")
        value = vibration_energy_error(directory / RUNS_DIRECTORY / row["run"] / "energy.csv")
        found.setdefault(method, {})[float(row["grid.spacing"])] = value
    lines = ["The energy balance's largest error over the vibration energy (the largest strain energy):\n",
             "| " + " / ".join(k for k in varied if k != "grid.spacing") + " | "
             + " | ".join(f"h = {h:g}" for h in spacings) + " |",
             "|---" * (len(spacings) + 1) + "|"]
    for method, values in found.items():
        lines.append(f"| {method} | " + " | ".join(f"{values[h]:.3g}" if h in values else "" for h in spacings) + " |")
    return "\n".join(lines) + "\n"
