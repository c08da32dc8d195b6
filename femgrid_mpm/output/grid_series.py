"""``grid.pvd`` + ``grid/grid_STEP.vtu``: the background grid's nodes as a ParaView time series."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..step import StepContext
from .series import MeshSeries, in_3d


def nodal_fields(ctx: StepContext) -> dict[str, np.ndarray]:
    """The grid's nodal fields at a record (after the particle-to-grid pass of its step).

    ``mass`` (kg per unit thickness) is the row sum ``m_I = sum_p N_Ip m_p`` (paper
    Eq. 15): the lumped mass, and the row sums of the consistent matrix, summed over
    the bodies when each has its own field.  It is negative where a basis' functions
    are (q2, serendipity), which is what ``negative_mass`` (1 there, else 0) marks;
    the partition of unity makes the masses sum to the points' mass.  ``momentum``
    (N s) is the grid momentum the step computed (over all bodies), ``velocity``
    (m/s) the grid velocity it moves the points with (supports applied); with one
    field per body, the momentum over the mass on the nodes a body reaches.
    """
    mass = np.array(ctx.mass.lumped, dtype=float)
    momentum, velocity = ctx.momentum, ctx.velocity
    if momentum.ndim == 3:  # one field per body: the total
        momentum = momentum.sum(axis=0)
        velocity = np.zeros_like(momentum)
        np.divide(momentum, mass[:, None], out=velocity, where=ctx.mass.active[:, None] & (mass[:, None] != 0))
    return {
        "mass": mass,
        "momentum": in_3d(momentum),
        "velocity": in_3d(velocity),
        "negative_mass": (mass < 0).astype(np.uint8),
    }


@dataclass
class GridSeries(MeshSeries):
    """An observer writing the grid's nodes as a ParaView time series (``[output] grid = true``).

    Every record writes ``grid/grid_STEP.vtu``, vertex cells at the nodes
    (:attr:`femgrid_mpm.Grid.nodes`: q2's and serendipity's mid-side nodes
    included, the splines' control points) with the point data of
    :func:`nodal_fields`: ``mass``, ``momentum``, ``velocity`` and
    ``negative_mass``; ``grid.pvd`` lists the files with their times, at the
    records of the particle series.

    Parameters
    ----------
    directory : Path
        The run's output directory.
    flush_seconds : float
        Rewrite ``grid.pvd`` at most this often; :meth:`close` writes the final one.
    """

    name = "grid"

    def frames(self, simulation):
        import meshio

        grid = simulation.grid
        points = in_3d(grid.nodes)
        vertices = [("vertex", np.arange(grid.n_nodes, dtype=np.int64)[:, None])]

        def grid_mesh(ctx: StepContext):
            return meshio.Mesh(points, vertices, point_data=nodal_fields(ctx))

        return grid_mesh
