"""The library's notes (the ``femgrid_mpm`` logger at INFO, e.g. that the kernels are being
built on first use) as one line each on stderr, while a command runs."""

from __future__ import annotations

import contextlib
import logging

from .parser import say


class _OneLine(logging.Handler):
    def emit(self, record: logging.LogRecord) -> None:
        say("note", record.getMessage())


@contextlib.contextmanager
def shown_notes():
    """``femgrid-mpm: note: ...`` for every INFO record of the ``femgrid_mpm`` logger (and
    above; warnings go through :mod:`warnings`) for the duration."""
    logger, handler = logging.getLogger("femgrid_mpm"), _OneLine(logging.INFO)
    level, propagate = logger.level, logger.propagate
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False  # one line, not also the root logger's
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
        logger.propagate = propagate
