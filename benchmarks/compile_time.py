"""Cold compilation of the numba kernels: what a first run pays before its first step, and where.

Run: ``python benchmarks/compile_time.py`` (``--only q1_lumped`` for one
workload, ``--kernels`` for the compilations of each workload, kernel by
kernel; the ``reproduce`` workload builds every simulation of ``reproduce``,
about 5 CPU minutes cold and warm together).

Each workload runs twice, each time in a fresh process with the same empty
numba cache (``NUMBA_CACHE_DIR``, a temporary directory): the first compiles
every kernel it reaches, the second loads them.  The compile time is the
first minus the second, in wall-clock seconds and in the process' CPU
seconds (compilation is single-threaded, so CPU time is the figure that other
load on a shared machine disturbs least).  The workloads:

* ``q1_lumped``: the vibrating bar (``femgrid_mpm/scenes/vibrating_bar.toml``)
  with q1 and lumped mass, three steps.
* ``bspline3_consistent``: the same bar with cubic B-splines and consistent
  mass, three steps: the README's Python example.
* ``reproduce``: every simulation ``femgrid-mpm reproduce`` makes with its
  defaults (the vibrating bar, cantilever and box impact cases, and every run
  of the cost-accuracy sweeps, which reproduce runs on Dask workers), each cut
  to three steps: the kernels its first run compiles, in one process.

``--kernels`` lists, per workload, every compilation numba reports (its
``numba:compile`` events, :mod:`numba.core.event`) with its CPU seconds: each
kernel with the arguments' types it was specialised for, and indented below
it the helpers and numba's own overloads compiled for it (the helpers compiled with
``forceinline=True`` once for their types, LLVM inlining them; an overload inlined with
``inline="always"`` has no line of its own), and then the kernels compiled again for
types that differ only in memory order or writability (:func:`recompiled`).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile

WORKLOADS = ("q1_lumped", "bspline3_consistent", "reproduce")

#: what a workload's process runs: the workload, then its timings and compilations as JSON
CHILD = r"""
import json, os, sys, time, warnings
warnings.simplefilter("ignore")
wall, cpu = time.perf_counter(), time.process_time()
from numba.core import event
compilations, depth, opened = [], [0], []

class Listener(event.Listener):
    def on_start(self, ev):
        opened.append((time.process_time(), depth[0], len(compilations)))
        compilations.append(None)
        depth[0] += 1

    def on_end(self, ev):
        depth[0] -= 1
        start, level, index = opened.pop()
        dispatcher = ev.data["dispatcher"]
        name = f"{dispatcher.py_func.__module__}.{dispatcher.py_func.__qualname__}"
        compilations[index] = (name, str(ev.data["args"]), time.process_time() - start, level)

event.register("numba:compile", Listener())
sys.path.insert(0, BENCHMARKS)
import compile_time
getattr(compile_time, "workload_" + WORKLOAD)()
print(json.dumps({"wall": time.perf_counter() - wall, "cpu": time.process_time() - cpu,
                  "compilations": compilations}))
