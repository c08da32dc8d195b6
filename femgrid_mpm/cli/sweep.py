"""``femgrid-mpm sweep`` and ``femgrid-mpm report``: the runs of a sweep file and their report.

``sweep`` checks every combination before it runs any (a problem is exit 2,
nothing written), runs the missing ones on Dask, rewrites ``DIR/runs.csv`` as
each ends and then writes the report.  Ctrl-C closes the cluster and keeps
the finished runs (exit 130); a run that could not be built is a row with
status ``failed`` (exit 2 once the others have run).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from .parser import EXIT_BAD_INPUT, EXIT_DONE, EXIT_INTERRUPTED, EXIT_WRITE_FAILED, BadInput, output_directory, say

#: the sweep file as given, kept beside its runs (the report reads its [report] table)
SWEEP_COPY = "sweep.toml"


def sweep(args) -> int:
    """Run the sweep file ``args.sweep`` into ``--out``; see the module's docstring for the exit codes."""
    from ..output import atomic_write
    from ..sweep import SweepError, plan, read_sweep, run_sweep
    from ..sweep.spec import sweep_path

    path = sweep_path(args.sweep)
    try:
        spec = read_sweep(path)
        runs = plan(spec, path)
    except SweepError as error:
        raise BadInput(str(error)) from None
    out = output_directory(args.out)
    try:
        source = path.read_bytes()
    except OSError as error:
        raise BadInput(f"{path}: cannot be read: {error.strerror or error}") from None
    writable(out)

    def prepare() -> None:
        out.mkdir(parents=True, exist_ok=True)
        atomic_write(out / SWEEP_COPY, source)

    bar = SweepBar(enabled=not args.no_progress and sys.stderr.isatty())
    try:
        counts = run_sweep(runs, out, workers=args.workers, scheduler=args.scheduler, progress=bar, prepare=prepare)
    except KeyboardInterrupt:
        bar.close()
        say("interrupted", f"the finished runs are kept in {out} (runs.csv); run the sweep again to compute the rest")
        return EXIT_INTERRUPTED
    except OSError as error:
        bar.close()
        if args.scheduler and "scheduler" in str(error):
            raise BadInput(f"--scheduler {args.scheduler}: {error}") from None
        say("error", f"cannot write the sweep's outputs in {out}: {error}")
        return EXIT_WRITE_FAILED
    bar.close()
    at_once = f" ({counts.workers} at once)" if counts.computed or counts.failed else ""
    print(f"{len(runs)} runs: {counts.computed} computed{at_once}, {counts.reused} reused, {counts.failed} failed; "
          f"runs.csv in {out}")
    written = write_report(out)
    if written != EXIT_DONE:
        return written
    if counts.failed:
        say("error", f"{counts.failed} run(s) could not run: their reason is in {out / 'runs.csv'}")
        return EXIT_BAD_INPUT
    return EXIT_DONE


def writable(out: Path) -> None:
    """Raise :class:`BadInput` unless ``out``, or the nearest folder above it that exists, can be written
    (checked without writing: a sweep writes nothing before its cluster is reached)."""
    place = out
    while not place.exists() and place != place.parent:
        place = place.parent
    if not place.is_dir() or not os.access(place, os.W_OK | os.X_OK):
        raise BadInput(f"--out {out}: cannot write there ({place} is not a writable directory)")


def report(args) -> int:
    """Write ``DIR/report.md``, ``report.html`` and the figures from ``DIR/runs.csv``."""
    from ..sweep import RUNS_FILE

    directory = Path(args.directory)
    if not (directory / RUNS_FILE).is_file():
        raise BadInput(f"{directory}: has no {RUNS_FILE} (the --out directory of femgrid-mpm sweep)")
    return write_report(directory)


def write_report(directory: Path) -> int:
    """The report of the sweep in ``directory``; its exit code (a runs.csv that does not read is bad input)."""
    from ..sweep.report import write_report as write

    try:
        path = write(directory)
    except ValueError as error:
        raise BadInput(str(error)) from None
    except OSError as error:
        say("error", f"cannot write the report in {directory}: {error}")
        return EXIT_WRITE_FAILED
    print(f"report: {path}")
    return EXIT_DONE


def workers_count(text: str) -> int:
    """``--workers N``: at least 1."""
    import argparse

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of workers, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1 (got {value})")
    return value


def default_workers() -> int:
    return os.cpu_count() or 1


class SweepBar:
    """One tqdm bar over a sweep's runs on stderr, naming the runs running (a
    :class:`~femgrid_mpm.sweep.SweepProgress`); nothing if not ``enabled``."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.bar = None

    def started(self, total: int, reused: int, running: list[str]) -> None:
        if not self.enabled or reused == total:
            return
        from tqdm import tqdm

        try:  # a terminal that reports no size (some ptys) would get no bar at all
            sized = min(os.get_terminal_size(sys.stderr.fileno())) > 0
        except (OSError, ValueError):
            sized = False
        self.bar = tqdm(total=total, initial=reused, unit="run", file=sys.stderr, dynamic_ncols=sized,
                        ncols=None if sized else 100, nrows=None if sized else 24,
                        bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} runs{postfix} [{elapsed}<{remaining}]")
        self.bar.set_postfix_str(f"running {', '.join(running)}")

    def finished(self, key: str, status: str, running: list[str]) -> None:
        if self.bar is not None:
            self.bar.set_postfix_str(f"running {', '.join(running)}" if running else f"last {key}", refresh=False)
            self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
