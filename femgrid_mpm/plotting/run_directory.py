"""A run's directory read back for pictures: its records, the points at each, its energies.

Everything a run writes is read here and checked as it is read; a
directory that is not a run, or a file that does not read as what the run
writes, raises :class:`RunUnreadable` with one line naming the file and
what is wrong (a killed or stopped run is a run: its files are whole).
"""

from __future__ import annotations

import json
import tomllib
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..output.files import ENERGY_FILE, FINAL_FILE, SCENE_FILE, SERIES_FILE, SUMMARY_FILE
from ..reading import read_regular_file

#: the fields the points can be coloured by: name -> unit
FIELDS = {
    "velocity": "m/s",
    "velocity_x": "m/s",
    "velocity_y": "m/s",
    "displacement": "m",
    "displacement_x": "m",
    "displacement_y": "m",
    "stress_xx": "Pa",
    "stress_yy": "Pa",
    "stress_xy": "Pa",
    "body": "index in scene order",
}
#: the largest file read whole (energy.csv of ~10^6 records, the summary, the collection)
MAX_TEXT_BYTES = 2**30


class RunUnreadable(ValueError):
    """A directory that is not a run, or one of its files unreadable; the message is one line."""


@dataclass(frozen=True)
class Frame:
    """The points at one record: positions ``x`` and initial positions ``x0`` (n, 2) m,
    the time (s), and every field of :data:`FIELDS`, shape (n,) each."""

    time: float
    x: np.ndarray
    x0: np.ndarray
    fields: dict[str, np.ndarray]


def _vectors(prefix: str, values: np.ndarray) -> dict[str, np.ndarray]:
    return {prefix: np.hypot(values[:, 0], values[:, 1]), f"{prefix}_x": values[:, 0], f"{prefix}_y": values[:, 1]}


def frame_of(time: float, x, v, x0, stress, body) -> Frame:
    """A :class:`Frame` from the arrays a run writes (z components dropped); ValueError (a damaged
    file's, :class:`RunUnreadable` from its reader) for no points, arrays of other lengths or a
    position that is not finite."""
    arrays = [(name, np.asarray(a, dtype=float), k) for name, a, k in
              (("positions", x, 2), ("velocities", v, 2), ("initial positions", x0, 2), ("stresses", stress, 3))]
    for name, array, k in arrays:
        if array.ndim != 2 or array.shape[1] < k:
            raise ValueError(f"{name} of shape {array.shape}: not the points of a run ({k} components each)")
    x, v, x0, stress = (array[:, :k] for _, array, k in arrays)
    if len(x) == 0 or any(len(a) != len(x) for a in (v, x0, stress, np.asarray(body))):
        raise ValueError(f"{len(x)} positions, {len(v)} velocities, {len(x0)} initial positions, {len(stress)} "
                         f"stresses, {len(np.asarray(body))} body numbers: not the points of a run")
    if not (np.isfinite(x).all() and np.isfinite(x0).all()):  # a run's guards stop before writing one
        bad = int(np.flatnonzero(~(np.isfinite(x).all(axis=1) & np.isfinite(x0).all(axis=1)))[0])
        raise ValueError(f"point {bad}: a position that is not finite ({x[bad].tolist()}, from {x0[bad].tolist()}): "
                         "not the points of a run")
    fields = {**_vectors("velocity", v), **_vectors("displacement", x - x0),
              "stress_xx": stress[:, 0], "stress_yy": stress[:, 1], "stress_xy": stress[:, 2],
              "body": np.asarray(body, dtype=float)}
    return Frame(float(time), x, x0, fields)


