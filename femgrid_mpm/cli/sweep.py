"""``femgrid-mpm sweep`` and ``femgrid-mpm report``: the runs of a sweep file and their report.

``sweep`` checks every combination before it runs any (a problem is exit 2,
nothing written), runs the missing ones on Dask, rewrites ``DIR/runs.csv`` as
each ends and then writes the report.  Ctrl-C closes the cluster and keeps
the finished runs (exit 130); a run that could not be built is a row with
status ``failed`` (exit 2 once the others have run).
"""

from __future__ import annotations

import errno
import os
import sys
from pathlib import Path

from .parser import (EXIT_BAD_INPUT, EXIT_DONE, EXIT_INTERRUPTED, EXIT_WRITE_FAILED, BadInput, StdoutFailed, emit,
                     output_directory, say)

#: the sweep file as given, kept beside its runs (the report reads its [report] table)
SWEEP_COPY = "sweep.toml"


def sweep(args) -> int:
    """Run the sweep file ``args.sweep`` into ``--out``; see the module's docstring for the exit codes."""
    from ..output import atomic_write
    from ..reading import read_regular_file
    from ..sweep import SweepError, plan, read_sweep, run_sweep
    from ..sweep.directories import SweepBusy
    from ..sweep.spec import scene_file, sweep_path

    path = sweep_path(args.sweep)
    try:
        spec = read_sweep(path)
        runs = plan(spec, path)
    except SweepError as error:
        raise BadInput(str(error)) from None
    out = output_directory(args.out)
    try:
        source = read_regular_file(path)
    except OSError as error:
        raise BadInput(f"{path}: cannot be read: {error.strerror or error}") from None
    refuse_inputs_as_outputs(out, {"sweep file given": path, "sweep's scene file": scene_file(spec, path)})
    writable(out)

    def prepare() -> None:
        out.mkdir(parents=True, exist_ok=True)
        atomic_write(out / SWEEP_COPY, source)

    bar = SweepBar(enabled=not args.no_progress and sys.stderr.isatty())
    try:
        counts = run_sweep(runs, out, workers=args.workers or (None if args.scheduler else default_workers()),
                           scheduler=args.scheduler, progress=bar, prepare=prepare)
    except SweepBusy as error:
        bar.close()
        raise BadInput(str(error)) from None
    except KeyboardInterrupt:
        bar.close()
        kept = f"the finished runs are kept in {out} (runs.csv)" if kept_runs(out) else \
            f"before any run was computed (nothing in {out} to keep)"
        say("interrupted", f"{kept}; run the sweep again to compute the rest")
        return EXIT_INTERRUPTED
    except OSError as error:
        bar.close()
        if args.scheduler and "scheduler" in str(error):
            raise BadInput(f"--scheduler {args.scheduler}: {error}") from None
        say("error", f"cannot write the sweep's outputs in {out}: {error}")
        return EXIT_WRITE_FAILED
    bar.close()
    at_once = f" ({counts.workers} at once)" if counts.computed or counts.failed else ""
    stdout_failed = None
    try:  # the runs are finished: a stdout that cannot take this line does not stop the report
        emit(f"{len(runs)} runs: {counts.computed} computed{at_once}, {counts.reused} reused, {counts.failed} failed; "
             f"runs.csv in {out}")
    except StdoutFailed as error:
        stdout_failed = error
    written = write_report(out, quiet=stdout_failed is not None)
    if written != EXIT_DONE:
        return written
    if counts.unwritten:  # a full disk or a read-only directory is a failed write, not bad input
        say("error", f"cannot write the sweep's outputs in {out}: {counts.unwritten} run(s) could not write their "
                     f"files (run {counts.write_error}); their reason is in {out / 'runs.csv'}")
        return EXIT_WRITE_FAILED
    if counts.failed:
        say("error", f"{counts.failed} run(s) could not run: their reason is in {out / 'runs.csv'}")
        return EXIT_BAD_INPUT
    if stdout_failed is not None:
        raise stdout_failed
    return EXIT_DONE


def kept_runs(out: Path) -> bool:
    """Whether ``out/runs.csv`` has a run's row (the sweep writes it with its header alone before
    any run ends)."""
    from ..sweep import RUNS_FILE, read_runs

    try:
        return bool(read_runs(out / RUNS_FILE)[1])
    except ValueError:  # none, or not readable: nothing said to be kept
        return False


