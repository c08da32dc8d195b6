"""The error sources of the MPM step, each measured alone on the manufactured solution.

Usage: ``python experiments/error_sources.py [SECTION ...]`` with sections
``time``, ``start``, ``quadrature``, ``projection``, ``weak``, ``space``, ``rollers``, ``rollers_time``,
``rollers_reconstructed``, ``rollers_auto`` (default: all),
printing one Markdown table per section (the tables of docs/accuracy.md).

The scene is ``scenes/manufactured.toml`` (u_x = A s(x) sin(w t), u_y = -A s(y) sin(w t),
s = sin(pi z)^4 on the unit square, no boundary conditions), and a variant that starts
from rest, u = A s (1 - cos w t), whose initial acceleration is not zero.  The error is
the reference's: the RMS over the points of |u_p - u_exact| over the largest exact
displacement, its maximum over the steps (every step here); "interior" counts only the
points seeded in [1/4, 3/4]^2.  The time error alone is measured without the spatial one
as the difference of the final displacements of runs at dt and dt/2 (same h, same points).
"""

from __future__ import annotations

import os
import sys
import time as clock

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from femgrid_mpm.diagnostics import SimulationStopped  # noqa: E402
from femgrid_mpm.scene.loading import bundled_scene  # noqa: E402
from femgrid_mpm.solver import Simulation  # noqa: E402

PERIOD = 0.6324555320336759  # the manufactured field's period 2 pi / w, the run's end
#: the variant from rest: u = A s(z) (1 - cos w t), b = A (w^2 s cos w t - c^2 s'' (1 - cos w t))
FROM_REST = {
    "bodies.0.velocity": ["0", "0"],
    "loads.0.acceleration": [
        "A*(w**2*sin(pi*x)**4*cos(w*t) - 4*pi**2*c2*sin(pi*x)**2*(3 - 4*sin(pi*x)**2)*(1 - cos(w*t)))",
        "-A*(w**2*sin(pi*y)**4*cos(w*t) - 4*pi**2*c2*sin(pi*y)**2*(3 - 4*sin(pi*y)**2)*(1 - cos(w*t)))"],
    "reference.displacement": ["A*sin(pi*x)**4*(1 - cos(w*t))", "-A*sin(pi*y)**4*(1 - cos(w*t))"],
}


#: the field of Wallstedt & Guilkey (2008) made a free mode: u_x = A sin(pi x) sin(w t),
#: u_y = -A sin(pi y) sin(w t), w = pi c, with rollers on every edge (no body force with nu = 0);
#: its stress does not vanish at the edges, where the supports hold the normal velocity
ROLLERS = {
    "bodies.0.velocity": ["1e-8*9.934588265796101*sin(pi*x)", "-1e-8*9.934588265796101*sin(pi*y)"],
    "loads": [],
    "supports": [{"where": "x <= 0", "fix": ["x"]}, {"where": "x >= 1", "fix": ["x"]},
                 {"where": "y <= 0", "fix": ["y"]}, {"where": "y >= 1", "fix": ["y"]}],  # ghosts set by scene()
    "reference.displacement": ["A*sin(pi*x)*sin(w*t)", "-A*sin(pi*y)*sin(w*t)"],
}


def scene(basis="bspline3", mass="consistent", spacing=1 / 16, points=2, steps=None, safety=0.5,
          from_rest=False, rollers=False, **more):
    """The manufactured scene with these choices; ``steps`` fixes dt = PERIOD / steps."""
    changes = {"grid.basis": basis, "solver.mass": mass, "grid.spacing": spacing,
               "bodies.0.points_per_cell": points, "output.energy": False, **more}
    changes.update({"time.dt": PERIOD / steps} if steps else {"time.safety": safety})
    if from_rest:
        changes.update(FROM_REST)
    if rollers:  # "mirrored" (or True) or "fixed" ghost nodes (bases with no ghost column: fixed)
        changes.update(ROLLERS)
        ghosts = "mirrored" if rollers is True else rollers
        changes["supports"] = [dict(support, ghosts=ghosts) for support in ROLLERS["supports"]]
    return bundled_scene("manufactured").with_overrides(**changes)


def run(current) -> dict:
    """Step the scene to its end; the largest error (whole body, interior) and the final displacement."""
    simulation = Simulation(current)
    p = simulation.particles
    exact = current.reference.exact()
    x0, y0 = p.x0[:, 0], p.x0[:, 1]
    inner = (np.abs(x0 - 0.5) < 0.25) & (np.abs(y0 - 0.5) < 0.25)
    worst = np.zeros(2)
    peak = 0.0
    started = clock.perf_counter()
    while simulation.step_index < simulation.n_steps:
        simulation.advance()
        u_exact = exact(x0, y0, simulation.time)
        squared = np.sum((p.x - p.x0 - u_exact) ** 2, axis=1)
        worst = np.maximum(worst, [np.sqrt(squared.mean()), np.sqrt(squared[inner].mean())])
        peak = max(peak, float(np.sqrt(np.max(np.sum(u_exact**2, axis=1)))))
    return {"whole": worst[0] / peak, "interior": worst[1] / peak, "u": p.x - p.x0, "peak": peak,
            "dt": simulation.dt, "steps": simulation.n_steps, "critical": simulation.critical_dt,
            "wall": clock.perf_counter() - started}


