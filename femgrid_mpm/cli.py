"""The ``femgrid-mpm`` command line."""

from __future__ import annotations

import argparse
import sys


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="femgrid-mpm", description="Material point method on finite-element grids.")
    commands = parser.add_subparsers(dest="command", required=True)
    reproduce = commands.add_parser("reproduce", help="run the paper's cases and write every figure and table")
    reproduce.add_argument("--out", default="results", help="output directory (default: results)")
    args = parser.parse_args(argv)
    if args.command == "reproduce":
        return _reproduce(args.out)
    return 2


def _reproduce(out: str) -> int:
    import warnings
    from pathlib import Path

    from .reproduce import CASES

    warnings.simplefilter("ignore")  # expected events (negative masses under "warn") are in the tables
    for name, run in CASES.items():
        print(f"{name} ...", file=sys.stderr, flush=True)
        run(Path(out) / name)
        table = Path(out) / name / "table.md"
        if table.exists():
            print(table.read_text())
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
