"""What a run produced: :class:`RunResult` (returned by ``Simulation.run``)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .particles import Particles


@dataclass
class RunResult:
    """What a run produced.

    Attributes
    ----------
    status : {"completed", "stopped"}
    message : str
        Why the run ended.
    energy : dict of ndarray or None
        Columns of :data:`femgrid_mpm.observers.COLUMNS`, one entry per record.
    particles : Particles
        The final (or last good) state.
    summary : dict
        Title, basis, mass, steps, wall time, counts, negative-mass events,
        ``energy_drift`` (:func:`femgrid_mpm.observers.energy_drift`; without energy
        records :func:`~femgrid_mpm.observers.energy_drift_of_ends`).
    """

    status: str
    message: str
    energy: dict | None
    particles: Particles
    summary: dict = field(default_factory=dict)


def run_result(simulation, status: str, message: str) -> RunResult:
    """The :class:`RunResult` of ``simulation`` (a :class:`~femgrid_mpm.solver.Simulation`) as it
    stands: its state, its energy records and the summary that ``summary.json`` holds."""
    from .observers import energy_drift

    s = simulation
    scene = s.scene
    summary = {
        "title": scene.title,
        "basis": scene.grid.basis,
        "mass": scene.solver.mass,
        "status": status,
        "reason": message,
        "steps": s.step_index,
        "time": s.time,
        "dt": s.dt,
        "critical_dt": s.__dict__.get("critical_dt"),  # if it was estimated (CLI runs, dt = "auto")
        "wall_time": s.wall_time,
        "points": s.particles.n,
        "nodes": s.grid.n_nodes,
        "effects": s.active_effects,
        "negative_mass": s.negative_mass.summary(),
        "energy_drift": energy_drift(s.energy.rows) if s.energy else _drift_of_ends(s),
    }
    summary.update(s.mass.summary())
    for recorder in s.recorders:
        summary.update(recorder.summary())
    energy = s.energy.table() if s.energy else None
    return RunResult(status, message, energy, s.particles, summary)


def _drift_of_ends(s) -> float | None:
    """The energy drift of a run without energy records: from the energy it started with (the
    runaway guard's), the one it ends with, the work the declared forces did and the guard's peak."""
    from .observers import energy_drift_of_ends, kinetic_energy

    with np.errstate(over="ignore", invalid="ignore"):  # a state beyond 1e308: the guard stopped the run on it
        final = kinetic_energy(s.particles.mass, s.particles.v) + s.strain_energy()
        guard = s.energy_guard
        drift = energy_drift_of_ends(guard.initial, final, float(sum(s.context.work.values())), guard.peak)
    return drift if np.isfinite(drift) else None
