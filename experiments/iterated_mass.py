"""What the iterated mass buys: error against the exact solution, steps and wall time.

Run: ``python experiments/iterated_mass.py`` (about five minutes; ``--bases bspline3`` and
``--cases bar`` choose).

The vibrating bar's exact first mode (``vibrating_bar_exact``, spacing 0.125) and the
manufactured solution (``manufactured``, spacing 0.0625), each basis with lumped mass,
consistent mass and the iterated mass (``solver.mass = "iterated"``, the consistent mass solved
by ``mass_corrections`` k = 1, 2, 3 Jacobi corrections of the lumped solution), in the paper's
time scheme and in the fourth-order ``yoshida4``, all at their own ``dt = "auto"``.  For each run:
the largest displacement error over the run (``error_max`` of the scene's reference), the steps,
and the wall time of ``run()`` (the fastest of two, after a run that compiles), and that time over
lumped mass's in the paper's scheme.  docs/time_step.md has the table.
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from femgrid_mpm.diagnostics import SimulationStopped  # noqa: E402
from femgrid_mpm.scene import bundled_scene  # noqa: E402
from femgrid_mpm.solver import Simulation  # noqa: E402

CASES = {"bar": ("vibrating_bar_exact", 0.125), "manufactured": ("manufactured", 0.0625)}
BASES = ("bspline3", "bspline2", "q1", "gimp")
METHODS = (("lumped", {"solver.mass": "lumped"}), ("consistent", {"solver.mass": "consistent"}),
           *((f"iterated k={k}", {"solver.mass": "iterated", "solver.mass_corrections": k}) for k in (1, 2, 3)))
SCHEMES = ("paper", "yoshida4")
REPEATS = 2


def run(case: str, basis: str, settings: dict) -> dict:
    name, spacing = CASES[case]
    scene = bundled_scene(name).with_overrides(**{"grid.basis": basis, "grid.spacing": spacing,
                                                  "solver.negative_mass": "warn", **settings})
    best = None
    for _ in range(REPEATS + 1):  # the first compiles
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            simulation = Simulation(scene)
            start = time.perf_counter()
            try:
                result = simulation.run()
                error = result.summary["reference"]["error_max"]
            except SimulationStopped as stop:
                return {"error": None, "steps": simulation.step_index, "wall": None, "stop": str(stop)[:60]}
            wall = time.perf_counter() - start
        best = wall if best is None else min(best, wall)
    return {"error": error, "steps": simulation.step_index, "wall": best}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bases", default=",".join(BASES))
    parser.add_argument("--cases", default=",".join(CASES))
    args = parser.parse_args(argv)
    print("| case | basis | mass | scheme | error_max | steps | wall (s) | wall / lumped's |")
    print("|---|---|---|---|---|---|---|---|")
    for case in args.cases.split(","):
        for basis in args.bases.split(","):
            lumped_wall = None
            for label, settings in METHODS:
                for scheme in SCHEMES:
                    row = run(case, basis, {**settings, "solver.scheme": scheme})
                    if label == "lumped" and scheme == "paper":
                        lumped_wall = row["wall"]
                    if row["error"] is None:
                        print(f"| {case} | {basis} | {label} | {scheme} | stopped: {row['stop']} | {row['steps']} | | |")
                        continue
                    ratio = f"{row['wall'] / lumped_wall:.1f}x" if lumped_wall else ""
                    print(f"| {case} | {basis} | {label} | {scheme} | {row['error']:.3g} | {row['steps']} | "
                          f"{row['wall']:.3f} | {ratio} |", flush=True)


if __name__ == "__main__":
    main()
