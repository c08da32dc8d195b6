"""``runs.csv``: one row per run of a sweep, from each run's ``summary.json``.

Its columns: the varied keys (as in the sweep file), then :data:`RESULT_COLUMNS`
and :data:`DESCRIPTION_COLUMNS`.  A number is written as the shortest text that
reads back to the same double; a value the run does not have (no reference, a
diagonal mass's CG iterations) is empty.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

from ..output import atomic_write, shortest_text

RUNS_FILE = "runs.csv"

#: what each run measured
RESULT_COLUMNS = ("status", "steps", "points", "nodes", "dt", "wall_time", "error_end", "error_max", "period_error",
                  "energy_drift", "cg_iterations")
#: what describes the run beyond its varied keys: the critical step estimated, the basis,
#: the mass and the spacing run, how many runs ran at once, how it ended, its directory
DESCRIPTION_COLUMNS = ("critical_dt", "basis", "mass", "spacing", "workers", "reason", "run")
NUMBER_COLUMNS = ("steps", "points", "nodes", "dt", "wall_time", "error_end", "error_max", "period_error",
                  "energy_drift", "cg_iterations", "critical_dt", "spacing", "workers")


def row(planned, summary: dict | None, workers: int | None, failure: str | None = None) -> dict:
    """The row of ``planned`` (a :class:`~femgrid_mpm.sweep.spec.PlannedRun`) from its
    ``summary``; ``failure`` for a run that could not be built or run (status ``failed``)."""
    values = {key: text(value) for key, value in planned.varied.items()}
    summary = summary or {}
    reference = summary.get("reference") or {}
    steps = summary.get("steps")
    cg = (summary.get("consistent_mass") or {}).get("cg_iterations")
    measured = {
        "status": "failed" if failure is not None else summary.get("status", ""),
        "steps": steps,
        "points": summary.get("points"),
        "nodes": summary.get("nodes"),
        "dt": summary.get("dt"),
        "wall_time": summary.get("wall_time"),
        "error_end": reference.get("error_end"),
        "error_max": reference.get("error_max"),
        "period_error": reference.get("period_error"),
        "energy_drift": summary.get("energy_drift"),
        # a consistent mass solved directly (up to its node limit) makes no CG iteration: empty, not 0
        "cg_iterations": cg / steps if cg and steps else None,
        "critical_dt": summary.get("critical_dt"),
        "basis": planned.scene.grid.basis,
        "mass": planned.scene.solver.mass,
        "spacing": planned.scene.grid.spacing,
        "workers": workers,
        "reason": failure if failure is not None else summary.get("reason", ""),
        "run": planned.key,
    }
    values.update({column: text(value) for column, value in measured.items()})
    return values


def text(value) -> str:
    """A cell: empty for None, ``true``/``false``, a number as its shortest exact text."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return shortest_text(value) if math.isfinite(value) else str(value)
    return " ".join(str(value).split())


def write_runs(path: Path, varied: list[str], rows: list[dict]) -> None:
    """``runs.csv`` with ``rows`` (from :func:`row`), written atomically."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=[*varied, *RESULT_COLUMNS, *DESCRIPTION_COLUMNS], lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    atomic_write(Path(path), buffer.getvalue())


def read_runs(path: Path) -> tuple[list[str], list[dict]]:
    """The varied keys and the rows of a ``runs.csv``, numbers as floats (None where empty).

    Raises
    ------
    ValueError
        If the file is not a sweep's ``runs.csv``.
    """
    with Path(path).open(newline="") as handle:
        reader = csv.DictReader(handle)
        header = list(reader.fieldnames or [])
        if "status" not in header or any(column not in header for column in RESULT_COLUMNS + DESCRIPTION_COLUMNS):
            raise ValueError(f"{path}: not a sweep's runs.csv (its columns: {', '.join(header) or 'none'})")
        varied = header[: header.index("status")]
        rows = []
        for line, record in enumerate(reader, start=2):
            parsed = dict(record)
            for column in NUMBER_COLUMNS:
                cell = record[column]
                try:
                    parsed[column] = float(cell) if cell not in ("", None) else None
                except ValueError:
                    raise ValueError(f"{path}: line {line}: {column}: not a number ({cell!r})") from None
            rows.append(parsed)
    return varied, rows
