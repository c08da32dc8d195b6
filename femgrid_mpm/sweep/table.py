"""``runs.csv``: one row per run of a sweep, from each run's ``summary.json``.

Its columns: the varied keys (as in the sweep file), then :data:`RESULT_COLUMNS`
and :data:`DESCRIPTION_COLUMNS`.  A number is written as the shortest text that
reads back to the same double; a value the run does not have (no reference, a
diagonal mass's CG iterations) is empty.
"""

from __future__ import annotations

import csv
import io
import json
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
    values = {key: value_text(value) for key, value in planned.varied.items()}
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


def value_text(value) -> str:
    """A varied key's cell: :func:`text`, but distinct for distinct values (the report groups by
    it): a string that is not one line of single spaces, or that starts with a double quote, is
    written as its JSON (``"a  b"`` with its two spaces, ``"a\\nb"``)."""
    if isinstance(value, str) and (value.startswith('"') or value != " ".join(value.split())):
        return json.dumps(value)
    return text(value)


def write_runs(path: Path, varied: list[str], rows: list[dict]) -> None:
    """``runs.csv`` with ``rows`` (from :func:`row`), written atomically."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=[*varied, *RESULT_COLUMNS, *DESCRIPTION_COLUMNS], lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    atomic_write(Path(path), buffer.getvalue())


#: the largest runs.csv read (a row is about 300 bytes: a million runs)
MAX_RUNS_BYTES = 2**30
STATUSES = ("completed", "stopped", "failed")
#: what a number of a column must be: > 0 (finite), a whole number >= 0, >= 0; the others finite
POSITIVE_COLUMNS = ("dt", "spacing", "workers")
COUNT_COLUMNS = ("steps", "points", "nodes")
#: the report's axes, which it sorts and draws the runs along: a row's spacing is its scene's, and a
#: run that ran (all but a failed one) has its time step
AXIS_COLUMNS = ("spacing", "dt")
#: may be non-finite in a run that did not complete (a state that blew up); never negative
ERROR_COLUMNS = ("error_end", "error_max", "cg_iterations")
#: the critical step is infinite or not positive when no step is stable or none is limited;
#: a drift or a period's error of either sign, non-finite when the energy or the period is 0
FREE_COLUMNS = ("critical_dt", "period_error", "energy_drift")


def read_runs(path: Path) -> tuple[list[str], list[dict]]:
    """The varied keys and the rows of a ``runs.csv``, numbers as floats (None where empty).

    Raises
    ------
    ValueError
        One line naming the file and the line: not a sweep's ``runs.csv`` (its columns), not
        UTF-8 text, a row of the wrong number of fields, an unknown status, a number that does
        not read or is out of its range (a wall time or a spacing that is not positive and
        finite, a count that is not a whole number).
        One that cannot be read too (a FIFO or a device is refused unread, as a scene file).
    """
    from ..reading import read_regular_file

    path = Path(path)
    try:
        data = read_regular_file(path, MAX_RUNS_BYTES)
    except OSError as error:
        raise ValueError(f"{path}: cannot be read: {error.strerror or error}") from None
    try:
        content = data.decode()
    except UnicodeDecodeError as error:
        line = data[: error.start].count(b"\n") + 1
        raise ValueError(f"{path}: line {line}: not UTF-8 text (byte {data[error.start]:#04x})") from None
    # a byte-order mark (a spreadsheet's "UTF-8 with BOM") is not part of the first column's name
    reader = csv.reader(io.StringIO(content.removeprefix("\ufeff"), newline=""))
    try:
        header = next(reader, [])
        if "status" not in header or any(column not in header for column in RESULT_COLUMNS + DESCRIPTION_COLUMNS):
            shown = ", ".join(header)[:200] or "none"
            raise ValueError(f"{path}: not a sweep's runs.csv (its columns: {shown})")
        twice = next((column for column in header if header.count(column) > 1), None)
        if twice is not None:  # a varied key named like a result column: the report would read the wrong one
            raise ValueError(f"{path}: not a sweep's runs.csv (the column {twice!r} twice)")
        varied = header[: header.index("status")]
        rows = [parsed_row(path, reader.line_num, header, record) for record in reader if record]
    except csv.Error as error:
        raise ValueError(f"{path}: line {reader.line_num}: not CSV: {error}") from None
    return varied, rows


def parsed_row(path: Path, line: int, header: list[str], record: list[str]) -> dict:
    """One row of ``runs.csv`` as a dict, numbers as floats, checked (see :func:`read_runs`)."""
    if len(record) != len(header):
        raise ValueError(f"{path}: line {line}: has {len(record)} fields, expected {len(header)}")
    parsed = dict(zip(header, record))
    if parsed["status"] not in STATUSES:
        raise ValueError(f"{path}: line {line}: status: {parsed['status'][:40]!r} is not one of {', '.join(STATUSES)}")
    for column in NUMBER_COLUMNS:
        cell = parsed[column]
        if cell == "":
            if column in AXIS_COLUMNS and (column == "spacing" or parsed["status"] != "failed"):
                raise ValueError(f"{path}: line {line}: {column}: is empty (a {parsed['status']} run has one)")
            parsed[column] = None
            continue
        try:
            value = float(cell)
        except ValueError:
            raise ValueError(f"{path}: line {line}: {column}: not a number ({cell[:40]!r})") from None
        problem = number_problem(column, value, parsed["status"])
        if problem:
            raise ValueError(f"{path}: line {line}: {column}: {problem} (got {cell[:40]})")
        parsed[column] = value
    return parsed


def number_problem(column: str, value: float, status: str) -> str | None:
    """What is wrong with ``value`` in ``column`` of a row of ``status``, or None."""
    if column in FREE_COLUMNS:
        return None if not math.isnan(value) else "must be a number"
    if column in ERROR_COLUMNS:
        if math.isnan(value) or math.isinf(value):
            return None if status != "completed" else "must be finite in a completed run"
        return "must not be negative" if value < 0 else None
    if not math.isfinite(value):
        return "must be finite"
    if (column in POSITIVE_COLUMNS or (column == "wall_time" and status == "completed")) and value <= 0:
        return "must be positive"
    if column == "wall_time" and value < 0:
        return "must not be negative"
    if column in COUNT_COLUMNS and (value < 0 or not value.is_integer()):
        return "must be a whole number, at least 0"
    return None


def run_failure(error: Exception, local: bool = True) -> str:
    """A run's failure, as its row says it.  A run whose workers all ended under it (Dask tries it
    on others first) says the likely cause: a local worker is ended at 95% of its share of the
    memory, the machine's over the workers; a ``--scheduler``'s (``local`` false) at its own
    ``--memory-limit`` (``--workers`` is refused there)."""
    from dask.distributed import KilledWorker

    if isinstance(error, KilledWorker) and not local:
        return ("KilledWorker: each worker that ran it ended while running it (more memory than a worker's "
                "--memory-limit, or a crash); workers with more memory each can run it")
    if isinstance(error, KilledWorker):
        return ("KilledWorker: each worker that ran it ended while running it (more memory than a worker's share, "
                "the machine's over --workers, or a crash); fewer --workers give each more")
    return f"{type(error).__name__}: {error}"
