"""SIGINT, SIGTERM and SIGHUP during a run: one interrupt, then a shutdown no signal breaks.

The first of them raises :class:`Interrupted` in the main thread (a
``KeyboardInterrupt``, so every atomic write on the way removes its
temporary file); every later one is only recorded, so the outputs are
written whole and the exit code is ``128 + the first signal`` (130, 143,
129).  While the handlers are *calm* (the start and the end of a run, when
files are being written), a signal is recorded only; arming them again
raises it then.
"""

from __future__ import annotations

import os
import signal
import threading

#: the longest a signal waits for the step under way to end (s)
STEP_WAIT = 2.0
#: the signals that end a run as an interrupt, and their exit codes (128 + the number)
HANDLED = {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGHUP: 129}


class Interrupted(KeyboardInterrupt):
    """A run ended by a signal (Ctrl-C, ``kill``, a closed terminal)."""

    def __init__(self, signum: int, mid_step: bool = False):
        super().__init__(signum)
        self.signum = signum
        self.name = signal.Signals(signum).name
        self.exit_code = HANDLED.get(signum, 128 + signum)
        #: raised inside a step (a second signal before the step under way ended): the points
        #: may hold part of that step
        self.mid_step = mid_step


class RunSignals:
    """A context in which :data:`HANDLED` signals end the run as one :class:`Interrupted`.

    Entered calm (a signal is recorded, not raised); :meth:`arm` lets the
    next one raise (and raises one recorded meanwhile), :meth:`calm` stops
    that.  At most one :class:`Interrupted` is ever raised.  Outside the
    main thread, where Python cannot handle signals, it does nothing.
    """

    def __init__(self):
        self.received: int | None = None
        self.armed = False
        self.at_step_ends = False
        self.raised = False
        self._previous: dict = {}
        self._timer: threading.Timer | None = None

    def __enter__(self) -> "RunSignals":
        if threading.current_thread() is threading.main_thread():
            for signum in HANDLED:
                if signal.getsignal(signum) is signal.SIG_IGN:
                    continue  # ignored by who started us (nohup, a background job): it stays so
                self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        # after a signal the process is ending as interrupted: more of them (a burst of
        # Ctrl-C) are ignored to its exit, where Python's handler would raise in the middle
        # of the last line, or kill the process by the signal; so after one that a context
        # inside this one received (it left them ignored: a run inside a command)
        for signum, previous in self._previous.items():
            if self.received is not None or signal.getsignal(signum) == signal.SIG_IGN:
                signal.signal(signum, signal.SIG_IGN)
            else:
                signal.signal(signum, previous if previous is not None else signal.SIG_DFL)
        self._previous.clear()

    def _handle(self, signum, frame) -> None:
        first = self.received is None
        if first:
            self.received = signum
        if self.armed and self.at_step_ends and first:
            # the step under way ends first, but a supervisor's SIGTERM waits no more than
            # STEP_WAIT seconds for it (a first step compiles its kernels: 20-30 s)
            self._timer = threading.Timer(STEP_WAIT, os.kill, (os.getpid(), signum))
            self._timer.daemon = True
            self._timer.start()
        elif self.armed:  # a second one, or the wait's end: at once
            self._raise(mid_step=self.at_step_ends)

    def _raise(self, mid_step: bool = False) -> None:
        self.armed = False
        if self._timer is not None:
            self._timer.cancel()
        if not self.raised:
            self.raised = True
            raise Interrupted(self.received, mid_step)

    def arm(self, at_step_ends: bool = False) -> None:
        """Let a signal raise :class:`Interrupted`; one received while calm is raised now.
        ``at_step_ends``: the first one waits for :meth:`step_ended` (a step cut part way
        would leave the points half moved: stresses of one step, positions of the last), a
        second one, or the end of :data:`STEP_WAIT` seconds, raises at once (a step that does not
        end soon: a first compilation)."""
        self.armed, self.at_step_ends = True, at_step_ends
        if self.received is not None:
            self._raise()

    def step_ended(self) -> None:
        """Between two steps: raise the signal that came during the step."""
        if self.armed and self.received is not None:
            self._raise()

    def calm(self) -> None:
        """Signals from now on are recorded only."""
        self.armed = False
        if self._timer is not None:
            self._timer.cancel()
