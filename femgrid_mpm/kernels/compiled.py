"""``compiled``: numba's ``njit(cache=True)``, with a cache that knows what a kernel inlines.

numba checks a cached kernel against the text of its own source file only.
The kernels here inline helpers from other modules (``shape.located_weights``
into every pass of ``p2g``, ``force`` and ``g2p``, ``arithmetic.fused``
everywhere), so after an edit of ``shape.py`` alone numba would load the
passes compiled from its old text, silently (seen here: P2G kept an
inside-grid test that had been edited out of the module it inlines).
:func:`compiled` therefore caches every kernel in
a directory named by a fingerprint of all modules of the kernel's package
that mention numba or this decorator: an edit of any of them gives a new
directory and a fresh compilation (43-49 CPU s for every kernel `reproduce` runs), an
unchanged tree loads in about a second.

Where (:func:`cache_directory`): ``<package>/__pycache__/numba-<fingerprint>``
if the package's directory is writable, else
``$XDG_CACHE_HOME/femgrid-mpm/<package>-<path hash>/numba-<fingerprint>``
(``~/.cache`` without ``XDG_CACHE_HOME``); with ``$NUMBA_CACHE_DIR`` set,
``$NUMBA_CACHE_DIR/<package>-<path hash>/numba-<fingerprint>``.  Beside the
current fingerprint the ``KEPT`` most recent ones are kept, and no directory
used in the last ``KEEP_DAYS`` days is removed (a long run may still write to
its own); the files of numba's own in-tree cache are removed from the
package's ``__pycache__`` directories.  Where no directory is writable,
kernels are compiled in every process, with one warning: loading from a cache
that cannot be keyed would bring back the stale kernels.

Processes that compile into one directory at once (a sweep's workers) save each
kernel under a lock (:func:`locked_save`): numba's own save lets them lose or swap
each other's entries.

A first use compiles for a few seconds to under a minute: :func:`note_compilation` says so
once, on the ``femgrid_mpm`` logger (INFO, which the command line shows as one
line), when numba starts compiling one of the library's functions and the tree's
cache holds no kernel yet.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import itertools
import logging
import os
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numba
from numba.core import event as numba_event
from numba.core.caching import IndexDataCacheFile

try:
    import fcntl
except ImportError:  # Windows: numba's own save, unlocked
    fcntl = None

#: fingerprint directories kept beside the current one (older trees, other runs)
KEPT = 4
#: and none used this recently is removed, whatever their number
KEEP_DAYS = 7
PREFIX = "numba-"
#: this library's package directory: code elsewhere that uses :func:`compiled` may inline its helpers
LIBRARY = Path(__file__).resolve().parents[1]


def fingerprint(root: Path) -> str:
    """SHA-256 (16 hex digits) of every ``.py`` file under ``root`` (a package's
    directory, or one module's file) that mentions ``numba`` or ``compiled``, with
    their paths: the modules whose functions (and global constants, which numba
    freezes) a kernel may compile or inline.  An edit elsewhere (the command
    line, scene loading) keeps the compiled kernels."""
    digest = hashlib.sha256(numba.__version__.encode())
    files = [root] if root.is_file() else sorted(root.rglob("*.py"))
    for path in files:
        text = path.read_bytes()
        if b"numba" in text or b"compiled" in text:
            name = path.name if root.is_file() else path.relative_to(root).as_posix()
            digest.update(name.encode() + b"\0" + text + b"\0")
    return digest.hexdigest()[:16]


def cache_key(root: Path) -> str:
    """The fingerprint that names ``root``'s cache: :func:`fingerprint` of ``root``, and
    for code outside this library also of the library, whose helpers (``fused``,
    ``quotient``, ``density_factor``) such code may inline (``benchmarks/minimal_q1.py``)."""
    own = fingerprint(root)
    if root == LIBRARY:
        return own
    return hashlib.sha256(f"{own} {fingerprint(LIBRARY)}".encode()).hexdigest()[:16]


def cache_is_cold(directory: Path | None) -> bool:
    """No kernel is cached in ``directory`` (a :func:`cache_directory`; None: nothing is
    ever cached), so the first run compiles them."""
    return directory is None or not any(directory.rglob("*.nbi"))


@functools.lru_cache(maxsize=None)
def note_compilation() -> bool:
    """Once per process: log that the kernels are about to be compiled if this tree's
    cache is cold (:func:`cache_is_cold`); returns whether it did.  Called when numba starts
    compiling one of this library's functions (:class:`FirstCompilation`), so a command that
    compiles nothing (``femgrid-mpm info``) says nothing."""
    directory = cache_directory(LIBRARY)
    if not cache_is_cold(directory):
        return False
    where = (f"they are cached in {directory} and load in about a second from then on" if directory is not None
             else "no cache directory is writable, so every process compiles them")
    logging.getLogger("femgrid_mpm").info(
        "compiling the numba kernels, seconds to a minute on first use (only once: %s)", where)
    return True


class FirstCompilation(numba_event.Listener):
    """numba's ``"numba:compile"`` event (broadcast on a cache miss, when a dispatcher starts
    compiling) for this library's functions: :func:`note_compilation`.  Loading a cached
    kernel broadcasts nothing."""

    def on_start(self, event) -> None:
        module = event.data["dispatcher"].py_func.__module__ or ""  # None for numba's generated functions
        if module.startswith(f"{LIBRARY.name}."):
            note_compilation()

    def on_end(self, event) -> None:
        pass


numba_event.register("numba:compile", FirstCompilation())


def _writable(directory: Path) -> bool:
    try:
        directory.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=directory).close()
    except OSError:
        return False
    return True


def _bases(root: Path) -> list[Path]:
    """Where the cache may go, in order of preference."""
    # outside the package, one directory per package path: checkouts do not prune each other
    own = f"{root.stem}-{hashlib.sha1(str(root).encode()).hexdigest()[:8]}"
    if os.environ.get("NUMBA_CACHE_DIR"):
        return [Path(os.environ["NUMBA_CACHE_DIR"]) / own]
    in_tree = (root if root.is_dir() else root.parent) / "__pycache__"
    user = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "femgrid-mpm" / own
    return [in_tree, user]


def _remove_unkeyed(root: Path) -> None:
    """Remove the files numba's own in-tree cache left in the package's ``__pycache__``
    directories (before :func:`compiled`, or by a plain ``numba.njit(cache=True)``):
    they are never read again, and would be the stale ones if they were."""
    if not root.is_dir():
        return
    for pattern in ("*.nbi", "*.nbc"):
        for stale in root.glob(f"**/__pycache__/{pattern}"):
            if not any(part.startswith(PREFIX) for part in stale.relative_to(root).parts):
                stale.unlink(missing_ok=True)


def _prune(base: Path, current: Path) -> None:
    """Remove fingerprint directories beyond the ``KEPT`` most recent that are unused
    for ``KEEP_DAYS``."""
    try:
        others = sorted((d for d in base.glob(PREFIX + "*") if d != current and d.is_dir()),
                        key=lambda d: d.stat().st_mtime, reverse=True)
        old = time.time() - KEEP_DAYS * 86400
        stale = [d for d in others[KEPT:] if d.stat().st_mtime < old]
    except OSError:
        return
    for directory in stale:
        shutil.rmtree(directory, ignore_errors=True)


@functools.lru_cache(maxsize=None)
def cache_directory(root: Path) -> Path | None:
    """The cache directory of the kernels of the package (or module) at ``root``,
    made, marked as used and with old ones pruned; None if none can be written."""
    name = PREFIX + cache_key(root)
    for base in _bases(root):
        directory = base / name
        if _writable(directory):
            os.utime(directory)  # most recently used, for the pruning of other processes
            _prune(base, directory)
            if base.name == "__pycache__":
                _remove_unkeyed(root)
            return directory
    warnings.warn(f"femgrid-mpm: no writable cache directory for the kernels of {root} (tried "
                  f"{', '.join(str(b) for b in _bases(root))}): they are compiled in every process",
                  RuntimeWarning, stacklevel=3)
    return None


def _source_root(function) -> Path | None:
    """The directory of the function's top-level package, or its module's file if that is
    no package; None for code without a source file (a REPL, a notebook cell)."""
    top = sys.modules.get(function.__module__.partition(".")[0])
    source = getattr(top, "__file__", None)
    if source is None:
        return None
    path = Path(source).resolve()
    return path.parent if path.name == "__init__.py" else path


def compiled(**options):
    """``numba.njit(cache=True, **options)``, cached in :func:`cache_directory` of the
    function's package.

    numba picks a function's cache directory when it is decorated (from
    ``numba.config.CACHE_DIR``); the setting is ours only for that moment, so
    other numba code in the process keeps its own.  ``cache=False``, code without
    a source file (a REPL, a notebook cell) and a tree with no writable cache
    directory compile in every process.

    >>> from femgrid_mpm.kernels import g2p
    >>> root = _source_root(g2p.density_factor.py_func)
    >>> g2p.density_factor._cache._cache_path.startswith(str(cache_directory(root)))
    True
    """
    cache = options.pop("cache", True)
    # numba passes a caller's forceinline on to a callee that does not set it, so a kernel first
    # compiled for a forceinline helper would be always-inline in one cache and not in another
    options.setdefault("forceinline", False)

    def decorate(function):
        root = _source_root(function) if cache else None
        directory = cache_directory(root) if root is not None else None
        if directory is None:
            return numba.njit(**options)(function)
        previous = numba.config.CACHE_DIR
        numba.config.CACHE_DIR = str(directory)
        try:
            kernel = numba.njit(cache=True, **options)(function)
        finally:
            numba.config.CACHE_DIR = previous
        if isinstance(kernel._cache._cache_file, IndexDataCacheFile):
            kernel._cache._cache_file.save = functools.partial(locked_save, kernel._cache._cache_file,
                                                               directory / LOCK)
        return kernel
    return decorate


#: the file whose lock makes one cache entry's writes (index and data) one step for all processes
LOCK = ".lock"


@contextlib.contextmanager
def _exclusive(path: Path):
    """An exclusive lock on ``path`` between processes; none where ``fcntl`` is missing or the
    file system refuses it (some network file systems): numba's own save then, unlocked."""
    handle = None
    if fcntl is not None:
        try:
            handle = open(path, "a")
            fcntl.flock(handle, fcntl.LOCK_EX)
        except OSError:
            if handle is not None:
                handle.close()
            handle = None
    try:
        yield
    finally:
        if handle is not None:
            handle.close()  # closing releases the lock


def locked_save(cache_file: IndexDataCacheFile, lock: Path, key, data) -> None:
    """numba's ``IndexDataCacheFile.save`` made safe for processes that compile into one
    directory at once (a sweep's Dask workers on a cold cache).

    numba reads the kernel's index, picks the first free data file's name, writes the
    index and then the data.  Two processes that save two specialisations of one kernel
    at once read the same index and pick the same name: one index entry is lost, and the
    data file may end up holding the other specialisation's machine code under this one's
    key, which a later process loads and runs on arguments of the wrong types.  Here the
    whole save holds an exclusive lock on the directory's :data:`LOCK`, and the data is
    written before the index that names it, so a process that loads (unlocked) finds either
    no entry or a complete one."""
    with _exclusive(lock):
        overloads = cache_file._load_index()
        name = overloads.get(key)
        if name is None:
            taken = set(overloads.values())
            name = next(n for n in map(cache_file._data_name, itertools.count(1)) if n not in taken)
        cache_file._save_data(name, data)
        overloads[key] = name
        cache_file._save_index(overloads)