def order(coarse: float, fine: float, ratio: float = 2.0) -> str:
    return f"{np.log(coarse / fine) / np.log(ratio):.2f}" if coarse > 0 and fine > 0 else "-"


def table(title: str, header: list[str], rows: list[list]) -> None:
    print(f"\n### {title}\n")
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for row in rows:
        print("| " + " | ".join(f"{v:.3g}" if isinstance(v, float) else str(v) for v in row) + " |", flush=True)


def time_integration(cases, from_rest=False, title="Time integration") -> None:
    """Vary dt at fixed h: the error against the exact field, and the time error alone
    (final displacement of dt against dt/2)."""
    rows = []
    for (basis, mass, spacing, steps_list, extra) in cases:
        runs = [run(scene(basis, mass, spacing, steps=n, from_rest=from_rest, **extra)) for n in steps_list]
        for k, (n, result) in enumerate(zip(steps_list, runs)):
            difference = ""
            if k + 1 < len(runs):
                difference = float(np.sqrt(np.mean(np.sum((result["u"] - runs[k + 1]["u"]) ** 2, axis=1)))) / result["peak"]
            rows.append([f"{basis} {mass}" + "".join(f" {key.split('.')[-1]}={v}" for key, v in extra.items()),
                         f"1/{round(1 / spacing)}", f"{result['dt']:.3g}", f"{result['dt'] / result['critical']:.3g}",
                         result["whole"], difference])
        differences = [row[-1] for row in rows[-len(runs):-1]]
        rows[-1][-1] = "order " + ", ".join(order(a, b) for a, b in zip(differences, differences[1:]))
    table(title, ["basis, mass", "h", "dt (s)", "dt / critical", "error_max vs exact",
                  "time error: |u(dt) - u(dt/2)| at the end"], rows)


def quadrature(cases, points_list) -> None:
    """Vary the points per cell at fixed h and a small step."""
    rows = []
    for basis, mass, spacing, steps in cases:
        for points in points_list:
            try:
                result = run(scene(basis, mass, spacing, points=points, steps=steps))
            except SimulationStopped as stop:  # one point per cell: a singular consistent mass
                rows.append([f"{basis} {mass}", f"1/{round(1 / spacing)}", f"{points}x{points}", "", "",
                             str(stop).split(": ")[1].split(" (")[0], ""])
                continue
            rows.append([f"{basis} {mass}", f"1/{round(1 / spacing)}", f"{points}x{points}", f"{result['dt']:.3g}",
                         f"{result['dt'] / result['critical']:.3g}", result["whole"], result["interior"]])
    table("Internal-force quadrature: points per cell", ["basis, mass", "h", "points", "dt (s)", "dt / critical",
                                                         "error_max whole", "error_max interior"], rows)


def projection(cases, spacings) -> None:
    """The initial projection alone: |N M^-1 N^T m v_p - v_p| / max|v_p| at t = 0 (no step)."""
    rows = []
    for basis, mass in cases:
        errors = []
        for spacing in spacings:
            simulation = Simulation(scene(basis, mass, spacing))
            ctx, p = simulation.project(), simulation.particles
            back = ctx.N @ ctx.velocity
            errors.append(float(np.sqrt(np.mean(np.sum((back - p.v) ** 2, axis=1))) / np.max(np.abs(p.v))))
        rows.append([f"{basis} {mass}", *errors, order(errors[-2], errors[-1])])
    table("Initial projection of the velocity (t = 0)", ["basis, mass", *(f"h = 1/{round(1 / h)}" for h in spacings),
                                                         "order"], rows)


def weak_nodes(spacing, fractions, steps) -> None:
    """The consistent mass with its weak nodes lumped below ``weak_fraction``, at one fixed dt."""
    rows = []
    for fraction in fractions:
        result = run(scene("bspline3", "consistent", spacing, steps=steps, **{"solver.weak_fraction": fraction}))
        rows.append([fraction, f"1/{round(1 / spacing)}", f"{result['dt']:.3g}",
                     f"{result['dt'] / result['critical']:.3g}", result["whole"], result["interior"]])
    table("Weak-node mass: weak_fraction (bspline3 consistent, 2x2 points)",
          ["weak_fraction", "h", "dt (s)", "dt / critical", "error_max whole", "error_max interior"], rows)


