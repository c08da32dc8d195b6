"""The passes whose integrals are Gauss quadratures of fields reconstructed from the points.

``[solver] force_quadrature = "reconstructed"`` wraps the scene's engine in
:class:`ReconstructedForce`: its force pass updates the stress at the points as the engine
does and then integrates ``-int grad N . sigma`` by Gauss quadrature of a polynomial fitted
to the points' stress in every filled cell, of degree ``points_per_cell - 1`` in each
direction (:class:`femgrid_mpm.quadrature.StressReconstruction`), the points' sum elsewhere.
``mass_quadrature = "reconstructed"`` wraps it in :class:`ReconstructedMass`: the consistent
mass and the momentum by Gauss quadrature in the same cells
(:class:`femgrid_mpm.quadrature.MassReconstruction`).  A scene that chooses neither runs
its engine unwrapped.
"""

from __future__ import annotations

import numpy as np

from ..quadrature import MassReconstruction, StressReconstruction
from ..step import StepContext
from .engine import Engine


class EngineVariant(Engine):
    """An engine's passes, each handed to it unless a variant replaces the pass."""

    def __init__(self, engine: Engine):
        self.engine = engine

    def frame_velocity(self, particles) -> np.ndarray:
        return self.engine.frame_velocity(particles)

    def context(self, simulation, dt: float) -> StepContext:
        return self.engine.context(simulation, dt)

    def to_grid(self, ctx: StepContext, mass) -> np.ndarray:
        return self.engine.to_grid(ctx, mass)

    def internal_force(self, ctx: StepContext, dt: float, materials, body_slices) -> np.ndarray:
        return self.engine.internal_force(ctx, dt, materials, body_slices)

    def to_points(self, ctx: StepContext, dt: float) -> float:
        return self.engine.to_points(ctx, dt)

    def kick(self, ctx: StepContext, dt: float, acceleration: np.ndarray) -> None:
        self.engine.kick(ctx, dt, acceleration)


class ReconstructedForce(EngineVariant):
    """An engine's passes, with the internal force by Gauss quadrature of a reconstructed stress."""

    name = "reconstructed"

    def __init__(self, engine: Engine, simulation):
        super().__init__(engine)
        self.reconstruction = StressReconstruction.of_scene(simulation.grid, simulation.scene)

    def internal_force(self, ctx: StepContext, dt: float, materials, body_slices) -> np.ndarray:
        self.engine.internal_force(ctx, dt, materials, body_slices)  # the stress of t + dt at the points
        p = ctx.particles
        return self.reconstruction.force(p.x, p.volume, p.stress, p.body, lambda: (ctx.dNdx, ctx.dNdy))


class ReconstructedMass(EngineVariant):
    """An engine's passes, with the consistent mass and the momentum by Gauss quadrature of the
    cells' density and of a velocity fitted to their points."""

    name = "reconstructed_mass"

    def __init__(self, engine: Engine, simulation):
        super().__init__(engine)
        self.grid = simulation.grid
        self.reconstruction = MassReconstruction.of_scene(simulation.grid, simulation.scene)

    def to_grid(self, ctx: StepContext, mass) -> np.ndarray:
        # the engine's own pass for its shape functions; its sums of the mass are not the run's,
        # so they are not assembled (a consistent mass prepares, and may factor, what it is given)
        self.engine.to_grid(ctx, _PointsMoved(mass))
        p = ctx.particles
        relative = p.v - ctx.frame_velocity
        rows, masses, volumes, velocities = self.reconstruction.rows(
            p.x, p.volume, p.mass, p.body, relative, lambda summed: self.grid.shape_functions(p.x[summed])[0])
        mass.assemble(rows, masses, volumes)
        return rows.T @ (masses[:, None] * velocities)


class _PointsMoved:
    """The mass an engine's P2G is handed by :class:`ReconstructedMass`: it hears that the points
    moved and drops the points' sums, which the variant replaces by its own."""

    def __init__(self, mass):
        self.mass = mass

    def points_moved(self) -> None:
        self.mass.points_moved()

    def assemble(self, N, m_p, volume_p=None) -> None:
        """The points' sums, dropped."""

    def assemble_sums(self, sums) -> None:
        """The compiled P2G's sums, dropped."""