@dataclass
class RunDirectory:
    """The files of one run, checked: see :meth:`open`.

    Attributes
    ----------
    records : list of (float, Path)
        The particle series' ``(time, file)``; without one, the final state alone
        (``final.npz``).
    box : (lower, upper, step) or None
        The grid's domain (m) and its lattice spacing, from ``scene.toml``.
    bodies : list of str
        The bodies' names in scene order.
    """

    path: Path
    summary: dict = field(default_factory=dict)
    records: list[tuple[float, Path]] = field(default_factory=list)
    energy: Path | None = None
    box: tuple[np.ndarray, np.ndarray, float] | None = None
    bodies: list[str] = field(default_factory=list)
    title: str = ""

    @classmethod
    def open(cls, path) -> "RunDirectory":
        """The run in ``path``; raises :class:`RunUnreadable` for a directory that is not
        one (missing, a file, no outputs) or whose summary, scene or collection do not read."""
        path = Path(path)
        try:
            if not path.exists():
                raise RunUnreadable(f"{path}: no such directory")
            if not path.is_dir():
                raise RunUnreadable(f"{path}: is not a directory (give the --out directory of femgrid-mpm run)")
            present = {name: (path / name).is_file() for name in (SERIES_FILE, FINAL_FILE, ENERGY_FILE, SUMMARY_FILE)}
        except OSError as error:  # e.g. a name longer than the file system allows
            raise RunUnreadable(f"{path}: cannot be used: {error.strerror or error}") from None
        if not (present[SERIES_FILE] or present[FINAL_FILE] or present[ENERGY_FILE]):
            raise RunUnreadable(f"{path}: is not the directory of a run (no {SERIES_FILE}, {FINAL_FILE} or "
                                f"{ENERGY_FILE}; give the --out directory of femgrid-mpm run)")
        run = cls(path)
        if present[SUMMARY_FILE]:
            summary = _parsed(path / SUMMARY_FILE, json.loads, "JSON")
            if not isinstance(summary, dict):
                raise RunUnreadable(f"{path / SUMMARY_FILE}: is not a run's summary (not a JSON object)")
            run.summary = summary
        if (path / SCENE_FILE).is_file():
            run._read_scene(_parsed(path / SCENE_FILE, tomllib.loads, "TOML"))
        if present[SERIES_FILE]:
            run.records = _collection(path, path / SERIES_FILE)
        elif present[FINAL_FILE]:
            run.records = [(float("nan"), path / FINAL_FILE)]
        run.energy = path / ENERGY_FILE if present[ENERGY_FILE] else None
        return run

    def _read_scene(self, scene: dict) -> None:
        from ..bases import BASES

        where = self.path / SCENE_FILE
        try:
            grid = scene["grid"]
            lower, upper = np.array(grid["lower"], dtype=float), np.array(grid["upper"], dtype=float)
            spacing = float(grid["spacing"])
            width = spacing * BASES[grid["basis"]].cells_per_element
            # the grid ends on whole elements, as femgrid_mpm.Grid lays it
            elements = np.maximum(1, np.ceil((upper - lower) / width - 1e-9))
            self.box = (lower, lower + elements * width, spacing)
            self.bodies = [str(body["name"]) for body in scene.get("bodies", [])]
            self.title = str(scene.get("title", ""))
        except (KeyError, TypeError, ValueError, IndexError) as error:
            raise RunUnreadable(f"{where}: is not a scene written by femgrid-mpm run ({type(error).__name__}: {error})") from None
        if lower.shape != (2,) or upper.shape != (2,) or not np.all(np.isfinite(self.box[1])) or not spacing > 0:
            raise RunUnreadable(f"{where}: grid: lower, upper and spacing do not describe a 2D grid")

    # -- the points -------------------------------------------------------------------

    def record_index(self, record: int | str) -> int:
        """The index of ``record`` (a number from 0, or ``"last"``) among :attr:`records`."""
        count = len(self.records)
        if count == 0:
            raise RunUnreadable(f"{self.path / SERIES_FILE}: lists no records yet")
        if record == "last":
            return count - 1
        if not 0 <= int(record) < count:
            which = f"0 to {count - 1}, or last" if count > 1 else "0, or last"
            source = "records" if self.series else "record (the final state: the run wrote no particle series)"
            raise RunUnreadable(f"--record {record}: the run in {self.path} has {count} {source} ({which})")
        return int(record)

    @property
    def series(self) -> bool:
        """Whether the records are a particle series (else the final state alone)."""
        return not (len(self.records) == 1 and self.records[0][1].name == FINAL_FILE)

    def frame(self, index: int) -> Frame:
        """The points at record ``index`` (of :attr:`records`)."""
        time, file = self.records[index]
        if file.name == FINAL_FILE and not self.series:
            return _final_frame(file)
        return _series_frame(time, file)


def _text(file: Path) -> str:
    try:
        return read_regular_file(file, MAX_TEXT_BYTES).decode()
    except OSError as error:
        raise RunUnreadable(f"{file}: cannot be read: {error.strerror or error}") from None
    except UnicodeDecodeError:
        raise RunUnreadable(f"{file}: is not text (damaged?)") from None


