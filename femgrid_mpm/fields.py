"""One grid velocity field per body (multi-field MPM), for contact between bodies.

With a single field (the paper's model) two bodies that share nodes share a
velocity there: they stick as soon as they are one cell apart.  With
``[contact] kind = "frictional"`` every body keeps its own field: its own
lumped mass, momentum, force, velocity and acceleration on every node, and
its points read only their own field.  The contact effect
(:mod:`femgrid_mpm.effects.contact`) then couples the fields where bodies
meet.  Grid arrays carry a leading field axis, shape (n_bodies, n_nodes, 2).

This is written with scipy's sparse matrices, the reference engine's way:
each body's rows of ``N`` are a contiguous slice (points are stored body by
body).  Lumped mass only.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .effects.base import StepContext
from .mass import _active


@dataclass
class FieldLumpedMass:
    """Lumped masses per body, shape (n_bodies, n_nodes); solves are divisions.

    ``lumped`` is the total over bodies (what a single field would have), for
    the energy bookkeeping and diagnostics; ``field_lumped`` is per body.
    """

    n_nodes: int
    reference_mass: float
    body_slices: list
    kind = "lumped"
    field_lumped: np.ndarray = field(init=False, repr=False)

    def assemble(self, N: sp.csr_matrix, m_p: np.ndarray, volume_p: np.ndarray | None = None) -> None:
        self.field_lumped = np.stack([N[members].T @ m_p[members] for members in self.body_slices])
        self.field_active = np.stack([
            _active(N[members], m_p[members], lumped, self.reference_mass)
            for members, lumped in zip(self.body_slices, self.field_lumped)
        ])
        self._inverse = np.divide(1.0, self.field_lumped, out=np.zeros_like(self.field_lumped), where=self.field_active)
        self.lumped = self.field_lumped.sum(axis=0)
        self.active = self.field_active.any(axis=0)

    def solve(self, rhs: np.ndarray, kind: str = "velocity") -> np.ndarray:
        """``rhs / m`` per field on active nodes, zero elsewhere; rhs (n_bodies, n_nodes, 2)."""
        return rhs * self._inverse[:, :, None]

    def grid_velocity(self, relative_momentum: np.ndarray, frame_velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        momentum = relative_momentum + self.field_lumped[:, :, None] * frame_velocity
        return momentum, self.solve(relative_momentum) + frame_velocity

    def apply(self, vector: np.ndarray) -> np.ndarray:
        """``M @ vector`` per field."""
        return vector * self.field_lumped[:, :, None]


class FieldTransfer:
    """The step's transfers with one field per body (scipy sparse products)."""

    name = "fields"

    def __init__(self, simulation):
        self.grid = simulation.grid
        self.body_slices = simulation.body_slices
        self._divergence = None

    def context(self, simulation, dt: float) -> StepContext:
        context = StepContext(simulation, dt=dt)
        context.body_slices = self.body_slices
        return context

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
        ctx.mass_gradient = np.stack([self._per_body(ctx.dNdx, p.mass[:, None])[..., 0], self._per_body(ctx.dNdy, p.mass[:, None])[..., 0]], axis=-1)
        return self._per_body(ctx.N, p.mass[:, None] * (p.v - ctx.frame_velocity))

    def internal_force(self, ctx: StepContext, dt: float, materials, body_slices) -> np.ndarray:
        p = ctx.particles
        relative_velocity = ctx.velocity - ctx.frame_velocity
        dv_dx = self._gather(ctx.dNdx, relative_velocity)  # (n, 2): d(vx)/dx, d(vy)/dx of each point's own body
        dv_dy = self._gather(ctx.dNdy, relative_velocity)
        strain_increment = dt * np.column_stack([dv_dx[:, 0], dv_dy[:, 1], 0.5 * (dv_dy[:, 0] + dv_dx[:, 1])])
        gradient_increment = dt * np.column_stack([dv_dx[:, 0], dv_dy[:, 0], dv_dx[:, 1], dv_dy[:, 1]])
        p.strain += strain_increment
        for material, members in zip(materials, body_slices):
            material.update(p, members, strain_increment, gradient_increment)
        self._divergence = dv_dx[:, 0] + dv_dy[:, 1]
        weighted_stress = p.volume[:, None] * p.stress
        return -(self._per_body(ctx.dNdx, weighted_stress[:, [0, 2]]) + self._per_body(ctx.dNdy, weighted_stress[:, [2, 1]]))

    def to_points(self, ctx: StepContext, dt: float) -> float:
        p = ctx.particles
        relative_velocity = ctx.velocity - ctx.frame_velocity
        p.v += dt * self._gather(ctx.N, ctx.acceleration)
        p.x += dt * (self._gather(ctx.N, relative_velocity) + ctx.frame_velocity)
        p.density *= np.exp(-dt * self._divergence)
        return p.v.sum() + p.x.sum() + p.stress.sum()