def space(cases, spacings, steps_per_cell, rollers=False, title="Space", **extra) -> None:
    """Convergence in h at a step proportional to h but small (the time error below the spatial one);
    ``extra`` scene keys for every run; the wall time per step of the finest run."""
    rows = []
    for basis, mass, points, *ghosts in cases:  # ghosts: the rollers' ("mirrored" unless given)
        walls = (ghosts[0] if ghosts else "mirrored") if rollers else False
        results = [run(scene(basis, mass, h, points=points, steps=round(steps_per_cell / h) if steps_per_cell else None,
                             rollers=walls, **extra)) for h in spacings]
        whole, inner = [r["whole"] for r in results], [r["interior"] for r in results]
        label = f"{basis} {mass} {points}x{points}" + (f" {walls} ghosts" if walls and basis in GHOST_COLUMN else "")
        rows.append([label, *(f"{w:.3g} / {i:.3g}" for w, i in zip(whole, inner)),
                     f"{order(whole[-2], whole[-1])} / {order(inner[-2], inner[-1])}",
                     f"{max(r['dt'] / r['critical'] for r in results):.3g}",
                     f"{1e3 * results[-1]['wall'] / results[-1]['steps']:.2f}"])
    choices = "".join(f", {key.split('.')[-1]} = {value}" for key, value in extra.items())
    step = f"dt = T / ({steps_per_cell:g} / h)" if steps_per_cell else "dt = auto (safety 0.5)"
    table(f"{title}: error_max whole / interior, {step}{choices}",
          ["basis, mass", *(f"h = 1/{round(1 / h)}" for h in spacings), "order (last two)", "dt / critical (largest)",
           "ms / step (finest)"], rows)


#: the bases with a column of nodes beyond the grid's edge, where the rollers' ghosts matter
GHOST_COLUMN = ("bspline3", "bspline2", "gimp")

#: basis, mass, h, steps per period (the first near the critical step), more scene keys
TIME_CASES = [("q1", "lumped", 1 / 16, [20, 40, 80, 160], {}), ("bspline3", "consistent", 1 / 16, [250, 500, 1000], {})]

#: basis, mass, points per cell of the rollers' tables
ROLLER_CASES = [("bspline3_open", "consistent", 2), ("bspline3_open", "consistent", 3), ("bspline3_open", "consistent", 4),
                ("q2", "consistent", 2), ("q2", "consistent", 3)]

SECTIONS = {
    "time": lambda: time_integration(TIME_CASES),
    "start": lambda: time_integration(TIME_CASES, from_rest=True,
                                      title="Time integration, from rest (initial acceleration not zero)"),
    "quadrature": lambda: quadrature([("bspline3", "consistent", 1 / 8, 600), ("q1", "lumped", 1 / 8, 600)],
                                     [1, 2, 3, 4, 5]),
    "projection": lambda: projection([("q1", "lumped"), ("q1", "consistent"), ("bspline3", "lumped"),
                                      ("bspline3", "consistent"), ("bspline3_open", "consistent")],
                                     [1 / 8, 1 / 16, 1 / 32]),
    "weak": lambda: weak_nodes(1 / 16, [0.0, 0.01, 0.05], 600),
    "space": lambda: space([("bspline3", "consistent", 2), ("bspline3_open", "consistent", 2), ("q1", "lumped", 2)],
                           [1 / 8, 1 / 16, 1 / 32], 37.5),
    "rollers": lambda: space([("bspline3_open", "consistent", 2), ("bspline3_open", "consistent", 3),
                              ("bspline3", "consistent", 2, "fixed"), ("bspline3", "consistent", 2),
                              ("bspline2", "consistent", 2), ("bspline3", "lumped", 2)],
                             [1 / 8, 1 / 16, 1 / 32], 37.5, rollers=True,
                             title="Boundaries: the W&G mode with rollers"),
    "rollers_time": lambda: space([("bspline3", "consistent", 2)], [1 / 8, 1 / 16, 1 / 32], 150, rollers=True,
                                  title="Boundaries: the W&G mode with mirrored rollers, a step 4x smaller"),
    "rollers_reconstructed": lambda: space(ROLLER_CASES, [1 / 8, 1 / 16, 1 / 32], 37.5, rollers=True,
                                           title="Boundaries: the W&G mode with rollers",
                                           **{"solver.force_quadrature": "reconstructed"}),
    "rollers_auto": lambda: [space(ROLLER_CASES[:3], [1 / 8, 1 / 16, 1 / 32], None, rollers=True,
                                   title="Boundaries: the W&G mode with rollers", **{"solver.force_quadrature": choice})
                             for choice in ("points", "reconstructed")],
}

if __name__ == "__main__":
    unknown = [name for name in sys.argv[1:] if name not in SECTIONS]
    if unknown:
        sys.exit(f"usage: python {sys.argv[0]} [SECTION ...]; sections: {', '.join(SECTIONS)} (not {', '.join(unknown)})")
    for name in sys.argv[1:] or SECTIONS:
        started = clock.perf_counter()
        SECTIONS[name]()
        print(f"\n({name}: {clock.perf_counter() - started:.0f} s)", flush=True)
