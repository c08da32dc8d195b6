"""One run of a case: its kernels loaded first, so that its wall time is the run's alone,
and reported to whoever follows the cases (the command line's progress bar).

The first run of a configuration in a process compiles or loads its kernels
(serendipity's lumped bar: 26.8 s cold against 0.29 s warm); the tables' wall
times would then say more about the cache than about the method.  So each run
is preceded by one step of the same scene (same basis, mass, engine, effects
and output, hence the same kernels and signatures) with a tiny step, untimed.

On a cold cache those warm-ups are where the compilation happens, one kernel after
the other in one process; :func:`warm_in_parallel` spreads the warm-ups of all the
runs to come over a process per core first (numba compiles in one thread), and the
runs then load what those processes cached.
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing
import os
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
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
    for follower in list(_followers):
        follower(label)
    return simulation, result, wall


def kernel_key(scene: Scene) -> str:
    """What of ``scene`` decides which kernels its run compiles: all of it but its title,
    times, output and grid spacing (which change sizes, not types)."""
    settings = scene.model_dump(mode="json", exclude={"title", "time", "output"})
    settings["grid"].pop("spacing")
    return json.dumps(settings, sort_keys=True)


def shares(scenes: list[Scene]) -> list[list[Scene]]:
    """One scene per :func:`kernel_key`, in one share per basis (a basis' transfer kernels
    are compiled in one process only), the largest shares first."""
    groups: dict[str, dict[str, Scene]] = {}
    for scene in scenes:
        groups.setdefault(scene.grid.basis, {}).setdefault(kernel_key(scene), scene)
    return sorted((list(group.values()) for group in groups.values()), key=len, reverse=True)


def _warm_share(share: list[Scene]) -> None:
    """One process' warm-ups (a scene that fails to start is the run's to report)."""
    for scene in share:
        with contextlib.suppress(Exception):
            warm_kernels(scene)


def warm_in_parallel(scenes: list[Scene], processes: int | None = None) -> int:
    """Compile the kernels of the runs of ``scenes`` in ``processes`` processes at once (default:
    the cores), each taking the next of the :func:`shares` when it has warmed up the last
    into the kernel cache, which :func:`femgrid_mpm.kernels.compiled.locked_save` keeps
    consistent under concurrent writes; returns the number of processes (1: nothing
    done, the runs compile as they go)."""
    dealt = shares(scenes)
    processes = min(processes or os.cpu_count() or 1, len(dealt))
    if processes < 2:
        return 1
    # spawn: a fork of this process would copy its threads' state (numba's, Dask's)
    with ProcessPoolExecutor(processes, mp_context=multiprocessing.get_context("spawn")) as pool:
        for _ in pool.map(_warm_share, dealt):  # one share at a time to whichever process is free
            pass
    return processes
