"""Energy bookkeeping (paper Eqs. 25-32) as an observing effect.

At every record step, with the grid velocities of time t known:

* ``kinetic``       E_kin = 1/2 sum_p m_p v_p.v_p                     (Eq. 26)
* ``kinetic_grid``  E_kin^nodes = 1/2 v.M v, lumped or consistent  (Eqs. 28-29)
* ``strain``        E_pot = 1/2 sum_p V_p sigma_p : eps_p (Eq. 27), or the
                    stored energy of a hyperelastic material
* ``total``         E_kin + E_pot                                      (Eq. 25)
* ``external_work`` W, the work done by the declared forces so far
* ``total_error``   dE_kin + dE_pot - W                             (Eqs. 30-31)
* ``interpolation_error``  E_int = dE_kin^nodes - dE_kin              (Eq. 32)
* ``algorithm_error``      E_alg = -dE_kin^nodes - dE_pot + W         (Eq. 32)

``d`` is the change since the first record, so ``total_error = -E_int -
E_alg`` as in the paper; W enters only when a scene declares forces.
Observers that keep a record of their own may add columns (:attr:`extra`:
the exact reference adds ``reference_error``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..effects.base import Effect
from ..step import Stage, StepContext

COLUMNS = (
    "time",
    "kinetic",
    "kinetic_grid",
    "strain",
    "total",
    "interpolation_error",
    "algorithm_error",
    "total_error",
    "external_work",
)


def energy_drift(rows: list[dict]) -> float | None:
    """The energy balance at the last record relative to the run's energy: its
    ``total_error`` over the largest ``kinetic + strain + |external_work|`` of the records
    (the energy the run has held or exchanged at most); None without records (see
    :func:`energy_drift_of_ends`), 0 when that scale is 0 (nothing moved, nothing worked)."""
    if not rows:
        return None
    scale = max(row["kinetic"] + row["strain"] + abs(row["external_work"]) for row in rows)
    return float(rows[-1]["total_error"] / scale) if scale > 0 else 0.0


def energy_drift_of_ends(initial: float, final: float, work: float, peak: float = 0.0) -> float:
    """:func:`energy_drift` of a run without records, from the energies ``kinetic + strain`` it
    started and ended with and the work put in: ``final - initial - work`` over the largest of
    ``initial``, ``final + |work|`` and ``peak``, the largest energy plus work seen between (the
    kinetic energy the runaway guard checks every step; a slow runaway below the guard's bound,
    9x the energy, had no measure at all without records)."""
    scale = max(initial, final + abs(work), peak)
    return float((final - initial - work) / scale) if scale > 0 else 0.0


def kinetic_energy(mass: np.ndarray, velocity: np.ndarray) -> float:
    """Eq. 26: ``1/2 sum m v.v`` (J per unit thickness)."""
    return 0.5 * float(np.einsum("p,pi,pi->", mass, velocity, velocity))


@dataclass
class EnergyBookkeeping(Effect):
    """Records one row of :data:`COLUMNS` per record step.

    ``initial`` holds the first record's kinetic, grid kinetic and strain
    energies and work (the ``d`` of every row is measured from them); with
    ``rows`` it is the whole state, which :meth:`state` and :meth:`restore`
    carry through a checkpoint.
    """

    sink: Callable[[dict], None] | None = None
    rows: list[dict] = field(default_factory=list)
    initial: dict[str, float] = field(default_factory=dict)
    #: further columns: name -> the value at the record just taken (read after the other observers ran)
    extra: dict[str, Callable[[], float]] = field(default_factory=dict)

    name = "energy"
    stage = Stage.OBSERVE

    def bind(self, simulation):
        def record_energy(ctx: StepContext) -> None:
            particles = ctx.particles
            # energies beyond 1e308 are inf, without numpy's warning: the energy guard stops the run on them
            with np.errstate(over="ignore", invalid="ignore"):
                kinetic = kinetic_energy(particles.mass, particles.v)
                grid = 0.5 * float(np.sum(ctx.velocity * ctx.mass.apply(ctx.velocity)))
                strain = ctx.simulation.strain_energy()
            work = float(sum(ctx.work.values()))
            initial = self.initial
            if not initial:
                initial.update(kinetic=kinetic, grid=grid, strain=strain, work=work)
            d_kinetic = kinetic - initial["kinetic"]
            d_grid = grid - initial["grid"]
            d_strain = strain - initial["strain"]
            d_work = work - initial["work"]
            row = {
                "time": ctx.time,
                "kinetic": kinetic,
                "kinetic_grid": grid,
                "strain": strain,
                "total": kinetic + strain,
                "interpolation_error": d_grid - d_kinetic,
                "algorithm_error": -d_grid - d_strain + d_work,
                "total_error": d_kinetic + d_strain - d_work,
                "external_work": work,
            }
            row.update((name, column()) for name, column in self.extra.items())
            self.rows.append(row)
            if self.sink is not None:
                self.sink(row)

        return record_energy

    @property
    def columns(self) -> tuple[str, ...]:
        """:data:`COLUMNS`, then the :attr:`extra` ones."""
        return (*COLUMNS, *self.extra)

    def table(self) -> dict[str, np.ndarray]:
        """The records as arrays, one per column."""
        return {name: np.array([row[name] for row in self.rows]) for name in self.columns}

    def state(self) -> tuple[dict, np.ndarray]:
        """``(initial, rows)``: the first record's values and every row so far,
        shape (records, len(columns)), for a checkpoint."""
        columns = self.columns
        rows = np.array([[row[name] for name in columns] for row in self.rows], dtype=float).reshape(-1, len(columns))
        return dict(self.initial), rows

    def restore(self, initial: dict, rows: np.ndarray) -> None:
        """Take back :meth:`state` (the sink is not called: its owner restores its own)."""
        self.initial.clear()
        self.initial.update({name: float(value) for name, value in initial.items()})
        self.rows[:] = [{name: float(value) for name, value in zip(self.columns, row)} for row in rows]
