"""What accuracy costs in time: the sweeps behind the README's work-precision figure.

Usage: ``python experiments/cost_accuracy.py [OUT_DIR] [--workers N]`` (default
results/cost_accuracy, N the number of cores; ``--workers 1`` for timing-grade
wall times). The same as ``femgrid-mpm reproduce --case cost_accuracy``.
"""

import argparse

from femgrid_mpm.reproduce import cost_accuracy

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", default="results/cost_accuracy")
    parser.add_argument("--workers", type=int, default=None)
    args = parser.parse_args()
    cost_accuracy.run(args.out, workers=args.workers)
    print(open(f"{args.out}/table.md").read())
