"""What a run produced: :class:`RunResult` (returned by ``Simulation.run``)."""

from __future__ import annotations

from dataclasses import dataclass, field

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
        ``energy_drift`` (:func:`femgrid_mpm.observers.energy_drift`, None
        without energy records).
    """

    status: str
    message: str
    energy: dict | None
    particles: Particles
    summary: dict = field(default_factory=dict)
