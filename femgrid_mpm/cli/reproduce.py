"""``femgrid-mpm reproduce``: the paper's cases, every figure and table."""

from __future__ import annotations

import sys
import warnings

from .parser import EXIT_DONE, BadInput, output_directory


def reproduce(args) -> int:
    """Run the paper's cases (:data:`femgrid_mpm.reproduce.CASES`) into ``--out``."""
    from ..output import probe_writable
    from ..reproduce import CASES

    unknown = [name for name in args.case if name not in CASES]
    if unknown:
        raise BadInput(f"--case {unknown[0]}: no such case (cases: {', '.join(CASES)})")
    out = output_directory(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe_writable(out)
    except OSError as error:
        raise BadInput(f"--out {out}: cannot write there: {error.strerror or error}") from None
    warnings.simplefilter("ignore")  # expected events (negative masses under "warn") are in the tables
    for name, run in CASES.items():
        if args.case and name not in args.case:
            continue
        print(f"{name} ...", file=sys.stderr, flush=True)
        run(out / name)
        table = out / name / "table.md"
        if table.exists():
            print(table.read_text())
    return EXIT_DONE
