"""How much work and how many records a run may make, checked before it starts.

A run of more steps than ``time.max_steps``, or whose records would take
more than ``output.max_bytes``, is a mistake of the scene (a time step in
the wrong unit, ``dt = "auto"`` with a tiny ``safety`` or an absurd
material): it is refused before anything is written or removed, with the
number of steps or bytes and the key that raises the limit.  The steps are
checked by the scene (a given ``dt``) and by ``Simulation`` (``"auto"``);
the records by the command line, for a run that goes to its end.
"""

from __future__ import annotations

import math

#: the default of ``time.max_steps``: at ~10 us a step, 1e9 steps take three hours
MAX_STEPS = 1_000_000_000
#: the default of ``output.max_bytes``: 10 GB of records
MAX_RECORD_BYTES = 10_000_000_000
#: an energy record as held during the run (the row and its line of ``energy.csv``); measured ~0.8 kB
ENERGY_ROW_BYTES = 1000
#: a point in one file of the particle series (positions, velocity, displacement, stress, body, its cell)
POINT_RECORD_BYTES = 120
#: a file of the particle series besides its points (headers, its line in ``particles.pvd``)
FRAME_BYTES = 2000
#: a node in one file of the grid series (position, mass, momentum, velocity, flag, its cell)
NODE_RECORD_BYTES = 100


def step_count(end: float, dt: float, max_steps: int) -> int:
    """The steps to ``end`` with ``dt`` (``ceil(end / dt)``, ignoring a last step shorter
    than 1e-9 of one); raises ValueError if that is more than ``max_steps``."""
    steps = end / dt if dt > 0 else math.inf
    if not steps - 1e-9 <= max_steps:  # also inf and NaN
        count = "infinitely many" if math.isinf(steps) else f"{steps:.3g}"
        raise ValueError(f"dt = {dt:.6g} s to t = {end:g} s would be {count} steps, more than the limit of "
                         f"{max_steps:.3g} (time.max_steps; raise it to run longer)")
    return int(math.ceil(steps - 1e-9))


def record_count(steps: int, every: int) -> int:
    """The records of a run of ``steps`` with one every ``every`` steps: at t = 0, every
    ``every`` steps and at the end."""
    return steps // every + 2


def record_bytes(scene, steps: int, points: int, nodes: int = 0) -> int:
    """About how many bytes the records of ``scene`` take over ``steps`` with ``points``
    (and ``nodes``, for the grid series)."""
    output = scene.output
    if output is None:
        return 0
    records = record_count(steps, output.every)
    size = records * ENERGY_ROW_BYTES if output.energy else 0
    if output.particles:
        size += records * (FRAME_BYTES + POINT_RECORD_BYTES * points)
    if output.grid:
        size += records * (FRAME_BYTES + NODE_RECORD_BYTES * nodes)
    return size


def run_steps(scene, dt: float) -> int:
    """The number of steps a run of ``scene`` with ``dt`` takes.

    Raises
    ------
    ValueError
        ``time.dt: ...`` when the steps exceed ``time.max_steps``, naming the count and the key.
    """
    time = scene.time
    where = (f"dt = \"auto\" ({time.safety:g} x the critical step): " if time.dt == "auto" else "")
    try:
        return step_count(time.end, dt, time.max_steps)
    except ValueError as error:
        raise ValueError(f"time.dt: {where}{error}") from None


def check_records(scene, steps: int, points: int, nodes: int = 0) -> None:
    """Raise ValueError (``output.every: ...``, naming the size and the keys) if the records
    of a whole run of ``steps`` with ``points`` (and ``nodes``) would exceed ``output.max_bytes``.

    A check for a run that goes to its end (the command line's); a simulation built to be
    stepped a few times need not pass it.
    """
    output = scene.output
    size = record_bytes(scene, steps, points, nodes)
    if output is not None and size > output.max_bytes:
        what = " and ".join(name for name, on in (("energy", output.energy), ("particles", output.particles),
                                                  ("grid", output.grid)) if on)
        raise ValueError(
            f"output.every: {record_count(steps, output.every):.3g} records ({what}) of {steps:.3g} steps "
            f"would take about {size / 1e9:.3g} GB, more than output.max_bytes = {output.max_bytes:.3g} "
            "(record less often with a larger output.every, or raise output.max_bytes)")
