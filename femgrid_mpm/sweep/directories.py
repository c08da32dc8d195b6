"""A sweep's directory: the lock two sweeps into it would race for, and the replacement of its runs'
directories (``runs/<key>/``, made beside it as ``.KEY.PID.tmp`` and renamed over it when the
run has ended), with the temporaries a killed sweep leaves."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

#: a run's directory while it runs: ``.KEY.PID.tmp``, beside its final place
TEMPORARY_SUFFIX = ".tmp"


class SweepBusy(OSError):
    """Another sweep is running into the same directory; the message is one line."""


class SweepLock:
    """An exclusive lock on a sweep's directory (``flock`` on the directory itself, so that
    no file is left behind), held from the first write to the end of the sweep: two sweeps
    into one directory would replace each other's runs and ``runs.csv``."""

    def __init__(self, directory: Path):
        self.directory = Path(directory)
        self.descriptor: int | None = None

    def acquire(self) -> None:
        """Lock the directory (it must exist); raises :class:`SweepBusy` if another process holds it."""
        import fcntl

        if self.descriptor is not None:
            return
        descriptor = os.open(self.directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | os.O_CLOEXEC)
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(descriptor)
            raise SweepBusy(f"another sweep is running in {self.directory} (wait for it, or give another --out)") from None
        except OSError:  # a file system without locks: nothing to hold
            os.close(descriptor)
            return
        self.descriptor = descriptor

    def release(self) -> None:
        if self.descriptor is not None:
            os.close(self.descriptor)  # closing the descriptor releases the lock
            self.descriptor = None


def replace_directory(source: Path, target: Path) -> None:
    """``source`` renamed to ``target``; an earlier ``target`` (a run of another digest) is removed."""
    if target.exists() or target.is_symlink():
        old = target.with_name(f".{target.name}.{os.getpid()}.old")
        _remove(old)
        os.replace(target, old)
        os.replace(source, target)
        _remove(old)
    else:
        os.replace(source, target)


def _remove(path: Path) -> None:
    """``path`` gone if it can be: a directory with its contents, a file or a link itself."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        try:
            path.unlink(missing_ok=True)
        except OSError:
            pass


def remove_stale(runs_directory: Path) -> None:
    """Remove the temporaries of runs a killed sweep left (``.KEY.PID.tmp``, ``.KEY.PID.old``,
    the latter a file too where a file stood at ``KEY``); one whose process is alive on this
    machine is left alone."""
    if runs_directory.is_dir():
        for entry in runs_directory.iterdir():
            if entry.name.startswith(".") and entry.name.endswith((TEMPORARY_SUFFIX, ".old")):
                if not process_alive(entry.name.rsplit(".", 2)[-2]):
                    _remove(entry)


def process_alive(pid_text: str) -> bool:
    """Whether the process of this id (the text of a temporary's name) runs on this machine."""
    if not pid_text.isdigit() or not 0 < int(pid_text) < 2**31:
        return False
    try:
        os.kill(int(pid_text), 0)
    except ProcessLookupError:
        return False
    except OSError:  # it exists, owned by another user
        return True
    return True
