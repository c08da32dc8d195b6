"""What consistent mass costs against lumped mass: per step, and to the same end time.

Run: ``python benchmarks/consistent_cost.py`` (about 10 minutes on 2 shared cores;
``--quick``: 1e3 and 1e4 points; ``--sizes 1000`` and ``--bases q1,bspline3`` choose;
``--set solver.weak_ratio=0.5`` sets a key of the consistent runs' scenes, e.g. the weak rows'
treatment of docs/time_step.md).

For each size and basis, on :func:`step.block_scene`'s block (2 x 2 points per
cell, the vibrating bar's cosine velocity, its own step ``0.1 h / c``):

* per step: the median time of a consistent step (default ``linear_solver =
  "auto"``), of a lumped one, and of a consistent one factored every step
  (``"direct"``), the fastest of :data:`step.ROUNDS` bursts that go
  round all the size's cases (:func:`step.fastest`), and their ratio;
* to the same end time: the same block with ``dt = "auto"`` (each mass's own
  critical step, which is smaller for consistent mass) run to :data:`TRANSITS`
  times a cell's wave transit time ``h / c`` for every basis, the steps and wall
  time of ``run()`` of each mass and their ratios (consistent over lumped), and
  the set-up before it (``Simulation(scene)``, the estimate of the critical step
  most of it), apart: each the fastest of :data:`REPEATS` runs, consistent and
  lumped in turn (a single run's lumped side, 0.01-0.3 s at 1e3-1e4 points,
  varied enough to move q1's wall ratio between 7.7x and 11.8x over runs), or of
  one where the consistent run took more than :data:`REPEAT_WITHIN` seconds.

The machine is shared: quote the ratios, which interleaving keeps steadier than
the times.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from step import block_scene, fastest  # noqa: E402

from femgrid_mpm.diagnostics import SimulationStopped  # noqa: E402
from femgrid_mpm.solver import Simulation  # noqa: E402

BASES = ("q1", "q2", "serendipity", "bspline3", "gimp", "bspline2")
SIZES = (1_000, 10_000, 100_000)
#: the end time of the runs to the same end time, in a cell's wave transit times h / c
TRANSITS = 100
#: steps a case must run at the block's step before it is timed: with "auto", the kept factors'
#: first window and CG's trial against them (femgrid_mpm.mass.layout.CgTrial), 20 steps each
TRIAL_STEPS = 45
#: the runs to the same end time: the fastest of this many of each mass ...
REPEATS = 3
#: ... but one where the first consistent run and its set-up took more than this many seconds (at
#: 1e5 points q2's take ~10 s, gimp's ~21 s, cubic splines' ~42 s; at 1e4 quadratic splines' ~22 s)
REPEAT_WITHIN = 15.0
WAVE_SPEED = float(np.sqrt(1e4 * 0.7 / (1.3 * 0.4) / 1e3))  # the block's p-wave speed (step.block_scene)


def per_step(bases, n: int, budget: float, settings: dict | None = None) -> dict:
    """(basis, mass) -> seconds per step at about ``n`` points, mass "direct" the consistent
    mass factored every step (``linear_solver = "direct"``, what "auto" did before it kept
    the factors); NaN for a case that stops within
    :data:`TRIAL_STEPS` steps at the block's step (consistent bspline2: its critical step is
    below ``0.1 h / c``)."""
    cases, stopped = {}, {}
    for basis in bases:
        for mass in ("lumped", "consistent", "direct"):
            scene = (block_scene(basis, "consistent", n).with_overrides(**{"solver.linear_solver": "direct"})
                     if mass == "direct" else block_scene(basis, mass, n))
            if mass != "lumped" and settings:
                scene = scene.with_overrides(**settings)
            simulation = Simulation(scene)
            try:
                for _ in range(TRIAL_STEPS):
                    simulation.advance()
                cases[basis, mass] = simulation
            except SimulationStopped:
                stopped[basis, mass] = np.nan
    return {**fastest(cases, budget), **stopped}


def to_end_time(basis: str, mass: str, n: int, settings: dict | None = None) -> tuple[int, float, float, str]:
    """(steps, wall seconds of ``run()``, seconds of the set-up, status) of the block with ``dt =
    "auto"`` to :data:`TRANSITS` h / c; the set-up is ``Simulation(scene)``, whose estimate of the
    critical step is most of it."""
    scene = block_scene(basis, mass, n).with_overrides(**{"time.dt": "auto", "time.end": TRANSITS / WAVE_SPEED,
                                                          **((settings or {}) if mass != "lumped" else {})})
    start = time.perf_counter()
    simulation = Simulation(scene)
    built = time.perf_counter()
    try:
        status = simulation.run().status
    except SimulationStopped as stop:
        status = f"stopped ({stop.reason})"
    return simulation.step_index, time.perf_counter() - built, built - start, status


def to_end_times(basis: str, n: int, settings: dict | None = None) -> tuple[tuple, tuple, int]:
    """:func:`to_end_time` of the consistent and the lumped mass, each the fastest of up to
    :data:`REPEATS` runs (wall and set-up apart), the two masses in turn; and the runs made of each."""
    runs = {"consistent": [], "lumped": []}
    for _ in range(REPEATS):
        for mass in runs:
            runs[mass].append(to_end_time(basis, mass, n, settings))
        _, wall, setup, _ = runs["consistent"][0]
        if wall + setup > REPEAT_WITHIN:
            break
    fastest_runs = tuple((made[0][0], min(run[1] for run in made), min(run[2] for run in made), made[0][3])
                         for made in runs.values())
    return fastest_runs[0], fastest_runs[1], len(runs["consistent"])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1e3 and 1e4 points only")
    parser.add_argument("--sizes", help="comma-separated numbers of points (default 1000,10000,100000)")
    parser.add_argument("--bases", default=",".join(BASES), help=f"comma-separated (default {','.join(BASES)})")
    parser.add_argument("--budget", type=float, default=1.0, help="seconds of timed steps per case (default 1)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a scene key of the consistent runs, e.g. solver.weak_ratio=0.5 (repeatable)")
    args = parser.parse_args(argv)
    settings = {}
    for item in args.set:
        key, _, value = item.partition("=")
        try:
            settings[key] = float(value)
        except ValueError:
            settings[key] = value
    sizes = [int(float(s)) for s in args.sizes.split(",")] if args.sizes else list(SIZES[:2] if args.quick else SIZES)
    bases = args.bases.split(",")
    warnings.simplefilter("ignore")
    chosen = "".join(f"; consistent with {key} = {value}" for key, value in settings.items())
    print(f"{time.strftime('%Y-%m-%d')}; numpy {np.__version__}; one BLAS thread; end time {TRANSITS} h / c; "
          f"runs to it the fastest of {REPEATS} (1 where a consistent one took over {REPEAT_WITHIN:g} s){chosen}\n")
    for n in sizes:
        seconds = per_step(bases, n, args.budget, settings)
        print(f"about {n:.0e} points:\n")
        print("| basis | consistent per step | lumped per step | ratio | factored every step: ratio | steps to the end time (consistent / "
              "lumped) | wall to the end time (consistent / lumped) | set-up (consistent / lumped) |")
        print("|---|---|---|---|---|---|---|---|")
        for basis in bases:
            consistent, lumped = seconds[basis, "consistent"], seconds[basis, "lumped"]
            (steps_c, wall_c, setup_c, status_c), (steps_l, wall_l, setup_l, status_l), made = to_end_times(
                basis, n, settings)
            note = "" if status_c == status_l == "completed" else f" ({status_c}; {status_l})"
            note += "" if made == REPEATS else " (1 run)"
            to_end = (f"| {steps_c} / {steps_l} = {steps_c / max(steps_l, 1):.1f}x "
                      f"| {wall_c:.2f} / {wall_l:.2f} s = {wall_c / wall_l:.1f}x{note} "
                      f"| {setup_c:.3f} / {setup_l:.3f} s |")
            if np.isnan(consistent):
                print(f"| {basis} | stops at the block's step 0.1 h / c | {1e3 * lumped:.3f} ms | | {to_end}", flush=True)
                continue
            print(f"| {basis} | {1e3 * consistent:.3f} ms | {1e3 * lumped:.3f} ms | {consistent / lumped:.1f}x "
                  f"| {seconds[basis, 'direct'] / lumped:.1f}x {to_end}", flush=True)
        print()


if __name__ == "__main__":
    main()
