"""``particles.pvd`` + ``particles/particles_STEP.vtu``: the points as a ParaView time series."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..step import StepContext
from .series import MeshSeries, collection_text, in_3d

__all__ = ["ParticleSeries", "collection_text"]


@dataclass
class ParticleSeries(MeshSeries):
    """An observer writing the points as a ParaView time series.

    Every record writes ``particles/particles_STEP.vtu`` (VTK unstructured
    grid of vertex cells, binary, zlib) with point data ``velocity`` and
    ``displacement`` (m/s, m; 3 components, z = 0), ``stress_xx``,
    ``stress_yy``, ``stress_xy`` (Pa) and ``body`` (index in scene order);
    ``particles.pvd`` lists the files with their times.  Each file is
    written atomically, so the series is readable whenever the run stops.

    Pass it to :class:`femgrid_mpm.solver.Simulation` among its
    ``observers``; binding touches no file, the first record creates the
    directory.

    Parameters
    ----------
    directory : Path
        The run's output directory.
    flush_seconds : float
        Rewrite ``particles.pvd`` at most this often (see :class:`Throttle`);
        :meth:`close` writes the final one.
    """

    name = "particles"

    def frames(self, simulation):
        import meshio

        vertices = [("vertex", np.arange(simulation.particles.n, dtype=np.int64)[:, None])]

        def particles_mesh(ctx: StepContext):
            p = ctx.particles
            return meshio.Mesh(
                in_3d(p.x),
                vertices,
                point_data={
                    "velocity": in_3d(p.v),
                    "displacement": in_3d(p.x - p.x0),
                    "stress_xx": p.stress[:, 0].copy(),
                    "stress_yy": p.stress[:, 1].copy(),
                    "stress_xy": p.stress[:, 2].copy(),
                    "body": p.body.astype(np.int32),
                },
            )

        return particles_mesh
