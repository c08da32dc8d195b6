"""The arguments of the command line, its exit codes and its one-line messages on stderr."""

from __future__ import annotations

import argparse
import sys
import unicodedata
from pathlib import Path

PROG = "femgrid-mpm"
EXIT_DONE = 0
EXIT_WRITE_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_STOPPED = 3
EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143
EXIT_HANGUP = 129
EXIT_CODES = {
    EXIT_DONE: "done",
    EXIT_WRITE_FAILED: "the outputs (or standard output) could not be written",
    EXIT_BAD_INPUT: "bad input: a scene file, an argument or an output directory",
    EXIT_STOPPED: "the simulation stopped on a numerical event; the outputs so far are valid",
    EXIT_INTERRUPTED: "interrupted (SIGINT, Ctrl-C); the outputs so far are valid",
    EXIT_HANGUP: "interrupted by SIGHUP (the terminal closed); the outputs so far are valid",
    EXIT_TERMINATED: "interrupted by SIGTERM (kill); the outputs so far are valid",
}


class BadInput(Exception):
    """Input the run cannot use; the message is one line naming the file and the key."""


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (exit code 2) instead of usage + error."""

    def error(self, message):
        self.exit(EXIT_BAD_INPUT, f"{PROG}: error: {message} (see {self.prog} --help)\n")

    def _print_message(self, message, file=None):
        # argparse drops a failed write: --help or --version into a full disk would exit 0
        # with nothing written; on stdout it raises (exit 1, or a closed pipe's quiet 0)
        if message:
            file = file or sys.stderr
            try:
                file.write(message)
                file.flush()
            except OSError:
                if file is sys.stdout:
                    raise


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``femgrid-mpm run | resume | info | plot | reproduce | sweep | report``."""
    from .. import __version__
    from ..bases import BASES

    parser = _Parser(
        prog=PROG,
        description="Material point method in 2D on finite-element background grids.",
        epilog="Exit codes: " + "; ".join(f"{code} {meaning}" for code, meaning in EXIT_CODES.items()) + ".",
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="{run,resume,info,plot,reproduce,sweep,report}")

    def scene_arguments(command):
        command.add_argument("scene", type=given_path, metavar="SCENE.toml", help="the scene file")
        command.add_argument("--basis", choices=list(BASES), help="override [grid] basis")
        command.add_argument("--mass", choices=["lumped", "consistent", "hrz", "iterated"], help="override [solver] mass")
        command.add_argument(
            "--set",
            dest="settings",
            action="append",
            default=[],
            metavar="KEY=VALUE",
            help="override any key, dotted, list items by index, the value in TOML "
            "(bare words are strings): --set time.end=1 --set bodies.0.points_per_cell=4 (repeatable)",
        )

    run = commands.add_parser("run", help="run a scene and write its outputs to --out")
    scene_arguments(run)
    run.add_argument("--out", required=True, metavar="DIR", help="output directory (created if missing)")
    run.add_argument("--no-progress", action="store_true", help="no progress bar (it is shown only when stderr is a terminal)")
    run.add_argument("--checkpoint-every", type=positive_steps, default=0, metavar="N",
                     help="write the whole state to DIR/checkpoint.npz every N steps, for femgrid-mpm resume")

    resume = commands.add_parser("resume", help="continue a run from the checkpoint in its output directory")
    resume.add_argument("directory", type=given_path, metavar="DIR", help="the --out directory of a run with --checkpoint-every")
    resume.add_argument("--no-progress", action="store_true", help="no progress bar (it is shown only when stderr is a terminal)")

    info = commands.add_parser("info", help="check a scene and print what a run would do")
    scene_arguments(info)

    from .plot import add_arguments as plot_arguments

    plot_arguments(commands.add_parser("plot", help="draw a run's points and energies (PNGs), or its particle "
                                       "series as an animation (--animate)"))

    reproduce = commands.add_parser("reproduce", help="run the paper's cases and write every figure and table")
    reproduce.add_argument("--out", default="results", metavar="DIR", help="output directory (default: results)")
    reproduce.add_argument("--case", action="append", default=[], metavar="NAME", help="only this case (repeatable; default: all)")
    reproduce.add_argument("--list", action="store_true", help="print the cases' names, one a line, and run nothing")
    reproduce.add_argument("--gallery", metavar="DIR", help="also copy the README's gallery figures of the cases run into DIR "
                           "(femgrid_mpm.reproduce.gallery.GALLERY)")

    from .sweep import default_workers, scheduler_address, workers_count

    sweep = commands.add_parser("sweep", help="run a scene over the product of the values of some keys (a sweep file), "
                                "on Dask, and write runs.csv and the report")
    sweep.add_argument("sweep", type=given_path, metavar="SWEEP.toml", help="the sweep file")
    sweep.add_argument("--out", required=True, metavar="DIR", help="output directory (created if missing; a rerun "
                       "into it computes only the runs missing)")
    cluster = sweep.add_mutually_exclusive_group()  # a count given with --scheduler would go unused
    cluster.add_argument("--workers", type=workers_count, metavar="N",
                         help="runs at once on a local Dask cluster (default: the number of cores, here "
                         f"{default_workers()}; at most the runs missing; 1 for timing-grade wall times)")
    cluster.add_argument("--scheduler", type=scheduler_address, metavar="tcp://HOST:PORT", help="run on an existing Dask cluster "
                         "instead (its workers must see DIR and the scene file at the same paths)")
    sweep.add_argument("--no-progress", action="store_true", help="no progress bar (it is shown only when stderr is a terminal)")

    report = commands.add_parser("report", help="write a sweep's report (report.md, report.html, figures) from its runs.csv")
    report.add_argument("directory", type=given_path, metavar="DIR", help="the --out directory of femgrid-mpm sweep")
    return parser


