"""The stable step of consistent mass and what its treatments cost in accuracy.

Run: ``python experiments/consistent_step.py [bar|manufactured|cantilever ...]`` (the bar
about five minutes, the manufactured solution two, the cantilever fifteen on one core).

For each basis, lumped mass, plain consistent mass (``weak_ratio = 0``), the weak rows'
treatment (``weak_ratio = 0.5``, ``weak_mix = 0.02``, :mod:`femgrid_mpm.mass.weak_rows`)
and the mixed mass ``mix = 0.25`` (weak rows off): the critical step the estimate gives
(element widths over c_p), the steps to the scene's end with ``dt = "auto"`` (safety 0.5),
and the error against the exact solution (``error_max``: the bar, the manufactured
solution; ``error_end``: the cantilever against Timoshenko & Goodier).  With ``--same-dt``
the treatments run at plain consistent mass's step too, which separates the time step's
share of the error from the mass's.  Prints a Markdown table (docs/time_step.md).
"""

from __future__ import annotations

import argparse
import os
import warnings

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from femgrid_mpm.bases import BASES  # noqa: E402
from femgrid_mpm.scene import bundled_scene  # noqa: E402
from femgrid_mpm.solver import Simulation  # noqa: E402

CASES = {  # scene, spacing, error
    "bar": ("vibrating_bar_exact", 0.125, "error_max"),
    "manufactured": ("manufactured", 0.0625, "error_max"),
    "cantilever": ("cantilever_quasistatic", 0.5, "error_end"),
}
BASIS_NAMES = ("q1", "q2", "bspline2", "bspline3", "gimp")
TREATMENTS = {
    "lumped": {"solver.mass": "lumped"},
    "consistent": {"solver.mass": "consistent", "solver.weak_ratio": 0.0},
    "weak rows": {"solver.mass": "consistent", "solver.weak_ratio": 0.5},
    "mix 0.25": {"solver.mass": "consistent", "solver.weak_ratio": 0.0, "solver.mix": 0.25},
}


def run(case: str, basis: str, settings: dict) -> dict:
    name, spacing, error = CASES[case]
    scene = bundled_scene(name).with_overrides(**{"grid.basis": basis, "grid.spacing": spacing,
                                                  "solver.negative_mass": "warn", **settings})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        simulation = Simulation(scene)
        result = simulation.run()
    wave_speed = simulation.materials[0].wave_speed
    width = spacing * BASES[basis].cells_per_element
    return {"factor": simulation.critical_dt * wave_speed / width, "dt": simulation.dt,
            "steps": result.summary["steps"], "error": (result.summary.get("reference") or {}).get(error),
            "status": result.status}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases", nargs="*", default=list(CASES), choices=list(CASES))
    parser.add_argument("--same-dt", action="store_true", help="also run the treatments at plain consistent's step")
    args = parser.parse_args()
    for case in args.cases:
        print(f"\n{case} ({CASES[case][0]}, spacing {CASES[case][1]})\n")
        print("| basis | mass | critical step x c_p / element width | steps | error | error at consistent's dt |")
        print("|---|---|---|---|---|---|")
        for basis in BASIS_NAMES:
            plain = None
            for label, settings in TREATMENTS.items():
                row = run(case, basis, settings)
                plain = row if label == "consistent" else plain
                same = ""
                if args.same_dt and plain is not None and label not in ("lumped", "consistent"):
                    same = f"{run(case, basis, {**settings, 'time.dt': plain['dt']})['error']:.3g}"
                error = "" if row["error"] is None else f"{row['error']:.3g}"
                print(f"| {basis} | {label} | {row['factor']:.3f} | {row['steps']} | {error} | {same} |", flush=True)


if __name__ == "__main__":
    main()
