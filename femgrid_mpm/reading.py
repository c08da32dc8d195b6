"""Reading an input file: a regular file only, and at most a stated size.

A scene named ``/dev/zero`` would be read until memory runs out, a FIFO
would block for ever on its open; both are refused in one line, before any
byte is read.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

#: the largest scene file read (a scene of 4000 bodies is about 1 MB)
MAX_SCENE_BYTES = 16 * 2**20


class FileRefused(OSError):
    """An input that is not a regular file, or is larger than the limit; the message is one line."""


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def read_regular_file(path, limit: int = MAX_SCENE_BYTES) -> bytes:
    """The bytes of ``path`` if it is a regular file (symbolic links followed) of at most ``limit`` bytes.

    Raises
    ------
    FileNotFoundError, IsADirectoryError, PermissionError, OSError
        As ``open`` would.
    FileRefused
        For a FIFO, a device or a socket (opened without blocking, not read),
        or a file larger than ``limit``.
    """
    path = Path(path)
    descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    with os.fdopen(descriptor, "rb", buffering=0) as handle:
        mode = os.fstat(descriptor)
        if stat.S_ISDIR(mode.st_mode):
            raise IsADirectoryError(errno.EISDIR, "is a directory", str(path))
        if not stat.S_ISREG(mode.st_mode):
            raise FileRefused(f"is {_kind(mode.st_mode)}; only a regular file is read")
        if mode.st_size > limit:
            raise FileRefused(f"is {mode.st_size} bytes, more than the {limit} read at most")
        chunks, total = [], 0
        while total <= limit:  # a regular file's size, read to its end (it may grow meanwhile)
            chunk = handle.read(max(mode.st_size - total, 0) + 1 if total < mode.st_size else 65536)
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
    data = b"".join(chunks)
    if len(data) > limit:  # it grew while being read
        raise FileRefused(f"is more than the {limit} bytes read at most")
    return data


class InputRefused(ValueError):
    """An input file that could not be read as TOML; the message is one line naming the file."""


def read_toml(path, what: str) -> dict:
    """The tables of the TOML file ``path`` (a ``what``: "scene file", "sweep file"), read as
    :func:`read_regular_file` reads.

    Raises
    ------
    InputRefused
        One line naming ``path``: missing, a directory, not a regular file, too large,
        unreadable, not UTF-8, not valid TOML, or nested too deeply for the TOML reader.
    """
    import tomllib

    path = Path(path)
    try:
        return tomllib.loads(read_regular_file(path).decode())
    except FileNotFoundError:
        problem = f"no such {what}"
    except IsADirectoryError:
        problem = f"is a directory, not a {what}"
    except tomllib.TOMLDecodeError as error:
        problem = f"not valid TOML: {error}"
    except RecursionError:
        problem = f"not valid TOML for a {what}: nested too deeply for the TOML reader"
    except OSError as error:
        problem = f"cannot be read: {error.strerror or error}"
    except UnicodeDecodeError as error:
        problem = f"cannot be read: {error}"
    raise InputRefused(" ".join(f"{path}: {problem}".split()))
