"""One run of a case: its kernels loaded first, so that its wall time is the run's alone,
and reported to whoever follows the cases (the command line's progress bar).

The first run of a configuration in a process compiles or loads its kernels
(serendipity's lumped bar: 26.8 s cold against 0.29 s warm); the tables' wall
times would then say more about the cache than about the method.  So each run
is preceded by one step of the same scene (same basis, mass, engine, effects
and output, hence the same kernels and signatures) with a tiny step, untimed.
"""

from __future__ import annotations

import contextlib
import time
import warnings
from typing import Callable

from ..diagnostics import SimulationStopped
from ..scene import Scene
from ..solver import RunResult, Simulation

#: the warm-up's one step (s): short enough that nothing happens in it
WARM_STEP = 1e-12

_followers: list[Callable[[str], None]] = []


@contextlib.contextmanager
def following(callback: Callable[[str], None]):
    """Call ``callback(label)`` after every :func:`timed_run` inside the block."""
    _followers.append(callback)
    try:
        yield
    finally:
        _followers.remove(callback)


def warm_kernels(scene: Scene) -> None:
    """Compile or load the kernels a run of ``scene`` uses: one step of ``WARM_STEP`` (its
    warnings, and a stop, are the warm-up's own and dropped)."""
    short = scene.with_overrides(**{"time.dt": WARM_STEP, "time.end": WARM_STEP})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            Simulation(short).run()
        except SimulationStopped:
            pass


def timed_run(scene: Scene, observers: list | None = None, label: str = "") -> tuple[Simulation, RunResult, float]:
    """``(simulation, result, wall seconds of its run)``, its kernels loaded beforehand
    (:func:`warm_kernels`); a stopped run's result is its ``SimulationStopped.result``."""
    warm_kernels(scene)
    simulation = Simulation(scene, observers=observers)
    start = time.perf_counter()
    try:
        result = simulation.run()
    except SimulationStopped as stop:
        result = stop.result
    wall = time.perf_counter() - start
    report_run(label)
    return simulation, result, wall


def report_run(label: str) -> None:
    """Tell whoever follows the cases that one run, ``label``, has ended."""
    for follower in list(_followers):
        follower(label)
