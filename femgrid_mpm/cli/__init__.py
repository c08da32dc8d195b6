"""The ``femgrid-mpm`` command line: ``run``, ``resume``, ``info``, ``plot``, ``reproduce``, ``sweep`` and ``report``.

Exit codes (:data:`EXIT_CODES`): 0 done; 2 bad input (a scene file, an
argument, an output directory that cannot be written), reported as one line
naming the file and the key, never a traceback, before anything is written;
3 the simulation stopped on a numerical event (negative mass under policy
``"error"``, a singular consistent mass, NaN, a runaway energy, a particle
leaving the grid), with every output written so far kept valid; 1 the outputs could not be
written during the run (e.g. a full disk), or standard output could not; 130, 143, 129
interrupted by SIGINT (Ctrl-C), SIGTERM or SIGHUP, outputs so far kept.  A closed pipe on
standard output ends the output quietly.  The library raises; only this package exits.

Its modules: :mod:`~femgrid_mpm.cli.parser` (the arguments, the exit codes,
the one-line messages), :mod:`~femgrid_mpm.cli.scene_input` (the scene of the
arguments, checked and built), one module per command (:mod:`~femgrid_mpm.cli.run`
for ``run`` and ``resume``, :mod:`~femgrid_mpm.cli.info`, :mod:`~femgrid_mpm.cli.plot`,
:mod:`~femgrid_mpm.cli.reproduce`, :mod:`~femgrid_mpm.cli.sweep` for ``sweep`` and ``report``),
:mod:`~femgrid_mpm.cli.progress` (the progress bars) and :mod:`~femgrid_mpm.cli.notes` (the library's
notes, one line each).  None of them loads numpy at import: the libraries load inside
:func:`main`, where a Ctrl-C is one line.
"""

from __future__ import annotations

import signal
import sys
import warnings

from . import info, parser, plot, reproduce, run, sweep
from .notes import shown_notes
from .parser import (EXIT_BAD_INPUT, EXIT_CODES, EXIT_DONE, EXIT_HANGUP, EXIT_INTERRUPTED, EXIT_STOPPED,
                     EXIT_TERMINATED, EXIT_WRITE_FAILED, PROG, BadInput, StdoutFailed, discard, say, show_warning)
from .signals import HANDLED, Interrupted, RunSignals

__all__ = ["main", "BadInput", "PROG", "EXIT_CODES", "EXIT_DONE", "EXIT_WRITE_FAILED", "EXIT_BAD_INPUT",
           "EXIT_STOPPED", "EXIT_INTERRUPTED", "EXIT_TERMINATED", "EXIT_HANGUP"]

#: the function of each command
COMMANDS = {"run": run.run, "resume": run.resume, "info": info.info, "plot": plot.plot, "reproduce": reproduce.reproduce,
            "sweep": sweep.sweep, "report": sweep.report}


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code (see :data:`EXIT_CODES`).

    SIGINT, SIGTERM and SIGHUP end every command as an interrupt (130, 143, 129 and one
    ``interrupted:`` line; :class:`~femgrid_mpm.cli.signals.RunSignals`), not only a run:
    ``kill`` of a ``reproduce`` or a ``sweep`` unwinds like a Ctrl-C, closing what it started."""
    with RunSignals() as signals:
        signals.arm()
        try:
            code = dispatch(argv)
        except Interrupted as interrupt:  # outside a command's own handling (a run's, a sweep's)
            code = interrupted(interrupt.signum)
        except KeyboardInterrupt:  # Python's own, where a signal is not ours to handle
            code = interrupted(signal.SIGINT)
        except Exception:  # noqa: BLE001 -- ours raised where a library swallows it (numba's
            # compiler callbacks), which then fails on: the signal is what ended the command
            if signals.received is None:
                raise
            code = interrupted(signals.received)
        if code == EXIT_INTERRUPTED and signals.received is not None:
            # a command that ends a Ctrl-C its own way (sweep) returns 130 whatever the signal
            code = HANDLED[signals.received]
        return code


def interrupted(signum: int) -> int:
    """The line of an interrupt outside a run, and its exit code."""
    say("interrupted", "stopped by the user" if signum == signal.SIGINT else f"by {signal.Signals(signum).name}")
    return HANDLED[signum]


def dispatch(argv: list[str] | None) -> int:
    """Parse ``argv`` and run its command; its exit code."""
    try:
        try:
            args = parser.build_parser().parse_args(argv)
        except SystemExit as exit_:  # --help (0) or a usage error (2, printed as one line)
            return exit_.code if isinstance(exit_.code, int) else EXIT_BAD_INPUT
    except BrokenPipeError:  # --help into a closed pipe
        discard(sys.stdout)
        return EXIT_DONE
    except OSError as error:  # --help into a full disk
        discard(sys.stdout)
        say("error", f"cannot write to standard output: {error.strerror or error}")
        return EXIT_WRITE_FAILED
    with warnings.catch_warnings(), shown_notes():
        warnings.showwarning = show_warning
        try:
            return COMMANDS[args.command](args)
        except BadInput as error:
            say("error", str(error))
            return EXIT_BAD_INPUT
        except StdoutFailed as error:
            say("error", f"cannot write to standard output: {error}")
            return EXIT_WRITE_FAILED