def refuse_inputs_as_outputs(out: Path, inputs: dict[str, Path]) -> None:
    """Raise :class:`BadInput` if the sweep into ``out`` would write over, replace or remove one of
    its ``inputs`` (the sweep file, the scene file): one named like a file the sweep writes in
    ``out`` (symbolic and hard links resolved with ``os.path.samefile``), or any file under
    ``out/runs/``, where runs are replaced and temporaries removed; or if ``out/runs`` is not a
    directory (a file, a dangling link).  Touches no file."""
    from ..output import _same_file
    from ..sweep import RUNS_FILE
    from ..sweep.report import FIGURES, HTML_FILE, REPORT_FILE
    from ..sweep.runner import RUNS_DIRECTORY

    written = [out / name for name in (RUNS_FILE, REPORT_FILE, HTML_FILE, SWEEP_COPY, *FIGURES.values())]
    refuse_directories(written)
    for what, source in inputs.items():
        for path in written:
            if _same_file(source, path):
                raise BadInput(f"--out {out}: {path} is the {what} ({source}): the sweep would write over it; "
                               "give another --out directory")
    runs = out / RUNS_DIRECTORY
    if not runs.is_dir():
        if runs.exists() or runs.is_symlink():  # found now, not once the cluster has started
            raise BadInput(f"{runs}: is not a directory, where the sweep's runs go; move it or give another "
                           "directory")
        return
    identities = {}
    for what, source in inputs.items():
        try:
            status = os.stat(source)
        except OSError:
            continue
        identities[(status.st_dev, status.st_ino)] = (what, source)
    for root, directories, files in os.walk(runs):
        for name in files:
            place = Path(root) / name
            try:
                status = os.lstat(place)
            except OSError:
                continue
            if (status.st_dev, status.st_ino) in identities:
                what, source = identities[(status.st_dev, status.st_ino)]
                raise BadInput(f"--out {out}: {place} is the {what} ({source}): it is under {runs}, where the sweep "
                               "replaces runs and removes their temporaries; give another --out directory")


def refuse_directories(written: list[Path]) -> None:
    """Raise :class:`BadInput` if a directory stands where a file is to be written (found before any
    run is computed, not when the report is written after them)."""
    for path in written:
        if path.is_dir() and not path.is_symlink():
            raise BadInput(f"{path}: is a directory, where a file is to be written; move it or give another directory")


def writable(out: Path) -> None:
    """Raise :class:`BadInput` unless ``out``, or the nearest folder above it that exists, can be written
    (checked without writing: a sweep writes nothing before its cluster is reached)."""
    place, missing = out, []
    while not place.exists() and place != place.parent:
        missing.append(os.fsencode(place.name))
        place = place.parent
    if not place.is_dir() or not os.access(place, os.W_OK | os.X_OK):
        raise BadInput(f"--out {out}: cannot write there ({place} is not a writable directory)")
    try:  # a folder to make with a name too long: refused now, as run refuses it, not after the cluster started
        longest = os.pathconf(place, "PC_NAME_MAX")
    except (OSError, ValueError):
        return
    if any(len(name) > longest for name in missing):
        raise BadInput(f"--out {out}: cannot be used: {os.strerror(errno.ENAMETOOLONG)} (a name of more than "
                       f"{longest} bytes)")


def report(args) -> int:
    """Write ``DIR/report.md``, ``report.html`` and the figures from ``DIR/runs.csv``."""
    from ..sweep import RUNS_FILE

    from ..sweep.report import FIGURES, HTML_FILE, REPORT_FILE

    directory = Path(args.directory)
    try:
        found = (directory / RUNS_FILE).is_file()
    except OSError as error:  # a name longer than the file system allows
        raise BadInput(f"{directory}: cannot be used: {error.strerror or error}") from None
    if not found:
        raise BadInput(f"{directory}: has no {RUNS_FILE} (the --out directory of femgrid-mpm sweep)")
    refuse_directories([directory / name for name in (REPORT_FILE, HTML_FILE, *FIGURES.values())])
    return write_report(directory)


def write_report(directory: Path, quiet: bool = False) -> int:
    """The report of the sweep in ``directory``; its exit code (a runs.csv that does not read is bad
    input); its line on stdout unless ``quiet`` (raising :class:`StdoutFailed` if it cannot be written)."""
    from ..sweep.report import write_report as write

    try:
        path = write(directory)
    except ValueError as error:
        raise BadInput(str(error)) from None
    except OSError as error:
        say("error", f"cannot write the report in {directory}: {error}")
        return EXIT_WRITE_FAILED
    if not quiet:
        emit(f"report: {path}")
    return EXIT_DONE


def workers_count(text: str) -> int:
    """``--workers N``: from 1 to :data:`~femgrid_mpm.sweep.runner.MAX_WORKERS`."""
    import argparse

    from ..sweep.runner import MAX_WORKERS

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of workers, got {text!r}") from None
    if not 1 <= value <= MAX_WORKERS:
        raise argparse.ArgumentTypeError(f"must be from 1 to {MAX_WORKERS} (got {value})")
    return value


#: the protocols of a Dask scheduler's address reachable from another machine
SCHEDULER_PROTOCOLS = ("tcp", "tls")


def scheduler_address(text: str) -> str:
    """``--scheduler tcp://HOST:PORT``: a protocol, a host and a port from 1 to 65535 (checked
    at once: Dask would try a malformed address for its whole time-out)."""
    import argparse
    from urllib.parse import urlsplit

    expected = f"expected tcp://HOST:PORT, got {text!r}"
    try:
        parts = urlsplit(text)
        port = parts.port
    except ValueError as error:
        raise argparse.ArgumentTypeError(f"{expected} ({error})") from None
    if parts.scheme not in SCHEDULER_PROTOCOLS or not parts.hostname:
        raise argparse.ArgumentTypeError(f"{expected} (protocol {', '.join(SCHEDULER_PROTOCOLS)})")
    if port is None or not 1 <= port <= 65535 or parts.path not in ("", "/") or parts.query or parts.fragment:
        raise argparse.ArgumentTypeError(f"{expected} (a port from 1 to 65535, nothing after it)")
    return text


def default_workers() -> int:
    from ..sweep.runner import MAX_WORKERS

    return min(os.cpu_count() or 1, MAX_WORKERS)


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
