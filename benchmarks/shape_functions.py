"""Cost of building (N, dNdx, dNdy) per particle, for every basis.

Run: ``python benchmarks/shape_functions.py``.  Prints a markdown table of
ns per particle (median of repeated runs) at 1e3, 1e4 and 1e5 particles.
Targets at 1e5 (issue 2): <= 150 ns for q1, q2, serendipity; <= 300 ns for
bspline3.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import time  # noqa: E402

import numpy as np  # noqa: E402

from femgrid_mpm import Grid  # noqa: E402
from femgrid_mpm.bases import BASES  # noqa: E402

SIZES = (1_000, 10_000, 100_000)
TARGET = {"q1": 150, "q2": 150, "serendipity": 150, "bspline3": 300, "bspline3_open": 300}


def time_per_particle(grid, points, repeats):
    grid.shape_functions(points)  # warm up caches and allocator
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        grid.shape_functions(points)
        samples.append(time.perf_counter() - start)
    return 1e9 * float(np.median(samples)) / len(points)


def main():
    rng = np.random.default_rng(0)
    rows = []
    for basis in BASES:
        # about 4 particles per lattice cell, as in a 2x2-per-cell seeding
        row = [basis]
        for n in SIZES:
            side = max(2, int(np.sqrt(n / 4)))
            grid = Grid(basis, (0.0, 0.0), (float(side), float(side)), 1.0)
            points = rng.random((n, 2)) * side
            row.append(time_per_particle(grid, points, repeats=max(5, int(2e6 / n))))
        rows.append(row)
    print("| basis | " + " | ".join(f"{n:.0e} particles" for n in SIZES) + " | target at 1e5 |")
    print("|---|" + "---|" * (len(SIZES) + 1))
    for basis, *values in rows:
        cells = " | ".join(f"{v:.0f} ns" for v in values)
        target = f"<= {TARGET[basis]} ns" if basis in TARGET else "-"
        print(f"| {basis} | {cells} | {target} |")


if __name__ == "__main__":
    main()
