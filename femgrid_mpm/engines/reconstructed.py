"""The force pass with the internal force integrated from a reconstructed stress.

``[solver] force_quadrature = "reconstructed"`` wraps the scene's engine: its passes are
the engine's own, its force pass updates the stress at the points as the engine does and
then integrates ``-int grad N . sigma`` by Gauss quadrature of a polynomial fitted to the
points' stress in every filled cell, of degree ``points_per_cell - 1`` in each direction (:class:`femgrid_mpm.quadrature.StressReconstruction`),
the points' sum elsewhere.  A scene that does not choose it runs the engine unwrapped.
"""

from __future__ import annotations

import numpy as np

from ..quadrature import StressReconstruction
from ..step import StepContext
from .engine import Engine


class ReconstructedForce(Engine):
    """An engine's passes, with the internal force by Gauss quadrature of a reconstructed stress."""

    name = "reconstructed"

    def __init__(self, engine: Engine, simulation):
        self.engine = engine
        self.reconstruction = StressReconstruction.of_scene(simulation.grid, simulation.scene)

    def frame_velocity(self, particles) -> np.ndarray:
        return self.engine.frame_velocity(particles)

    def context(self, simulation, dt: float) -> StepContext:
        return self.engine.context(simulation, dt)

    def to_grid(self, ctx: StepContext, mass) -> np.ndarray:
        return self.engine.to_grid(ctx, mass)

    def internal_force(self, ctx: StepContext, dt: float, materials, body_slices) -> np.ndarray:
        self.engine.internal_force(ctx, dt, materials, body_slices)  # the stress of t + dt at the points
        p = ctx.particles
        return self.reconstruction.force(p.x, p.volume, p.stress, p.body, lambda: (ctx.dNdx, ctx.dNdy))

    def to_points(self, ctx: StepContext, dt: float) -> float:
        return self.engine.to_points(ctx, dt)

    def kick(self, ctx: StepContext, dt: float, acceleration: np.ndarray) -> None:
        self.engine.kick(ctx, dt, acceleration)
