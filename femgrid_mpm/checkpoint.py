"""Checkpoints: the whole state of a run in one file, written atomically.

``femgrid-mpm run SCENE --out DIR --checkpoint-every N`` writes
``DIR/checkpoint.npz`` every N steps; ``femgrid-mpm resume DIR`` continues
from it, and the run's final outputs are bit for bit those of a run that
was never interrupted.

What makes that hold:

* The state is everything that carries from one step to the next and
  nothing else (:meth:`femgrid_mpm.solver.Simulation.state`): the points'
  arrays, the step, the work ledger in its order, the energy records and
  their initial values, the runaway guard's bound, the negative-mass
  counters, the mass model's history (CG's warm start), and the output
  writers' lists (:meth:`femgrid_mpm.output.RunOutputs.state`).  The rest
  (grid, materials, effects, engine buffers, the time step, the critical
  step) is rebuilt from the scene saved in ``DIR/scene.toml``, the same way
  as at the start, before the state is put back.
* Numbers keep every bit: arrays are stored as ``.npy`` members, plain
  values as JSON, whose floats are ``repr`` (the shortest text that reads
  back to the same double).
* A checkpoint is taken between steps, where a continued run starts; never
  after the last step, nor at a step where the run came to rest.
* The file is written under a temporary name, flushed to disk and renamed
  over the previous checkpoint (:func:`femgrid_mpm.output.atomic_path`): a
  run killed at any moment, even with SIGKILL while writing, leaves the
  previous complete checkpoint or the new one.
* ``DIR/scene.toml``'s SHA-256 is stored; a checkpoint of another scene, or
  of a scene file edited since, is refused.

File layout (``numpy.load``): one member per array of the state, named as in
``state()`` (``particles.x``, ``energy.rows``, ``mass.previous.velocity.0``,
...), and ``checkpoint`` (uint8): the UTF-8 JSON of the plain values with
``format`` (:data:`FORMAT`), ``scene_sha256``, ``simulation`` and ``outputs``.
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from pathlib import Path

import numpy as np

from .output import CHECKPOINT_FILE, atomic_path

__all__ = ["CHECKPOINT_FILE", "FORMAT", "CheckpointError", "read_checkpoint", "scene_digest", "write_checkpoint"]

#: written into every checkpoint; a different one is refused
FORMAT = "femgrid-mpm checkpoint 2"  # 2: q2 and serendipity nodes numbered along the lattice
_VALUES = "checkpoint"


class CheckpointError(ValueError):
    """A checkpoint that cannot be used: missing, unreadable, or of another scene."""


def scene_digest(path: Path) -> str:
    """SHA-256 of a scene file's bytes (hex)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def write_checkpoint(path: Path, arrays: dict, values: dict) -> None:
    """Write ``arrays`` (name -> ndarray) and ``values`` (JSON-able) to ``path``
    atomically and durably (flushed to disk before the rename)."""
    payload = json.dumps({"format": FORMAT, **values}, allow_nan=True).encode()
    members = {**arrays, _VALUES: np.frombuffer(payload, dtype=np.uint8)}
    if _VALUES in arrays:  # pragma: no cover - a programming error
        raise ValueError(f"{_VALUES!r} is reserved")
    with atomic_path(Path(path)) as temporary:
        with temporary.open("wb") as handle:
            np.savez(handle, **members)
            handle.flush()
            os.fsync(handle.fileno())


def _check_sizes(path: Path) -> None:
    """Raise ValueError unless every array's header claims no more bytes than its member
    holds, and no member more than the file could hold: a damaged header must not
    make the reader allocate what it claims (10^12 elements, 7 TiB)."""
    size = path.stat().st_size
    with zipfile.ZipFile(path) as archive:
        for member in archive.infolist():
            # deflate expands at most ~1032-fold; np.savez stores the members uncompressed
            most = size if member.compress_type == zipfile.ZIP_STORED else 1032 * member.compress_size
            if member.file_size > most:
                raise ValueError(f"member {member.filename} claims {member.file_size} bytes, more than the file holds")
            with archive.open(member) as handle:
                version = np.lib.format.read_magic(handle)
                if version == (1, 0):
                    shape, _, dtype = np.lib.format.read_array_header_1_0(handle)
                else:
                    shape, _, dtype = np.lib.format.read_array_header_2_0(handle)
                header = handle.tell()
            claimed = int(np.prod(shape, dtype=object)) * dtype.itemsize
            if claimed > member.file_size - header:
                raise ValueError(f"member {member.filename}: its header claims shape {shape} of {dtype} "
                                 f"({claimed} bytes), more than the {member.file_size - header} bytes it holds")


def read_checkpoint(path: Path) -> tuple[dict, dict]:
    """``(arrays, values)`` of a checkpoint file.

    Raises
    ------
    CheckpointError
        One line: no such file, not a checkpoint, unreadable or truncated,
        or written by another format.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: no checkpoint here (run with --checkpoint-every N to write one)")
    try:
        _check_sizes(path)
        with np.load(path, allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files}
        values = json.loads(arrays.pop(_VALUES).tobytes().decode())
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, UnicodeDecodeError, RecursionError) as error:
        raise CheckpointError(f"{path}: not a readable checkpoint ({type(error).__name__}: {error})") from None
    if not isinstance(values, dict) or values.get("format") != FORMAT:
        found = values.get("format") if isinstance(values, dict) else None
        raise CheckpointError(f"{path}: not a checkpoint of this version (format {found!r}, expected {FORMAT!r})")
    return arrays, values
