"""A ParaView time series of one mesh per record: ``NAME.pvd`` + ``NAME/NAME_STEP.vtu``.

:class:`MeshSeries` is the observer both series share (the points,
:class:`~femgrid_mpm.output.ParticleSeries`; the grid,
:class:`~femgrid_mpm.output.GridSeries`): each record's file is written
atomically and listed in the ``.pvd`` collection, which is rewritten at most
about once a second and once more at the end, so the series reads whole
whenever the run stops.
"""

from __future__ import annotations

import abc
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ..effects.base import Effect
from ..step import Stage, StepContext
from .files import Throttle, atomic_path, atomic_write, shortest_text


def in_3d(values: np.ndarray) -> np.ndarray:
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


def frame_file(series: str, step: int, digits: int) -> str:
    """The file of one record of a series, relative to the run's directory: ``NAME/NAME_STEP.vtu``."""
    return f"{series}/{series}_{step:0{digits}d}.vtu"


def is_frame_file(series: str, name: str) -> bool:
    """Whether ``name`` is a file :func:`frame_file` makes for ``series`` (a checkpoint's entry
    goes into the .pvd's XML and names a file it reads)."""
    return re.fullmatch(rf"{re.escape(series)}/{re.escape(series)}_\d+\.vtu", name) is not None


@dataclass
class MeshSeries(Effect):
    """An observer writing one VTK unstructured grid per record (binary, zlib).

    Its :attr:`name` names everything it writes in the run's directory:
    ``NAME/NAME_STEP.vtu`` (STEP zero-padded to the digits of the run's
    step count) and ``NAME.pvd``; binding touches no file, the first
    record creates the directory.

    Parameters
    ----------
    directory : Path
        The run's output directory.
    flush_seconds : float
        Rewrite the ``.pvd`` at most this often (see :class:`Throttle`);
        :meth:`close` writes the final one.
    entries : list of (float, str)
        ``(time, file)`` of every record so far (a resumed run's are put back).
    """

    directory: Path
    flush_seconds: float = 1.0
    entries: list[tuple[float, str]] = field(default_factory=list)

    #: the series' name: its directory, its files' prefix, its collection ``NAME.pvd``
    name = "series"
    stage = Stage.OBSERVE

    @property
    def collection(self) -> str:
        """The file name of the ``.pvd`` collection."""
        return f"{self.name}.pvd"

    @abc.abstractmethod
    def frames(self, simulation) -> Callable[[StepContext], object]:
        """Set-up once: a function of the record's context returning its ``meshio.Mesh``."""

    def bind(self, simulation):
        import meshio

        directory = Path(self.directory)
        digits = len(str(simulation.n_steps))
        throttle = Throttle(self.flush_seconds)
        mesh_of = self.frames(simulation)

        def write_frame(ctx: StepContext) -> None:
            (directory / self.name).mkdir(parents=True, exist_ok=True)
            name = frame_file(self.name, ctx.step, digits)
            with atomic_path(directory / name) as temporary:
                meshio.write(temporary, mesh_of(ctx), file_format="vtu")
            self.entries.append((ctx.time, name))
            if throttle.due():
                throttle.run(self.close)

        return write_frame

    def close(self) -> None:
        """Write the ``.pvd`` collection listing every record so far."""
        if self.entries:
            atomic_write(Path(self.directory) / self.collection, collection_text(self.entries))