def output_directory(text: str, option: str = "--out") -> Path:
    """``--out`` (or ``option``) as a path; raises :class:`BadInput` for an empty one (an unset
    ``$OUT`` would mean the working directory) or one that is a file."""
    if not text:  # (a name of spaces is a directory's name like any other)
        raise BadInput(f"{option}: is empty (give a directory, e.g. {option} results)")
    out = Path(text)
    try:
        if out.exists() and not out.is_dir():
            raise BadInput(f"{option} {out}: exists and is not a directory")
    except OSError as error:  # e.g. a name longer than the file system allows
        raise BadInput(f"{option} {out}: cannot be used: {error.strerror or error}") from None
    return out


def given_path(text: str) -> str:
    """A file or directory named on the command line: an empty one (an unset ``$DIR``) is refused,
    not taken as the working directory."""
    if not text:
        raise argparse.ArgumentTypeError("is empty (give a path)")
    return text


def positive_steps(text: str) -> int:
    """``--checkpoint-every N``: a whole number of steps, at least 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of steps, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1 (got {value})")
    return value


class StdoutFailed(Exception):
    """Standard output could not be written (a full disk, ``> /dev/full``); not a closed pipe."""


def discard(stream) -> None:
    """Send what is still to be written to ``stream`` (stdout or stderr) to /dev/null, so
    that its flush at exit cannot fail again (Python's advice for a closed pipe)."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, stream.fileno())
        os.close(devnull)
    except (OSError, ValueError):  # no descriptor (a test's capture): nothing is flushed at exit
        pass


#: the direction overrides and isolates of Unicode, which reorder what a terminal shows after them
_BIDI_CONTROLS = set("\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")


def visible(text: str) -> str:
    """``text`` with its control characters escaped (an ESC or a CR from a scene's title or a
    body's name would reach the terminal as a command; a direction override would reorder the
    line), line breaks and tabs kept, other text (no-break spaces, joiners) as it is."""
    if text.isprintable():
        return text
    return "".join(c.encode("unicode_escape").decode() if (unicodedata.category(c) == "Cc" and c not in "\n\t")
                   or c in _BIDI_CONTROLS else c for c in text)


def emit(text: str) -> None:
    """A line on stdout, flushed.  A reader that went away (a closed pipe: ``| head -1``)
    ends the output quietly; any other failure raises :class:`StdoutFailed`."""
    text = visible(text)
    try:
        try:
            print(text, flush=True)
        except UnicodeEncodeError:  # a terminal or locale that cannot show a scene's title: escaped
            encoding = sys.stdout.encoding or "ascii"
            print(text.encode(encoding, "backslashreplace").decode(encoding), flush=True)
    except BrokenPipeError:
        discard(sys.stdout)
    except OSError as error:
        discard(sys.stdout)
        raise StdoutFailed(error.strerror or str(error)) from None


def say(kind: str, message: str) -> None:
    """One line on stderr: ``femgrid-mpm: KIND: message`` (nothing if stderr cannot be written);
    a progress bar drawn there is cleared first and drawn again below (the kernels compile,
    and say so, inside the first step, after the run's bar is drawn)."""
    from tqdm import tqdm

    try:
        with tqdm.external_write_mode(file=sys.stderr):
            print(f"{PROG}: {kind}: {visible(' '.join(str(message).split()))}", file=sys.stderr, flush=True)
    except OSError:
        discard(sys.stderr)


def show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as one line (:func:`say`), for ``warnings.showwarning``."""
    say("warning", str(message))
