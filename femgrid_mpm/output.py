"""The files of a run, written so that a killed or stopped run leaves only valid files.

Every file is written under a temporary name in the same directory and then
renamed over its final name (:func:`atomic_path`): a rename within one file
system is atomic, so a reader, or a run killed at any moment, sees either
the previous complete file or the new complete file, never half of one.
Files that grow during the run (``energy.csv``, ``particles.pvd``) are
rewritten whole at most about once a second (:class:`Throttle`) and once
more when the run ends, also when it stops on a numerical event.

The outputs of a run in ``DIR`` (the contract documented in the README):

``energy.csv``
    One row per record, the first at t = 0: :data:`femgrid_mpm.energy.COLUMNS`
    (``external_work`` only when a force effect is declared).
``final.npz``
    The last state of the points: ``x0, x, v, stress, strain, mass, volume,
    body`` (and ``step``, ``time``).
``summary.json``
    What ran and how it ended; ``status = "running"`` until the end.
``particles.pvd`` + ``particles/particles_STEP.vtu``
    The points as a ParaView time series (when ``[output] particles = true``).
``scene.toml``, ``source_scene.toml``
    The scene as run (overrides applied, every default spelled out) and the
    scene file as given, byte for byte.
``checkpoint.npz``
    With ``--checkpoint-every N``: the whole state every N steps, for
    ``femgrid-mpm resume`` (:mod:`femgrid_mpm.checkpoint`).

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

import contextlib
import json
import math
import os
import re
import tempfile
import time as clock
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from .effects.base import Stage, StepContext
from .observers import COLUMNS

ENERGY_FILE = "energy.csv"
FINAL_FILE = "final.npz"
SUMMARY_FILE = "summary.json"
SCENE_FILE = "scene.toml"
SOURCE_SCENE_FILE = "source_scene.toml"
SERIES_FILE = "particles.pvd"
CHECKPOINT_FILE = "checkpoint.npz"
SERIES_DIRECTORY = "particles"
#: names of one series' point files: ``particles/particles_000120.vtu`` (the step)
SERIES_PATTERN = re.compile(r"^particles_\d+\.vtu$")


# -- atomic files ---------------------------------------------------------------------


@contextlib.contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """A temporary path next to ``path``, renamed to ``path`` when the block ends.

    If the block raises (including ``KeyboardInterrupt``), the temporary file
    is removed and ``path`` keeps its previous content.  The temporary name
    starts with a dot and carries the process id, so concurrent writers and
    directory listings do not mistake it for an output.
    """
    path = Path(path)
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        yield temporary
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            temporary.unlink()
        raise


def probe_writable(directory: Path) -> None:
    """Raise OSError unless a file can be created (and removed) in ``directory``."""
    with tempfile.NamedTemporaryFile(dir=directory, prefix=".femgrid-probe-"):
        pass


def atomic_write(path: Path, data: str | bytes) -> None:
    """Write ``data`` (text as UTF-8) to ``path`` atomically."""
    payload = data.encode() if isinstance(data, str) else data
    with atomic_path(path) as temporary:
        temporary.write_bytes(payload)


@dataclass
class Throttle:
    """When to rewrite a growing file: at most every ``seconds``, and so that
    rewriting takes at most ``1 / cost_ratio`` of the wall time.

    Rewriting the whole file at every record would cost time quadratic in
    the number of records; this bounds it while keeping the file at most
    about a second behind.  The first call is always due; with ``seconds =
    0`` every call is (no throttling).
    """

    seconds: float = 1.0
    cost_ratio: float = 10.0
    last: float = -math.inf
    cost: float = 0.0

    def due(self) -> bool:
        if self.seconds <= 0:
            return True
        return clock.perf_counter() - self.last >= max(self.seconds, self.cost_ratio * self.cost)

    def run(self, write) -> None:
        """Call ``write()`` and remember when and for how long."""
        start = clock.perf_counter()
        write()
        self.last = clock.perf_counter()
        self.cost = self.last - start


# -- energy.csv -------------------------------------------------------------------------


def _number(value: float) -> str:
    """Shortest text that reads back to the same double."""
    return repr(float(value))


@dataclass
class EnergyCsv:
    """``energy.csv``: a header and one row per record, rewritten atomically as rows come.

    Parameters
    ----------
    path : Path
    columns : tuple of str
        Names in :data:`femgrid_mpm.energy.COLUMNS` (J per unit thickness; ``time`` in s).
    flush_seconds : float
        Rewrite at most this often during the run (see :class:`Throttle`);
        :meth:`flush` writes the rest.
    """

    path: Path
    columns: tuple[str, ...]
    flush_seconds: float = 1.0
    lines: list[str] = field(default_factory=list)

    def __post_init__(self):
        self.lines = [",".join(self.columns) + "\n"]
        self.throttle = Throttle(self.flush_seconds)

    def add_row(self, row: dict) -> None:
        """Append one record (a row of :class:`femgrid_mpm.energy.EnergyBookkeeping`)."""
        self.lines.append(self._line(row))
        if self.throttle.due():
            self.throttle.run(self.flush)

    def extend(self, rows: list[dict]) -> None:
        """Append records without writing (a resumed run's records so far)."""
        self.lines.extend(self._line(row) for row in rows)

    def _line(self, row: dict) -> str:
        return ",".join(_number(row[name]) for name in self.columns) + "\n"

    def flush(self) -> None:
        atomic_write(self.path, "".join(self.lines))


# -- the particle series ------------------------------------------------------------------


def _in_3d(values: np.ndarray) -> np.ndarray:
    """(n, 2) -> (n, 3) with z = 0: VTK points and vectors are 3D."""
    return np.column_stack([values, np.zeros(len(values))])


def collection_text(entries: list[tuple[float, str]]) -> str:
    """A ParaView ``.pvd`` collection listing ``(time, file)`` pairs."""
    datasets = "".join(f'    <DataSet timestep="{_number(t)}" group="" part="0" file="{name}"/>\n' for t, name in entries)
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


# -- final.npz, summary.json, scene.toml --------------------------------------------------


def write_final_state(path: Path, particles, step: int, time: float) -> None:
    """``final.npz``: the points' state, atomically.

    Arrays (n points): ``x0``, ``x`` (n, 2) m; ``v`` (n, 2) m/s; ``stress``
    (n, 3) Pa and ``strain`` (n, 3), columns xx, yy, xy (tensor shear);
    ``mass`` (n,) kg per unit thickness; ``volume`` (n,) m^2 per unit
    thickness; ``body`` (n,) int, the body's index in scene order; the
    scalars ``step`` and ``time`` (s) of the state; and, when the particles
    carry it, ``deformation_gradient`` (n, 4): F_xx, F_xy, F_yx, F_yy.
    """
    arrays = {
        "x0": particles.x0,
        "x": particles.x,
        "v": particles.v,
        "stress": particles.stress,
        "strain": particles.strain,
        "mass": particles.mass,
        "volume": particles.volume,
        "body": particles.body,
        "step": np.int64(step),
        "time": np.float64(time),
    }
    gradient = getattr(particles, "deformation_gradient", None)
    if gradient is not None:
        arrays["deformation_gradient"] = gradient
    with atomic_path(path) as temporary, temporary.open("wb") as handle:
        np.savez(handle, **arrays)


def json_safe(value):
    """``value`` with numpy scalars as Python numbers and NaN/inf as strings (strict JSON)."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    return value


def write_summary(path: Path, summary: dict) -> None:
    atomic_write(path, json.dumps(json_safe(summary), indent=2, allow_nan=False) + "\n")


def _toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else _toml_string(key)


def _toml_string(text: str) -> str:
    """A TOML basic string: quotes, backslashes and control characters escaped, every
    other character as itself (an escaped astral character would be a surrogate pair,
    which TOML refuses); a lone surrogate, which no TOML string can hold, becomes U+FFFD."""
    return '"' + "".join(_toml_character(c) for c in text) + '"'


def _toml_character(c: str) -> str:
    if c in '"\\':
        return "\\" + c
    code = ord(c)
    if code < 0x20 or code == 0x7F:
        return f"\\u{code:04x}"
    if 0xD800 <= code <= 0xDFFF:
        return "\ufffd"
    return c


def _toml_comment(text: str) -> str:
    """``text`` fit for a TOML comment: no control character but tab (they are
    written as ``\\uXXXX``), no lone surrogate."""
    return "".join(c if c == "\t" else (_toml_character(c) if c not in '"\\' else c) for c in text)


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + " }" if value else "{}"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def scene_to_toml(scene, header: str = "") -> str:
    """A scene as a TOML scene file that loads back to an equal :class:`~femgrid_mpm.scene.Scene`.

    Every key is written, defaults included.  ``header`` becomes comment lines.
    """
    data = scene.model_dump(mode="json", exclude_none=True)
    lines = [f"# {_toml_comment(line)}".rstrip() for line in header.split("\n")]

    def is_table_array(value) -> bool:
        return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)

    # plain keys first: in TOML, a key after a [table] header belongs to that table
    lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in data.items() if not isinstance(v, dict) and not is_table_array(v)]
    for key, value in data.items():
        if isinstance(value, dict):
            lines += ["", f"[{_toml_key(key)}]"] + [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()]
        elif is_table_array(value):
            for item in value:
                lines += ["", f"[[{_toml_key(key)}]]"] + [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in item.items()]
    return "\n".join(lines) + "\n"


# -- one run's outputs ---------------------------------------------------------------------


def declared_observers(scene, directory: Path, flush_seconds: float = 1.0) -> list:
    """The output effects a scene declares (beyond energy, which the solver owns)."""
    if scene.output is not None and scene.output.particles:
        return [ParticleSeries(Path(directory), flush_seconds)]
    return []


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
        series = directory / SERIES_DIRECTORY
        for place in (directory, series) if series.is_dir() else (directory,):
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
        for name in (ENERGY_FILE, FINAL_FILE, SERIES_FILE, CHECKPOINT_FILE):
            (directory / name).unlink(missing_ok=True)
        if series.is_dir():
            for stale in series.iterdir():
                if SERIES_PATTERN.match(stale.name):
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
            columns = COLUMNS if forced else tuple(c for c in COLUMNS if c != "external_work")
            self.energy = EnergyCsv(self.directory / ENERGY_FILE, columns, self.flush_seconds)
            self.energy.extend(simulation.energy.rows)
            self.energy.flush()  # the header, so the file exists from the start
            simulation.energy.sink = self.energy.add_row

    def state(self) -> dict:
        """What the files of this run need to go on after a checkpoint (JSON):
        where the scene came from, the overrides, the particle series so far."""
        return {
            "scene_file": str(self.source) if self.source is not None else None,
            "overrides": self.overrides,
            "checkpoint_every": self.checkpoint_every,
            "series": [[time, name] for observer in self.observers for time, name in observer.entries],
        }

    @classmethod
    def resumed(cls, directory, scene, state: dict, flush_seconds: float = 1.0) -> "RunOutputs":
        """The outputs of a run in ``directory`` continued from a checkpoint with ``state``
        (:meth:`state`); call :meth:`resume` once the simulation is restored."""
        outputs = cls(directory, scene, source=state["scene_file"], overrides=state["overrides"],
                      flush_seconds=flush_seconds, checkpoint_every=state["checkpoint_every"])
        outputs._series_state = [(float(time), str(name)) for time, name in state["series"]]
        return outputs

    def resume(self, simulation) -> None:
        """Go on writing into the directory of a checkpointed run: the scene files
        stay, ``energy.csv`` and ``particles.pvd`` are rewritten with the records up
        to the checkpoint (a killed run's later records are written again, the same,
        as the run comes to them), and the summary says ``running``.

        Raises
        ------
        OSError
            If the directory cannot be written.
        """
        self.simulation = simulation
        for observer in self.observers:
            observer.entries[:] = self._series_state
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
        names += [SERIES_FILE] if self.observers else []
        names += [FINAL_FILE] if result.status != "running" else []
        # a checkpoint is written every N steps: a run shorter than N has none
        names += [CHECKPOINT_FILE] if self.checkpoint_every and (self.directory / CHECKPOINT_FILE).exists() else []
        summary["files"] = sorted(names)
        return summary
