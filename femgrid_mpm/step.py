"""The step's shared state and its stages: what effects and engines read and change.

Stages, in step order (see :meth:`femgrid_mpm.solver.Simulation.advance`):

``observe``
    Read-only, at record steps, once the grid velocities of time ``t`` are
    known: energies, particle output.
``external_force``
    Add forces with ``ctx.add_force(name, f)``; these are order-free sums,
    and the step books each one's work.
``adjust_force``
    Forces that depend on the state or on the total (damping).
``constrain``
    Change a grid field in place: ``ctx.target`` is the grid velocity, then
    the grid acceleration.  Contact comes first, supports last.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np


class Stage(str, enum.Enum):
    OBSERVE = "observe"
    EXTERNAL_FORCE = "external_force"
    ADJUST_FORCE = "adjust_force"
    CONSTRAIN = "constrain"


@dataclass
class StepContext:
    """Everything an effect may read or change during one step.

    Grid fields have shape (n_nodes, 2); particle data lives in
    ``simulation.particles`` (shape (n, ...)).
    """

    simulation: Any  # the femgrid_mpm.solver.Simulation being stepped
    step: int = 0
    time: float = 0.0
    dt: float = 0.0
    #: the instant the step's forces act (s): ``time + dt``, as the stress they are added to
    #: is that of ``time + dt``; ``time`` for the centred scheme's starting half step
    force_time: float = 0.0
    N: Any = None
    dNdx: Any = None
    dNdy: Any = None
    momentum: np.ndarray | None = None
    velocity: np.ndarray | None = None
    #: the frame the step computes in (m/s): grid velocity is frame + relative
    frame_velocity: np.ndarray | None = None
    force: np.ndarray | None = None
    acceleration: np.ndarray | None = None
    target: np.ndarray | None = None
    #: forces added this step by each effect, for the work ledger
    external: dict[str, np.ndarray] = field(default_factory=dict)
    #: cumulative work done by each force effect (J per unit thickness)
    work: dict[str, float] = field(default_factory=dict)

    @property
    def particles(self):
        return self.simulation.particles

    @property
    def grid(self):
        return self.simulation.grid

    @property
    def mass(self):
        return self.simulation.mass

    @property
    def transfer_weights(self):
        """What carries mass, momentum and point forces between points and grid:
        ``N``, or the mass model's own non-negative weights (``mass = "hrz"``,
        :class:`femgrid_mpm.mass.HrzMass`), so that a force on a point acts on the
        grid as the point's momentum does."""
        return self.mass.transfer_weights(self.N)

    #: grid gradient of each body's mass, sum m_p grad N, (n_bodies, n_nodes, 2):
    #: contact normals (one field per body only)
    mass_gradient: np.ndarray | None = None
    #: with one velocity field per body (frictional contact): each body's
    #: contiguous range of points; None for the single shared field
    body_slices: list | None = None

    def add_force(self, name: str, grid_force: np.ndarray) -> None:
        """Add a nodal force (N per unit thickness), shaped like ``force``:
        (n_nodes, 2), or (n_bodies, n_nodes, 2) with one field per body."""
        self.force += grid_force
        if name in self.external:
            self.external[name] = self.external[name] + grid_force
        else:
            self.external[name] = grid_force

    def add_point_forces(self, name: str, forces: np.ndarray, points: np.ndarray | None = None) -> None:
        """Add forces acting on points, ``N.T @ forces`` (``W.T`` with HRZ mass), to each point's own field.

        Parameters
        ----------
        forces : ndarray, shape (n_points, 2) or (len(points), 2)
            Force on each point (N per unit thickness).
        points : ndarray of int, optional
            The points the forces act on (all if omitted): for a few points
            only their rows of ``N`` are touched.
        """
        N = self.transfer_weights
        n_nodes = N.shape[1]
        fields = 1 if self.body_slices is None else len(self.body_slices)
        grid_force = np.zeros((fields, n_nodes, 2))
        if points is None:
            ranges = [slice(0, N.shape[0])] if self.body_slices is None else self.body_slices
            for field_index, members in enumerate(ranges):
                grid_force[field_index] = N[members].T @ forces[members]
        else:
            body = self.particles.body
            for point, force in zip(np.atleast_1d(points), np.atleast_2d(forces)):
                start, stop = N.indptr[point], N.indptr[point + 1]
                field_index = 0 if self.body_slices is None else body[point]
                np.add.at(grid_force[field_index], N.indices[start:stop], np.outer(N.data[start:stop], force))
        self.add_force(name, grid_force[0] if self.body_slices is None else grid_force)


#: what an effect's ``bind`` returns: called at its stage with the step's context
Action = Callable[[StepContext], None]
