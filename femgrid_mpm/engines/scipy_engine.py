"""The reference engine: the paper's sparse linear algebra spelled out with scipy matrices.

P2G is ``N.T @ (...)``, G2P ``N @ (...)``, the internal force
``-(dNdx.T @ V sigma_x + dNdy.T @ V sigma_y)``: this is the readable
definition of the step's transfers, which the compiled kernels
(:mod:`.numba_engine`) reproduce to rounding.

:class:`PerBodyTransfer` is the same algebra with one grid field per body
(frictional contact, :class:`femgrid_mpm.mass.FieldLumpedMass`): every
product is taken over one body's rows of the matrices (points are stored
body by body, so those are contiguous), and grid arrays carry a leading body
axis, shape (n_bodies, n_nodes, 2).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..step import StepContext
from .engine import Engine


class ScipyTransfer(Engine):
    """Shape-function matrices and scipy.sparse products."""

    name = "scipy"

    def __init__(self, simulation):
        self.grid = simulation.grid
        self._divergence = None

    def context(self, simulation, dt: float) -> StepContext:
        return StepContext(simulation, dt=dt)

    def to_grid(self, ctx: StepContext, mass) -> np.ndarray:
        p = ctx.particles
        ctx.N, ctx.dNdx, ctx.dNdy = self.grid.shape_functions(p.x)  # ValueError if a point left the grid
        mass.assemble(ctx.N, p.mass, p.volume)
        return ctx.transfer_weights.T @ (p.mass[:, None] * (p.v - ctx.frame_velocity))

    def internal_force(self, ctx: StepContext, dt: float, materials, body_slices) -> np.ndarray:
        p = ctx.particles
        relative_velocity = ctx.velocity - ctx.frame_velocity  # gradients sum to zero: same gradient
        dv_dx = ctx.dNdx @ relative_velocity  # (n, 2): d(vx)/dx, d(vy)/dx
        dv_dy = ctx.dNdy @ relative_velocity  # (n, 2): d(vx)/dy, d(vy)/dy
        self._update_stress(p, dt, dv_dx, dv_dy, materials, body_slices)
        weighted_stress = p.volume[:, None] * p.stress  # volumes of time t
        return -(ctx.dNdx.T @ weighted_stress[:, [0, 2]] + ctx.dNdy.T @ weighted_stress[:, [2, 1]])

    def to_points(self, ctx: StepContext, dt: float) -> float:
        p = ctx.particles
        relative_velocity = ctx.velocity - ctx.frame_velocity
        p.v += dt * (ctx.transfer_weights @ ctx.acceleration)
        p.x += dt * (ctx.N @ relative_velocity + ctx.frame_velocity)
        return self._update_density(p, dt)

    def _update_stress(self, p, dt: float, dv_dx: np.ndarray, dv_dy: np.ndarray, materials, body_slices) -> None:
        """Eq. 18's strain increment from the velocity gradient at the points, then each
        body's material update (Eq. 6)."""
        strain_increment = dt * np.column_stack([dv_dx[:, 0], dv_dy[:, 1], 0.5 * (dv_dy[:, 0] + dv_dx[:, 1])])
        gradient_increment = dt * np.column_stack([dv_dx[:, 0], dv_dy[:, 0], dv_dx[:, 1], dv_dy[:, 1]])  # dt L
        p.strain += strain_increment
        for material, members in zip(materials, body_slices):
            material.update(p, members, strain_increment, gradient_increment)
        self._divergence = dv_dx[:, 0] + dv_dy[:, 1]

    def _update_density(self, p, dt: float) -> float:
        """Eq. 21 with the divergence of the step's start; the finiteness checksum."""
        p.density *= np.exp(-dt * self._divergence)
        return p.v.sum() + p.x.sum() + p.stress.sum()


class PerBodyTransfer(ScipyTransfer):
    """The same transfers with one grid field per body: each body's points see only their own field."""

    name = "fields"

    def __init__(self, simulation):
        super().__init__(simulation)
        self.body_slices = simulation.body_slices

    def context(self, simulation, dt: float) -> StepContext:
        context = StepContext(simulation, dt=dt)
        context.body_slices = self.body_slices
        return context

    def frame_velocity(self, particles) -> np.ndarray:
        """Each field's own frame: the velocity of its body's first point, shape (n_bodies, 1, 2).
        One frame for all (body 0's) left a node that another body touches with a
        round-off weight, inactive, at body 0's velocity, and strained that body by the
        difference (a block moving rigidly took 2.7 kPa when its points crossed a node line)."""
        frames = np.zeros((len(self.body_slices), 1, 2))
        for body, members in enumerate(self.body_slices):
            if members.stop > members.start:
                frames[body, 0] = particles.v[members.start]
        return frames

    def _point_frames(self, ctx: StepContext) -> np.ndarray:
        """Each point's own field's frame, shape (n_points, 2)."""
        return ctx.frame_velocity[ctx.particles.body, 0]

    def _per_body(self, matrix: sp.csr_matrix, values: np.ndarray) -> np.ndarray:
        """``matrix[b].T @ values[b]`` for each body, shape (n_bodies, n_nodes, k)."""
        return np.stack([matrix[members].T @ values[members] for members in self.body_slices])

    def _gather(self, matrix: sp.csr_matrix, grid_field: np.ndarray) -> np.ndarray:
        """``matrix[b] @ grid_field[b]`` stacked over the points, shape (n_points, k)."""
        return np.concatenate([matrix[members] @ grid_field[b] for b, members in enumerate(self.body_slices)])

    def to_grid(self, ctx: StepContext, mass) -> np.ndarray:
        p = ctx.particles
        ctx.N, ctx.dNdx, ctx.dNdy = self.grid.shape_functions(p.x)  # ValueError if a point left the grid
        mass.assemble(ctx.N, p.mass, p.volume)
        ctx.mass_gradient = np.stack([self._per_body(ctx.dNdx, p.mass[:, None])[..., 0],
                                      self._per_body(ctx.dNdy, p.mass[:, None])[..., 0]], axis=-1)
        return self._per_body(ctx.N, p.mass[:, None] * (p.v - self._point_frames(ctx)))

    def internal_force(self, ctx: StepContext, dt: float, materials, body_slices) -> np.ndarray:
        p = ctx.particles
        relative_velocity = ctx.velocity - ctx.frame_velocity
        dv_dx = self._gather(ctx.dNdx, relative_velocity)  # (n, 2): d(vx)/dx, d(vy)/dx of each point's own body
        dv_dy = self._gather(ctx.dNdy, relative_velocity)
        self._update_stress(p, dt, dv_dx, dv_dy, materials, body_slices)
        weighted_stress = p.volume[:, None] * p.stress
        return -(self._per_body(ctx.dNdx, weighted_stress[:, [0, 2]]) + self._per_body(ctx.dNdy, weighted_stress[:, [2, 1]]))

    def kick(self, ctx: StepContext, dt: float, acceleration: np.ndarray) -> None:
        ctx.particles.v += dt * self._gather(ctx.N, acceleration)

    def to_points(self, ctx: StepContext, dt: float) -> float:
        p = ctx.particles
        relative_velocity = ctx.velocity - ctx.frame_velocity
        p.v += dt * self._gather(ctx.N, ctx.acceleration)
        p.x += dt * (self._gather(ctx.N, relative_velocity) + self._point_frames(ctx))
        return self._update_density(p, dt)
