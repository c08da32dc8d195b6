"""The names of a run's files, and writing a file so that a reader never sees half of it
(:func:`atomic_path`; see :mod:`femgrid_mpm.output`)."""

from __future__ import annotations

import contextlib
import math
import os
import re
import tempfile
import time as clock
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

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
GRID_FILE = "grid.pvd"
GRID_DIRECTORY = "grid"
#: names of the grid series' files: ``grid/grid_000120.vtu`` (the step)
GRID_PATTERN = re.compile(r"^grid_\d+\.vtu$")
#: every series a run may write: its collection, its directory, the names of its files
SERIES = ((SERIES_FILE, SERIES_DIRECTORY, SERIES_PATTERN), (GRID_FILE, GRID_DIRECTORY, GRID_PATTERN))


@contextlib.contextmanager
def atomic_path(path: Path, keep_suffix: bool = False) -> Iterator[Path]:
    """A temporary path next to ``path``, renamed to ``path`` when the block ends (ending in
    ``path``'s suffix with ``keep_suffix``: image writers choose the format by it).

    If the block raises (including ``KeyboardInterrupt``), the temporary file
    is removed and ``path`` keeps its previous content.  The temporary name
    starts with a dot and carries the process id, so concurrent writers and
    directory listings do not mistake it for an output.
    """
    path = Path(path)
    temporary = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}" if keep_suffix
                               else f".{path.name}.{os.getpid()}.tmp")
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


def shortest_text(value: float) -> str:
    """Shortest text that reads back to the same double."""
    return repr(float(value))
