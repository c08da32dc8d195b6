"""``energy.csv``: the energy records of a run, one row each."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from .files import Throttle, atomic_write, shortest_text


@dataclass
class EnergyCsv:
    """``energy.csv``: a header and one row per record, rewritten atomically as rows come.

    Parameters
    ----------
    path : Path
    columns : tuple of str
        Names in :data:`femgrid_mpm.observers.COLUMNS` (J per unit thickness; ``time`` in s).
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
        """Append one record (a row of :class:`femgrid_mpm.observers.EnergyBookkeeping`)."""
        self.lines.append(self._line(row))
        if self.throttle.due():
            self.throttle.run(self.flush)

    def extend(self, rows: list[dict]) -> None:
        """Append records without writing (a resumed run's records so far)."""
        self.lines.extend(self._line(row) for row in rows)

    def _line(self, row: dict) -> str:
        return ",".join(shortest_text(row[name]) for name in self.columns) + "\n"

    def flush(self) -> None:
        atomic_write(self.path, "".join(self.lines))
