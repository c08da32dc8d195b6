"""The interface of the step's transfers, which :meth:`femgrid_mpm.solver.Simulation.advance`
is written against once (``[solver] engine`` picks the implementation)."""

from __future__ import annotations

import abc
from typing import ClassVar

import numpy as np

from ..step import StepContext


class Engine(abc.ABC):
    """The three passes of a step between points and grid.

    ``to_grid(ctx, mass) -> relative momentum``
        P2G: shape functions at the points, the grid mass (``mass`` is
        assembled), ``N.T @ (m_p (v_p - v_ref))``.
    ``internal_force(ctx, dt, materials, body_slices) -> force``
        Strain increment from the grid velocity (Eq. 18), each body's material
        update (Eq. 6), ``-(dNdx.T @ V sigma_x + dNdy.T @ V sigma_y)`` (Eq. 11).
    ``to_points(ctx, dt) -> checksum``
        G2P: ``v += dt N @ a``, ``x += dt (N @ v_rel + v_ref)``, density (Eqs.
        19-21); returns ``sum(v) + sum(x) + sum(stress)`` for the finiteness check.

    A mass model with transfer weights of its own (HRZ) has them replace ``N``
    in the P2G momentum and the G2P velocity increment
    (:meth:`femgrid_mpm.mass.MassModel.transfer_weights`); gradients and
    positions keep ``N``.
    """

    name: ClassVar[str]

    def frame_velocity(self, particles) -> np.ndarray:
        """The velocity of the frame the step computes in: one point's (the first), so that
        a uniform motion has zero relative velocity and moves exactly."""
        return particles.v[0].copy()

    @abc.abstractmethod
    def context(self, simulation, dt: float) -> StepContext:
        """The step's context, made once per run."""

    @abc.abstractmethod
    def to_grid(self, ctx: StepContext, mass) -> np.ndarray:
        """P2G; assembles ``mass``; returns the momentum relative to ``ctx.frame_velocity``."""

    @abc.abstractmethod
    def internal_force(self, ctx: StepContext, dt: float, materials, body_slices) -> np.ndarray:
        """Strain and stress at the points, then the nodal internal force."""

    @abc.abstractmethod
    def to_points(self, ctx: StepContext, dt: float) -> float:
        """G2P; returns the finiteness checksum."""

    def kick(self, ctx: StepContext, dt: float, acceleration: np.ndarray) -> None:
        """The points' velocity alone, ``v += dt N @ a`` (``W`` with HRZ mass), the points
        staying where they are: the centred scheme's starting half step."""
        ctx.particles.v += dt * (ctx.transfer_weights @ acceleration)
