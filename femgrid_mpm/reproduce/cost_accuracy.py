"""What accuracy costs in time: the bundled sweeps behind the README's headline figure.

Each sweep (``femgrid_mpm/sweeps/NAME.toml``) runs into ``OUT/NAME/`` as
``femgrid-mpm sweep`` runs it (finished runs are reused on a second call) and
gets its report (``report.md``, ``report.html``, the figures); ``OUT/table.md``
lists, per sweep, the fitted order of convergence of every basis and mass kind
with its errors at each spacing.
"""

from __future__ import annotations

import math
from pathlib import Path

#: the sweeps run, in order: the bar and the manufactured solution over every basis and mass
#: kind, the quasi-static cantilever, the bar's time-step sweep, and the manufactured mode on
#: rollers over every basis, mass kind and scheme
SWEEPS = ("bar_convergence", "manufactured_convergence", "cantilever_convergence", "bar_time_steps",
          "manufactured_rollers")


def planned_runs() -> int:
    """Simulations this case makes in its own process: none (its runs are on Dask's workers)."""
    return 0


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
        run_sweep(plan(read_sweep(path), path), directory, workers=workers)
        write_report(directory)
        orders[name], section = order_table(directory)
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
