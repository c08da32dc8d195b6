"""Why consistent cubic splines converge at order 1.57 on the vibrating bar (bar_convergence sweep).

Usage: ``python experiments/bar_order.py [SECTION ...]`` with sections ``auto`` (the sweep's runs:
dt = "auto"), ``fixed`` (a small fixed step), ``fixed_open`` (the same with open knots), ``scheme``
(the centred scheme), ``amplitude`` (1e-6 m/s), ``time`` (the step at one spacing), ``points``
(the points per cell); default all (about an hour).
Each prints a Markdown table (docs/accuracy.md, "The vibrating bar").

The scene is ``vibrating_bar_exact`` (nu = 0, the exact first axial mode, free on every side, 8 s);
the error is its reference's ``error_max``: the RMS over the points of |u - u_exact| over the
largest exact displacement, the largest over the records (every step here).
"""

from __future__ import annotations

import os
import sys
import time as clock

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from femgrid_mpm.scene.loading import bundled_scene  # noqa: E402
from femgrid_mpm.solver import Simulation  # noqa: E402

SPACINGS = [0.5, 0.25, 0.125, 0.0625]


def error(basis="bspline3", spacing=0.5, dt="auto", scheme="paper", amplitude=1e-5, mass="consistent", points=3):
    """(error_max, dt, wall) of one run of the exact bar with these choices."""
    changes = {"grid.basis": basis, "solver.mass": mass, "grid.spacing": spacing, "time.dt": dt,
               "solver.scheme": scheme, "output.every": 1, "output.energy": False,
               "bodies.0.points_per_cell": points,
               "bodies.0.velocity": [f"{amplitude!r}*cos(pi*x/5)", "0"], "reference.constants.A": amplitude}
    simulation = Simulation(bundled_scene("vibrating_bar_exact").with_overrides(**changes))
    started = clock.perf_counter()
    result = simulation.run()
    return result.summary["reference"]["error_max"], simulation.dt, clock.perf_counter() - started


def order(a: float, b: float, ratio: float = 2.0) -> str:
    return f"{np.log(a / b) / np.log(ratio):.2f}"


def convergence(title: str, spacings=SPACINGS, bases=("bspline3", "bspline3_open"), steps=None, **choices) -> None:
    """Each basis over the spacings; ``steps``: a fixed dt per spacing (else ``choices``' dt)."""
    print(f"\n### {title}\n\n| basis | " + " | ".join(f"h = {h:g}" for h in spacings) + " | orders | dt |")
    print("|" + "---|" * (len(spacings) + 3))
    for basis in bases:
        runs = [error(basis, h, **({"dt": steps[k]} if steps else {}), **choices) for k, h in enumerate(spacings)]
        errors = [r[0] for r in runs]
        print(f"| {basis} | " + " | ".join(f"{e:.3g}" for e in errors) + " | "
              + ", ".join(order(a, b) for a, b in zip(errors, errors[1:])) + " | "
              + ", ".join(f"{r[1]:.3g}" for r in runs) + " |", flush=True)


def time_error(spacing=0.25, steps=(0.008, 0.004, 0.002, 0.001, 0.0005)) -> None:
    print(f"\n### Time step at h = {spacing:g} (bspline3 consistent)\n\n| dt | error_max | wall (s) |\n|---|---|---|")
    for dt in steps:
        e, _, wall = error("bspline3", spacing, dt)
        print(f"| {dt:g} | {e:.3g} | {wall:.1f} |", flush=True)


def points(cases=((0.5, (3, 4, 6)), (0.25, (2, 3, 4))), dt=0.001) -> None:
    print(f"\n### Points per cell (bspline3 consistent, dt = {dt:g} s)\n\n| h | points | error_max |\n|---|---|---|")
    for spacing, counts in cases:
        for count in counts:
            print(f"| {spacing:g} | {count}x{count} | {error('bspline3', spacing, dt, points=count)[0]:.3g} |", flush=True)


SECTIONS = {
    "auto": lambda: convergence('dt = "auto" (the sweep)'),
    "fixed": lambda: convergence("a small fixed step (the spatial error alone)", bases=("bspline3",),
                                  steps=[0.0005, 0.0005, 0.0005, 0.00025]),
    "fixed_open": lambda: convergence("a small fixed step, open knots", SPACINGS[:2], ("bspline3_open",), dt=0.0005),
    "scheme": lambda: convergence('centred scheme, dt = "auto"', [0.25], ("bspline3",), scheme="centred"),
    "amplitude": lambda: convergence('amplitude 1e-6 m/s, dt = "auto"', [0.5], ("bspline3",), amplitude=1e-6),
    "time": time_error,
    "points": points,
}

if __name__ == "__main__":
    unknown = [name for name in sys.argv[1:] if name not in SECTIONS]
    if unknown:
        sys.exit(f"usage: python {sys.argv[0]} [SECTION ...]; sections: {', '.join(SECTIONS)} (not {', '.join(unknown)})")
    for name in sys.argv[1:] or SECTIONS:
        started = clock.perf_counter()
        SECTIONS[name]()
        print(f"\n({name}: {clock.perf_counter() - started:.0f} s)", flush=True)
