"""The ``femgrid-mpm`` command line: ``run``, ``resume``, ``info`` and ``reproduce``.

Exit codes (:data:`EXIT_CODES`): 0 done; 2 bad input (a scene file, an
argument, an output directory that cannot be written), reported as one line
naming the file and the key, never a traceback, before anything is written;
3 the simulation stopped on a numerical event (negative mass under policy
``"error"``, a singular consistent mass, NaN, a runaway energy, a particle
leaving the grid), with every output written so far kept valid; 1 the outputs could not be
written during the run (e.g. a full disk); 130 interrupted (Ctrl-C), outputs
so far kept.  The library raises; only this package exits.

Its modules: :mod:`~femgrid_mpm.cli.parser` (the arguments, the exit codes,
the one-line messages), :mod:`~femgrid_mpm.cli.scene_input` (the scene of the
arguments, checked and built), one module per command (:mod:`~femgrid_mpm.cli.run`
for ``run`` and ``resume``, :mod:`~femgrid_mpm.cli.info`,
:mod:`~femgrid_mpm.cli.reproduce`) and :mod:`~femgrid_mpm.cli.progress` (the
progress bar).  None of them loads numpy at import: the libraries load inside
:func:`main`, where a Ctrl-C is one line.
"""

from __future__ import annotations

import warnings

from . import info, parser, reproduce, run
from .parser import (EXIT_BAD_INPUT, EXIT_CODES, EXIT_DONE, EXIT_INTERRUPTED, EXIT_STOPPED, EXIT_WRITE_FAILED, PROG,
                     BadInput, say, show_warning)

__all__ = ["main", "BadInput", "PROG", "EXIT_CODES", "EXIT_DONE", "EXIT_WRITE_FAILED", "EXIT_BAD_INPUT",
           "EXIT_STOPPED", "EXIT_INTERRUPTED"]

#: the function of each command
COMMANDS = {"run": run.run, "resume": run.resume, "info": info.info, "reproduce": reproduce.reproduce}


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code (see :data:`EXIT_CODES`)."""
    try:
        try:
            args = parser.build_parser().parse_args(argv)
        except SystemExit as exit_:  # --help (0) or a usage error (2, printed as one line)
            return exit_.code if isinstance(exit_.code, int) else EXIT_BAD_INPUT
    except KeyboardInterrupt:  # while the libraries load (about a second)
        say("interrupted", "stopped by the user")
        return EXIT_INTERRUPTED
    with warnings.catch_warnings():
        warnings.showwarning = show_warning
        try:
            return COMMANDS[args.command](args)
        except BadInput as error:
            say("error", str(error))
            return EXIT_BAD_INPUT
        except KeyboardInterrupt:  # outside a run (a run writes its outputs first)
            say("interrupted", "stopped by the user")
            return EXIT_INTERRUPTED
