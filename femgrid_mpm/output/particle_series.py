"""``particles.pvd`` + ``particles/particles_STEP.vtu``: the points as a ParaView time series."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..step import Stage, StepContext
from .files import SERIES_DIRECTORY, SERIES_FILE, Throttle, atomic_path, atomic_write, shortest_text


def _in_3d(values: np.ndarray) -> np.ndarray:
    """(n, 2) -> (n, 3) with z = 0: VTK points and vectors are 3D."""
    return np.column_stack([values, np.zeros(len(values))])


def collection_text(entries: list[tuple[float, str]]) -> str:
    """A ParaView ``.pvd`` collection listing ``(time, file)`` pairs."""
    datasets = "".join(f'    <DataSet timestep="{shortest_text(t)}" group="" part="0" file="{name}"/>\n' for t, name in entries)
    return (
        '<?xml version="1.0"?>\n'
        '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
        "  <Collection>\n" + datasets + "  </Collection>\n</VTKFile>\n"
    )


@dataclass
class ParticleSeries:
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

    directory: Path
    flush_seconds: float = 1.0
    entries: list[tuple[float, str]] = field(default_factory=list)

    name = "particles"
    stage = Stage.OBSERVE

    def bind(self, simulation):
        import meshio

        directory = Path(self.directory)
        digits = len(str(simulation.n_steps))
        vertices = [("vertex", np.arange(simulation.particles.n, dtype=np.int64)[:, None])]
        throttle = Throttle(self.flush_seconds)

        def write_particles(ctx: StepContext) -> None:
            p = ctx.particles
            (directory / SERIES_DIRECTORY).mkdir(parents=True, exist_ok=True)
            name = f"{SERIES_DIRECTORY}/particles_{ctx.step:0{digits}d}.vtu"
            mesh = meshio.Mesh(
                _in_3d(p.x),
                vertices,
                point_data={
                    "velocity": _in_3d(p.v),
                    "displacement": _in_3d(p.x - p.x0),
                    "stress_xx": p.stress[:, 0].copy(),
                    "stress_yy": p.stress[:, 1].copy(),
                    "stress_xy": p.stress[:, 2].copy(),
                    "body": p.body.astype(np.int32),
                },
            )
            with atomic_path(directory / name) as temporary:
                meshio.write(temporary, mesh, file_format="vtu")
            self.entries.append((ctx.time, name))
            if throttle.due():
                throttle.run(self.close)

        return write_particles

    def close(self) -> None:
        """Write ``particles.pvd`` listing every record so far."""
        if self.entries:
            atomic_write(Path(self.directory) / SERIES_FILE, collection_text(self.entries))
