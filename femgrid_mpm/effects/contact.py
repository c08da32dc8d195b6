"""Contact between bodies: one shared velocity field, or frictional multi-field contact.

``[contact] kind = "shared"`` is the paper's model: all bodies share one grid
velocity field, so they stick as soon as their points share nodes.  It runs
no code of its own (it is the single-field step).

``[contact] kind = "frictional"`` follows Bardenhagen, Guilkey, Roessig,
Brackbill, Witzel and Foster (2001, CMES 2(4)): every body has its own grid
field (:mod:`femgrid_mpm.mass.per_body`), and at a node where several bodies have
mass each body's velocity is compared with the centre-of-mass velocity
``v_cm = sum m_b v_b / sum m_b``:

* normal: ``n_b``, the unit vector from body b towards the others, from the
  bodies' mass gradients ``sum_p m_p grad N_i(x_p)`` (each an outward
  normal of its body): ``grad m_b - grad m_rest``, common (opposite) for two
  bodies so that the correction conserves momentum;
* contact only where body b *approaches*, ``(v_b - v_cm) . n_b > 0``, and
  the bodies are *actually close*: the gap between the surfaces, measured
  along ``n_b`` from the outermost points of each body touching the node
  minus half a point spacing for each, is below ``gap`` spacings of the grid
  (default 0: the surfaces touch);
* there the approaching normal velocity is removed (bodies cannot
  interpenetrate) and the tangential slip is reduced by at most
  ``friction`` times that normal change (Coulomb; 0 is frictionless);
  separating bodies are left alone, so they can part.

The correction acts on the updated velocity ``v^L = v + dt a`` (the
acceleration becomes ``(corrected v^L - v) / dt``), so the points' FLIP
update carries it.  Bardenhagen et al. also correct the velocity right
after P2G; in the paper's update order that velocity moves the points and
strains each body from its own field, and correcting it as well broke the
energy balance (strains and kinetic energy then see different velocities:
29% of the initial energy unaccounted for in the box impact, against 9.6%
without).  Acting at the end of the step only, bodies can overlap by at
most ``v dt`` for one step (measured in the box impact: 0.07 m at the
most, under half a cell).  The kinetic energy the correction gives the
points is booked exactly as the contact's work (``external_work``):
frictionless normal impact on the grid is perfectly inelastic, so it is a
loss.  The balance then closes to first order in dt (box impact: 9.6% of
the initial energy at dt = 0.005, 2.4% at dt = 0.001, the single-field
run's level).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import NonNegativeFloat
from pydantic.dataclasses import dataclass

from ..step import Stage, StepContext
from .base import Effect
from .config import EFFECT_CONFIG


@dataclass(frozen=True, config=EFFECT_CONFIG)
class Contact(Effect):
    """``[contact]``: ``kind`` ``"shared"`` or ``"frictional"``, with ``friction``
    (Coulomb coefficient) and ``gap`` (in grid spacings) for ``"frictional"``."""

    kind: Literal["shared", "frictional"] = "shared"
    friction: NonNegativeFloat = 0.0
    gap: NonNegativeFloat = 0.0

    name = "contact"
    stage = Stage.CONSTRAIN

    @property
    def fields_per_body(self) -> bool:
        """One grid field per body: frictional contact (shared contact is the single-field
        step itself and runs no code of its own)."""
        return self.kind == "frictional"

    def bind(self, simulation):
        particles = simulation.particles
        slices = simulation.body_slices
        n_bodies = len(slices)
        # half the spacing of the points of each body (m): surfaces lie that far out
        half_spacing = np.array([0.5 * np.sqrt(np.mean(particles.volume[members])) for members in slices])
        tolerance = self.gap * simulation.grid.spacing
        mu = float(self.friction)
        # a body is present at a node with more than 1e-12 of a full cell of its own material
        tiny = 1e-12 * simulation.cell_masses.per_body[:, None]

        def resolve(ctx: StepContext) -> None:
            if ctx.target is ctx.velocity:
                return  # acts on the updated velocity only (see the module's notes)
            mass = ctx.mass.field_lumped  # (bodies, nodes)
            present = mass > tiny
            shared = np.flatnonzero(present.sum(axis=0) >= 2)
            if len(shared) == 0:
                return
            trial = ctx.velocity[:, shared] + ctx.dt * ctx.target[:, shared]  # v^L = v + dt a
            m = mass[:, shared]
            centre = np.einsum("bn,bnc->nc", m, trial) / m.sum(axis=0)[:, None]
            gradient = ctx.mass_gradient[:, shared]  # (bodies, nodes, 2)
            correction = np.zeros_like(trial)
            for body in range(n_bodies):
                # sum m_p grad N_i(x_p) points from a body's mass towards node i: the
                # body's outward normal there.  Towards the others: own minus theirs.
                normal = 2.0 * gradient[body] - gradient.sum(axis=0)
                length = np.linalg.norm(normal, axis=1)
                usable = present[body, shared] & (length > 0)
                normal = np.divide(normal, length[:, None], out=np.zeros_like(normal), where=length[:, None] > 0)
                relative = trial[body] - centre
                approach = np.einsum("nc,nc->n", relative, normal)
                touching = usable & (approach > 0)
                if not touching.any():
                    continue
                touching &= self._gap(ctx, body, shared, normal, half_spacing) <= tolerance
                normal_part = approach[:, None] * normal
                tangential = relative - normal_part
                slip = np.linalg.norm(tangential, axis=1)
                # Coulomb: the tangential change is at most mu times the normal one
                reduction = np.minimum(mu * approach, slip)
                direction = np.divide(tangential, slip[:, None], out=np.zeros_like(tangential), where=slip[:, None] > 0)
                correction[body] = np.where(touching[:, None], -normal_part - reduction[:, None] * direction, 0.0)
            total = np.zeros_like(ctx.target)
            total[:, shared] = correction
            ctx.work[self.name] = ctx.work.get(self.name, 0.0) + self._work_on_points(ctx, total)
            ctx.target += total / ctx.dt  # a = (corrected v^L - v) / dt

        return resolve

    @staticmethod
    def _work_on_points(ctx: StepContext, correction: np.ndarray) -> float:
        """Kinetic energy the correction gives the points (J per unit thickness).

        A point's FLIP update gains ``dv_p = N_p dv`` (its own body's field)
        on top of ``v_p + dt N_p a``; the work is exactly
        ``sum m_p (v_p^L . dv_p + |dv_p|^2 / 2)``.  (The grid's kinetic energy
        would overstate it many times at nodes with little mass.)
        """
        p, N, work = ctx.particles, ctx.N, 0.0
        for body, members in enumerate(ctx.body_slices):
            rows = N[members]
            change = rows @ correction[body]
            updated = p.v[members] + ctx.dt * (rows @ ctx.target[body])
            work += float(np.sum(p.mass[members, None] * (updated * change + 0.5 * change**2)))
        return work

    @staticmethod
    def _gap(ctx: StepContext, body: int, nodes: np.ndarray, normal: np.ndarray, half_spacing: np.ndarray) -> np.ndarray:
        """Distance between body's surface and the others' along ``normal`` at ``nodes`` (m).

        From the points touching each node: body's outermost point along the
        normal, the others' outermost point against it, less half a point
        spacing on each side.  Nodes without such points get +inf.
        """
        N, p = ctx.N, ctx.particles
        n_local = N.indptr[1] - N.indptr[0]
        point_of_entry = np.repeat(np.arange(N.shape[0]), n_local)
        position = np.full(N.shape[1], -1)
        position[nodes] = np.arange(len(nodes))
        slot = position[N.indices]
        entry = np.flatnonzero((slot >= 0) & (N.data != 0.0))
        slot, point = slot[entry], point_of_entry[entry]
        along = np.einsum("ec,ec->e", p.x[point], normal[slot])
        mine = p.body[point] == body
        front = np.full(len(nodes), -np.inf)
        rest_front = np.full(len(nodes), -np.inf)
        np.maximum.at(front, slot[mine], along[mine])
        np.maximum.at(rest_front, slot[~mine], -along[~mine])
        others = np.flatnonzero(np.arange(len(half_spacing)) != body)
        surfaces = half_spacing[body] + (half_spacing[others].max() if len(others) else 0.0)
        gap = -(front + rest_front) - surfaces
        return np.where(np.isfinite(gap), gap, np.inf)
