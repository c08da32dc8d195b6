"""The files of a run, written so that a killed or stopped run leaves only valid files.

Every file is written under a temporary name in the same directory and then
renamed over its final name (:func:`atomic_path`): a rename within one file
system is atomic, so a reader, or a run killed at any moment, sees either
the previous complete file or the new complete file, never half of one.
Files that grow during the run (``energy.csv``, ``particles.pvd``) are
rewritten whole at most about once a second (:class:`Throttle`) and once
more when the run ends, also when it stops on a numerical event.

The outputs of a run in ``DIR`` (the contract documented in docs/outputs.md):

``energy.csv``
    One row per record, the first at t = 0: :data:`femgrid_mpm.observers.COLUMNS`
    (``external_work`` only when a force effect is declared), then
    ``reference_error`` when the scene declares ``[reference]``.
``final.npz``
    The last state of the points: ``x0, x, v, stress, strain, mass, volume,
    body`` (and ``step``, ``time``).
``summary.json``
    What ran and how it ended; ``status = "running"`` until the end.
``particles.pvd`` + ``particles/particles_STEP.vtu``
    The points as a ParaView time series (when ``[output] particles = true``).
``grid.pvd`` + ``grid/grid_STEP.vtu``
    The grid's nodes as a ParaView time series at the same records: nodal mass,
    momentum, velocity, a negative-mass flag (when ``[output] grid = true``).
``scene.toml``, ``source_scene.toml``
    The scene as run (overrides applied, every default spelled out) and the
    scene file as given, byte for byte.
``checkpoint.npz``
    With ``--checkpoint-every N``: the whole state every N steps, for
    ``femgrid-mpm resume`` (:mod:`femgrid_mpm.checkpoint`).

The package's modules: :mod:`~femgrid_mpm.output.files` (the names, atomic
writes), :mod:`~femgrid_mpm.output.energy_csv`,
:mod:`~femgrid_mpm.output.particle_series` and :mod:`~femgrid_mpm.output.grid_series` (both
:class:`~femgrid_mpm.output.series.MeshSeries`), :mod:`~femgrid_mpm.output.results`
(``final.npz``, ``summary.json``) and :mod:`~femgrid_mpm.output.toml_writer`
(``scene.toml``); :class:`RunOutputs`, here, writes them all for one run.

Examples
--------
>>> import tempfile, tomllib
>>> from femgrid_mpm.scene import bundled_scene
>>> scene = bundled_scene("vibrating_bar")
>>> text = scene_to_toml(scene)
>>> type(scene).model_validate(tomllib.loads(text)) == scene
True
>>> directory = Path(tempfile.mkdtemp())
>>> atomic_write(directory / "note.txt", "complete")
>>> (directory / "note.txt").read_text(), sorted(p.name for p in directory.iterdir())
('complete', ['note.txt'])
"""

from __future__ import annotations

import math
from pathlib import Path

from ..step import Stage
from .energy_csv import EnergyCsv
from .files import (
    CHECKPOINT_FILE,
    ENERGY_FILE,
    FINAL_FILE,
    GRID_DIRECTORY,
    GRID_FILE,
    GRID_PATTERN,
    SCENE_FILE,
    SERIES,
    SERIES_DIRECTORY,
    SERIES_FILE,
    SERIES_PATTERN,
    SOURCE_SCENE_FILE,
    SUMMARY_FILE,
    Throttle,
    atomic_path,
    atomic_write,
    probe_writable,
    shortest_text,
)
from .grid_series import GridSeries
from .particle_series import ParticleSeries, collection_text
from .series import is_frame_file
from .results import json_safe, write_final_state, write_summary
from .toml_writer import scene_to_toml

__all__ = [
    "CHECKPOINT_FILE",
    "ENERGY_FILE",
    "FINAL_FILE",
    "GRID_DIRECTORY",
    "GRID_FILE",
    "GRID_PATTERN",
    "SCENE_FILE",
    "SERIES_DIRECTORY",
    "SERIES_FILE",
    "SERIES_PATTERN",
    "SOURCE_SCENE_FILE",
    "SUMMARY_FILE",
    "EnergyCsv",
    "GridSeries",
    "OutputRefused",
    "ParticleSeries",
    "RunOutputs",
    "Throttle",
    "atomic_path",
    "atomic_write",
    "collection_text",
    "declared_observers",
    "json_safe",
    "probe_writable",
    "scene_to_toml",
    "shortest_text",
    "write_final_state",
    "write_summary",
]

class OutputRefused(ValueError):
    """An output directory the run must not write into as it stands; the message is one line."""


def _same_file(first: Path, second: Path) -> bool:
    """Whether two paths name one file (symbolic links resolved, hard links included)."""
    import os

    try:
        return os.path.samefile(first, second)
    except (OSError, ValueError):  # one of them does not exist (or cannot be looked at)
        return False


# RunOutputs lives in the package module itself: it calls the writers by the names
# they have here (femgrid_mpm.output.write_final_state, probe_writable, ...), the
# names a caller sees and may replace (to try a full disk or a read-only directory).