def _parsed(file: Path, parse, kind: str):
    text = _text(file)
    try:
        return parse(text)
    except (ValueError, RecursionError) as error:  # json and tomllib errors are ValueErrors
        raise RunUnreadable(f"{file}: is not valid {kind} (damaged?): {' '.join(str(error).split())}") from None


def _collection(directory: Path, file: Path) -> list[tuple[float, Path]]:
    """The ``(time, file)`` pairs a ParaView ``.pvd`` collection lists (files not opened yet)."""
    try:
        root = ElementTree.fromstring(_text(file))
        entries = [(float(item.attrib["timestep"]), directory / item.attrib["file"]) for item in root.iter("DataSet")]
    except (ElementTree.ParseError, KeyError, ValueError) as error:
        raise RunUnreadable(f"{file}: is not a ParaView collection (damaged?): {' '.join(str(error).split())}") from None
    return entries


def _final_frame(file: Path) -> Frame:
    try:
        with np.load(file, allow_pickle=False) as arrays:
            return frame_of(float(arrays["time"]), arrays["x"], arrays["v"], arrays["x0"], arrays["stress"], arrays["body"])
    except OSError as error:
        raise RunUnreadable(f"{file}: cannot be read: {error.strerror or error}") from None
    except Exception as error:  # a damaged archive raises whatever its reader meets (zip, pickle, shapes)
        raise RunUnreadable(f"{file}: is not the final state of a run (damaged?): {type(error).__name__}: "
                            f"{' '.join(str(error).split())}") from None


#: the point data of a particle file, and the columns read of each
SERIES_ARRAYS = {"velocity": 2, "displacement": 2, "stress_xx": 1, "stress_yy": 1, "stress_xy": 1, "body": 1}


def _series_frame(time: float, file: Path) -> Frame:
    import meshio

    try:
        if not file.is_file():
            raise RunUnreadable(f"{file}: is missing (listed in {SERIES_FILE})")
        mesh = meshio.vtu.read(str(file))  # (meshio.read prints and exits on a damaged file)
    except RunUnreadable:
        raise
    except OSError as error:
        raise RunUnreadable(f"{file}: cannot be read: {error.strerror or error}") from None
    except Exception as error:  # a damaged file raises whatever its XML, base64 or zlib reader meets
        detail = " ".join(str(error).split()) or "does not parse"
        raise RunUnreadable(f"{file}: is not a VTK particle file (damaged?): {type(error).__name__}: {detail}") from None
    data, n = mesh.point_data, len(mesh.points)
    for name, columns in SERIES_ARRAYS.items():
        values = data.get(name)
        if values is None or len(values) != n or (columns > 1 and (values.ndim != 2 or values.shape[1] < columns)):
            raise RunUnreadable(f"{file}: has no point data {name!r} of {n} points (not a particle file of femgrid-mpm run)")
    x = mesh.points[:, :2]
    stress = np.column_stack([data["stress_xx"], data["stress_yy"], data["stress_xy"]])
    try:
        return frame_of(time, x, data["velocity"], x - data["displacement"][:, :2], stress, data["body"])
    except ValueError as error:
        raise RunUnreadable(f"{file}: {error} (damaged?)") from None


def energy_table(file: Path) -> dict[str, np.ndarray]:
    """``energy.csv`` as one array per column (the names of its header), its rows checked."""
    lines = _text(file).splitlines()
    if not lines or "time" not in (columns := lines[0].split(",")):
        raise RunUnreadable(f"{file}: is not a run's energy record (its header has no 'time' column)")
    rows = []
    for number, line in enumerate(lines[1:], start=2):
        values = line.split(",")
        try:
            if len(values) != len(columns):
                raise ValueError(f"{len(values)} values, the header has {len(columns)} columns")
            rows.append([float(value) for value in values])
        except ValueError as error:
            raise RunUnreadable(f"{file}: line {number} is not a row of numbers (damaged?): {error}") from None
    table = np.array(rows, dtype=float).reshape(len(rows), len(columns))
    # beyond 1e300 a value cannot be drawn (the axis' span overflows): left out like a NaN
    table[np.abs(table) > 1e300] = np.nan
    return {name: table[:, index] for index, name in enumerate(columns)}
