"""``femgrid-mpm info``: what a run of a scene would do, without running it."""

from __future__ import annotations

from pathlib import Path

from .parser import EXIT_DONE, emit
from .scene_input import build, critical_dt, load, warn_time_step


def info(args) -> int:
    """Print what a run of the scene would do: counts, active effects, time steps."""
    from ..output import declared_observers

    scene, overrides = load(args)
    simulation = build(scene, args.scene, declared_observers(scene, Path(".")))
    bodies = ", ".join(
        f"{body.name} {members.stop - members.start}" for body, members in zip(scene.bodies, simulation.body_slices)
    )
    grid = scene.grid
    lines = {
        "title": scene.title,
        "scene": args.scene + (" (with " + ", ".join(f"{k} = {v!r}" for k, v in overrides.items()) + ")" if overrides else ""),
        "basis": grid.basis,
        "mass": scene.solver.mass + (f" ({scene.solver.mass_corrections} correction{'s' if scene.solver.mass_corrections > 1 else ''})" if scene.solver.mass == "iterated" else ""),
        "grid": f"[{grid.lower[0]:g}, {grid.lower[1]:g}] to [{simulation.grid.upper[0]:g}, {simulation.grid.upper[1]:g}], spacing {grid.spacing:g} m",
        "points": f"{simulation.particles.n} ({bodies})",
        "nodes": str(simulation.grid.n_nodes),
        "effects": ", ".join(["internal_force (always)", *simulation.active_effects]),
        "dt": f"{simulation.dt:.6g} s" + (" (auto)" if scene.time.dt == "auto" else ""),
        "critical_dt": "not estimated (not enough memory)" if (critical := critical_dt(simulation)) is None
        else f"{critical:.6g} s (estimated)",
        "steps": f"{simulation.n_steps} to t = {simulation.end_time:.6g} s" + (
            "" if abs(simulation.end_time - scene.time.end) <= 1e-9 * scene.time.end else f" (time.end = {scene.time.end:g} s, rounded up to whole steps)"),
        "records": f"every {simulation.every} steps" if simulation.every else "none (no [output])",
    }
    width = max(map(len, lines)) + 1
    emit("\n".join(f"{key + ':':<{width}} {value}" for key, value in lines.items()))
    warn_time_step(simulation)
    return EXIT_DONE
