"""The set-up of a local cluster's worker process: a Dask preload (:func:`dask_setup`).

A Ctrl-C on a terminal is a SIGINT to every process of its group, and closing the terminal
a SIGHUP, the workers of a local cluster included.  The sweep's own process handles them (it
closes the cluster, which ends the workers, and says so in one line); a worker that took them
as well would print its own traceback on the shared stderr.  A worker starts with
:data:`TERMINAL_SIGNALS` blocked (the sweep blocks them while its cluster starts, and the
threads that spawn the workers inherit that mask), so none reaches it before this set-up.
SIGTERM is left alone: it ends a worker without a word, and a cluster's close may need it.
"""

from __future__ import annotations

import signal
import threading

#: the signals a terminal sends its whole process group: Ctrl-C and a hang-up
TERMINAL_SIGNALS = frozenset({signal.SIGINT, signal.SIGHUP})


def dask_setup(worker) -> None:
    """Ignore SIGINT and SIGHUP in this worker's process."""
    if threading.current_thread() is threading.main_thread():  # the worker's event loop: its main thread
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGHUP, signal.SIG_IGN)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, TERMINAL_SIGNALS)