def declared_observers(scene, directory: Path, flush_seconds: float = 1.0) -> list:
    """The output effects a scene declares (beyond energy, which the solver owns):
    the particle series, the grid series; none of them costs anything undeclared."""
    output = scene.output
    if output is None:
        return []
    declared = ((output.particles, ParticleSeries), (output.grid, GridSeries))
    return [series(Path(directory), flush_seconds) for on, series in declared if on]


class RunOutputs:
    """All the files of one run in ``directory``.

    Constructing touches no file, so a run can be checked (and refused) first.
    Then :meth:`start` before the run, :meth:`finish` after it, also when it
    stopped.

    Parameters
    ----------
    directory : Path
    scene : Scene
        The scene as run.
    source : Path, optional
        The scene file it came from (copied verbatim to ``source_scene.toml``).
    overrides : dict, optional
        Dotted keys changed from the file (recorded in the summary).
    flush_seconds : float
        How often growing files are rewritten during the run (see :class:`Throttle`).
    checkpoint_every : int
        Steps between checkpoints (``checkpoint.npz``); 0: none.
    """

    def __init__(self, directory, scene, source=None, overrides=None, flush_seconds: float = 1.0, checkpoint_every: int = 0):
        self.directory = Path(directory)
        self.scene = scene
        self.source = Path(source) if source is not None else None
        self.overrides = dict(overrides or {})
        self.flush_seconds = flush_seconds
        self.checkpoint_every = int(checkpoint_every)
        self.observers = declared_observers(scene, self.directory, flush_seconds)
        self.energy: EnergyCsv | None = None
        self.simulation = None

    def paths(self, starting: bool = True) -> list[Path]:
        """Every path this run writes, replaces or removes in its directory (a resumed
        run, ``starting = False``, keeps its scene files)."""
        directory = self.directory
        names = [ENERGY_FILE, FINAL_FILE, SUMMARY_FILE, CHECKPOINT_FILE, *(collection for collection, _, _ in SERIES)]
        names += [SCENE_FILE, SOURCE_SCENE_FILE] if starting else []
        paths = [directory / name for name in names]
        for _, subdirectory, pattern in SERIES:
            series = directory / subdirectory
            if series.is_dir():
                paths += [path for path in series.iterdir() if pattern.match(path.name)]
        return paths

    def check(self, starting: bool = True) -> None:
        """Raise :class:`OutputRefused` if the run would write over its own scene file, or
        where a directory stands in the place of a file (or a file in that of ``particles/``
        or ``grid/``);
        touches no file.  Called before the run, so that nothing is written or removed then."""
        source = self.source if starting else None
        for path in self.paths(starting):
            if source is not None and _same_file(source, path):
                raise OutputRefused(f"{path}: is the scene file given ({source}): the run would write over it; "
                                    "give another --out directory")
            if path.is_dir():
                raise OutputRefused(f"{path}: is a directory, where the run writes a file")
        for observer in self.observers:
            series = self.directory / observer.name
            if (series.exists() or series.is_symlink()) and not series.is_dir():
                raise OutputRefused(f"{series}: is not a directory, where the run writes its {observer.name} series")

    def start(self, simulation, source_bytes: bytes | None = None) -> None:
        """Create the directory, clear an earlier run's outputs, write the scene and a
        ``running`` summary, and attach ``energy.csv`` to the energy bookkeeping.

        Raises
        ------
        OSError
            If the directory cannot be created or written.
        """
        self.simulation = simulation
        directory = self.directory
        directory.mkdir(parents=True, exist_ok=True)
        # every place this run writes or removes in must take a file before anything is
        # written or removed: a failure then leaves an earlier run's outputs whole
        series = [directory / subdirectory for _, subdirectory, _ in SERIES]
        for place in (directory, *(place for place in series if place.is_dir())):
            probe_writable(place)
        if source_bytes is None and self.source is not None:
            source_bytes = self.source.read_bytes()
        if source_bytes is not None:
            atomic_write(directory / SOURCE_SCENE_FILE, source_bytes)
        header = "The scene as run by femgrid-mpm, every default spelled out"
        if self.source is not None:
            header += f"\nfrom {self.source}"
        if self.overrides:
            header += "\nwith " + ", ".join(f"{k} = {v!r}" for k, v in self.overrides.items())
        atomic_write(directory / SCENE_FILE, scene_to_toml(self.scene, header))
        # An earlier run's files would mix with this run's (more particle
        # files than records, an energy.csv of another scene): remove ours only.
        for name in (ENERGY_FILE, FINAL_FILE, CHECKPOINT_FILE, *(collection for collection, _, _ in SERIES)):
            (directory / name).unlink(missing_ok=True)
        for place, (_, _, pattern) in zip(series, SERIES):
            if place.is_dir():
                for stale in place.iterdir():
                    if pattern.match(stale.name):
                        stale.unlink()
        write_summary(
            directory / SUMMARY_FILE,
            self._summary(simulation.result("running", "the run has not ended (if it stays so, it was killed)"), None),
        )
        self._attach_energy(simulation)

    def _attach_energy(self, simulation) -> None:
        """``energy.csv`` with the records so far (none, or a resumed run's), written
        at once, then fed by the energy bookkeeping."""
        if simulation.energy is not None:
            forced = simulation.effects[Stage.EXTERNAL_FORCE] or simulation.effects[Stage.ADJUST_FORCE]
            columns = tuple(c for c in simulation.energy.columns if forced or c != "external_work")
            self.energy = EnergyCsv(self.directory / ENERGY_FILE, columns, self.flush_seconds)
            self.energy.extend(simulation.energy.rows)
            self.energy.flush()  # the header, so the file exists from the start
            simulation.energy.sink = self.energy.add_row

    def state(self) -> dict:
        """What the files of this run need to go on after a checkpoint (JSON):
        where the scene came from, the overrides, each series' records so far."""
        return {
            "scene_file": str(self.source) if self.source is not None else None,
            "overrides": self.overrides,
            "checkpoint_every": self.checkpoint_every,
            "series": {observer.name: [[time, name] for time, name in observer.entries] for observer in self.observers},
        }

    @classmethod
    def resumed(cls, directory, scene, state: dict, flush_seconds: float = 1.0) -> "RunOutputs":
        """The outputs of a run in ``directory`` continued from a checkpoint with ``state``
        (:meth:`state`); call :meth:`resume` once the simulation is restored."""
        every = state["checkpoint_every"]
        if isinstance(every, bool) or not isinstance(every, int) or every < 1:
            raise ValueError(f"checkpoint_every {every!r} is not a whole number of steps, at least 1")
        outputs = cls(directory, scene, source=state["scene_file"], overrides=state["overrides"],
                      flush_seconds=flush_seconds, checkpoint_every=every)
        series = state["series"]
        if isinstance(series, list):  # a checkpoint of the particle series alone
            series = {ParticleSeries.name: series}
        outputs._series_state = {str(observer): [(float(time), str(name)) for time, name in entries]
                                 for observer, entries in series.items()}
        for observer, entries in outputs._series_state.items():
            for time, name in entries:  # the names go into the .pvd's XML and name the files it reads
                if not (math.isfinite(time) and is_frame_file(observer, name)):
                    raise ValueError(f"series {observer!r}: entry ({time!r}, {name[:80]!r}) is not one it writes")
        return outputs

    def resume(self, simulation) -> None:
        """Go on writing into the directory of a checkpointed run: the scene files
        stay, ``energy.csv`` and each series' ``.pvd`` are rewritten with the records up
        to the checkpoint (a killed run's later records are written again, the same,
        as the run comes to them), and the summary says ``running``.

        Raises
        ------
        OSError
            If the directory cannot be written.
        """
        self.simulation = simulation
        for observer in self.observers:
            observer.entries[:] = self._series_state.get(observer.name, [])
            observer.close()
        write_summary(
            self.directory / SUMMARY_FILE,
            self._summary(simulation.result("running", "the run has not ended (if it stays so, it was killed)"), None),
        )
        self._attach_energy(simulation)

    def finish(self, result, stop=None) -> dict:
        """Write everything that is still pending, ``final.npz`` and ``summary.json``.

        Parameters
        ----------
        result : RunResult
            The run's result (for a stopped run, ``SimulationStopped.result``).
        stop : SimulationStopped, optional
            Why the run stopped.

        Returns
        -------
        dict
            The summary written.
        """
        if self.energy is not None:
            self.energy.flush()
        for observer in self.observers:
            observer.close()
        write_final_state(self.directory / FINAL_FILE, result.particles, self.simulation.step_index, self.simulation.time)
        summary = self._summary(result, stop)
        write_summary(self.directory / SUMMARY_FILE, summary)
        return summary

    def _summary(self, result, stop) -> dict:
        summary = dict(result.summary)
        summary["scene_file"] = str(self.source) if self.source is not None else None
        summary["overrides"] = self.overrides
        if self.energy is not None:
            summary["records"] = len(self.energy.lines) - 1
        else:
            summary["records"] = len(self.observers[0].entries) if self.observers else 0
        summary["stop"] = (
            None if stop is None else {"reason": stop.reason, "step": stop.step, "time": stop.time, "message": str(stop)}
        )
        names = [SCENE_FILE, SUMMARY_FILE]
        names += [SOURCE_SCENE_FILE] if self.source is not None else []
        names += [ENERGY_FILE] if self.energy is not None else []
        # a series whose first record was never taken (a stop at step 0) has no collection
        names += [observer.collection for observer in self.observers if (self.directory / observer.collection).exists()]
        names += [FINAL_FILE] if result.status != "running" else []
        # a checkpoint is written every N steps: a run shorter than N has none
        names += [CHECKPOINT_FILE] if self.checkpoint_every and (self.directory / CHECKPOINT_FILE).exists() else []
        summary["files"] = sorted(names)
        return summary