"""

#: the shortest compilation ``--kernels`` lists (CPU s)
SHOWN = 0.05
#: steps of every run of a workload: the step's every pass, and a second and third step's paths
STEPS = 3


def _cap_steps() -> None:
    """Every simulation of this process made to stop after :data:`STEPS` steps."""
    from femgrid_mpm.solver import Simulation

    original = Simulation.__init__

    def short(self, *args, **kwargs):
        original(self, *args, **kwargs)
        self.n_steps = min(self.n_steps, STEPS)

    Simulation.__init__ = short


def _run(scene) -> None:
    from femgrid_mpm.diagnostics import SimulationStopped
    from femgrid_mpm.solver import Simulation

    _cap_steps()
    try:
        Simulation(scene).run()
    except SimulationStopped:
        pass


def _bar(basis: str, mass: str):
    from femgrid_mpm.scene import bundled_scene

    return bundled_scene("vibrating_bar").with_overrides(**{"grid.basis": basis, "solver.mass": mass,
                                                           "solver.negative_mass": "warn"})


def workload_q1_lumped() -> None:
    _run(_bar("q1", "lumped"))


def workload_bspline3_consistent() -> None:
    _run(_bar("bspline3", "consistent"))


def workload_reproduce() -> None:
    """The runs of ``femgrid-mpm reproduce``, each cut to :data:`STEPS` steps: the cases
    that run in this process through :func:`femgrid_mpm.reproduce.timing.timed_run`
    (their figures and tables are made from the short runs and are not looked at), and
    the cost-accuracy sweeps' planned runs."""
    import contextlib

    import femgrid_mpm.reproduce.timing as timing
    from femgrid_mpm.reproduce import CASES
    from femgrid_mpm.scene import load_scene
    from femgrid_mpm.solver import Simulation
    from femgrid_mpm.sweep import plan, read_sweep
    from femgrid_mpm.sweep.spec import BUNDLED_SWEEPS
    from femgrid_mpm.reproduce.cost_accuracy import SWEEPS

    _cap_steps()
    with tempfile.TemporaryDirectory() as out:
        for name, case in CASES.items():
            if name == "cost_accuracy":
                continue
            with contextlib.suppress(Exception), contextlib.redirect_stdout(sys.stderr):
                case(os.path.join(out, name))
    for name in SWEEPS:
        path = BUNDLED_SWEEPS / f"{name}.toml"
        for planned in plan(read_sweep(path), path):
            scene = load_scene(planned.scene_file, planned.overrides)
            timing.warm_kernels(scene)
            with contextlib.suppress(Exception):
                Simulation(scene).run()


def measure(workload: str) -> dict:
    """The workload cold and warm, each in a fresh process, with one empty cache."""
    code = f"BENCHMARKS = {os.path.dirname(os.path.abspath(__file__))!r}\nWORKLOAD = {workload!r}\n" + CHILD
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, OPENBLAS_NUM_THREADS="1", MPLBACKEND="Agg")
        cold, warm = (json.loads(subprocess.run([sys.executable, "-c", code], env=env, check=True,
                                                capture_output=True, text=True).stdout.splitlines()[-1])
                      for _ in range(2))
    return {"cold": cold, "warm": warm}


def recompiled(compilations) -> list[str]:
    """The kernels (top-level compilations) compiled more than once for argument types that
    differ only in an array's memory order ('C', 'F', 'A') or read-only flag: a second
    compilation that one layout at the caller would save."""
    seen: dict = {}
    for name, types, _, level in compilations:
        if level == 0:
            plain = re.sub(r"'[CFA]'", "'C'", types).replace("True, aligned", "False, aligned")
            seen.setdefault((name, plain), []).append(types)
    return sorted({f"{name} ({len(variants)}x)" for (name, _), variants in seen.items() if len(variants) > 1})


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", action="append", choices=WORKLOADS, help="this workload (repeatable; default: all)")
    parser.add_argument("--kernels", action="store_true", help="every compilation of each workload, with its seconds")
    parser.add_argument("--json", metavar="FILE", help="also write the measurements to FILE")
    args = parser.parse_args(argv)
    results = {}
    print("| workload | kernels compiled | compile wall (s) | compile CPU (s) | warm run wall (s) |")
    print("|---|---|---|---|---|")
    for workload in args.only or WORKLOADS:
        result = results[workload] = measure(workload)
        cold, warm = result["cold"], result["warm"]
        kernels = sum(1 for c in cold["compilations"] if c[3] == 0)
        print(f"| {workload} | {kernels} | {cold['wall'] - warm['wall']:.1f} "
              f"| {cold['cpu'] - warm['cpu']:.1f} | {warm['wall']:.1f} |", flush=True)
    if args.kernels:
        for workload, result in results.items():
            print(f"\n{workload}: CPU seconds of each compilation, in order, the helpers it compiled "
                  f"indented below it (those above {SHOWN} s)\n")
            for name, types, seconds, level in result["cold"]["compilations"]:
                if seconds > SHOWN:
                    print(f"  {seconds:6.2f}  {'  ' * level}{name}  {types[:120] if level == 0 else ''}")
        for workload, result in results.items():
            again = recompiled(result["cold"]["compilations"])
            print(f"\n{workload}: kernels compiled again for types that differ only in memory order or "
                  f"writability: {', '.join(again) if again else 'none'}")
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(results, handle, indent=1)


if __name__ == "__main__":
    main()
