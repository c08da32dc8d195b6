"""``compiled``: numba's ``njit(cache=True)``, with a cache that knows what a kernel inlines.

numba checks a cached kernel against the text of its own source file only.
The kernels here inline helpers from other modules (``basis.located_weights``
into every pass of ``transfer``, ``arithmetic.fused`` everywhere), so after an
edit of ``basis.py`` alone numba would load the transfers compiled from its
old text, silently (seen here: P2G kept an inside-grid test that had been
edited out of ``basis.py``).  :func:`compiled` therefore caches every kernel in
a directory named by a fingerprint of all modules of the kernel's package
that use numba: an edit of any of them gives a new directory and a fresh
compilation (about a minute for every kernel), an unchanged tree loads in
about a second.

Where (``cache_directory``): under ``$NUMBA_CACHE_DIR`` if set, else in the
package's ``__pycache__`` if writable, else in ``$XDG_CACHE_HOME/femgrid-mpm``
(``~/.cache/femgrid-mpm``); the few most recent fingerprints are kept there.
"""

from __future__ import annotations

import functools
import hashlib
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numba

#: fingerprint directories kept beside the current one (older trees, other checkouts' runs)
KEPT = 4
PREFIX = "numba-"


def fingerprint(root: Path) -> str:
    """SHA-256 (16 hex digits) of every ``.py`` file under ``root`` that mentions ``numba``
    or ``compiled``, with their paths: the modules whose functions (and global
    constants, which numba freezes) a kernel may compile or inline.  An edit
    elsewhere (the command line, scene loading) keeps the compiled kernels."""
    digest = hashlib.sha256(numba.__version__.encode())
    for path in sorted(root.rglob("*.py")):
        text = path.read_bytes()
        if b"numba" in text or b"compiled" in text:
            digest.update(path.relative_to(root).as_posix().encode() + b"\0" + text + b"\0")
    return digest.hexdigest()[:16]


def _writable(directory: Path) -> bool:
    try:
        directory.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=directory).close()
    except OSError:
        return False
    return True


def _base(root: Path) -> Path:
    if os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"]) / root.name
    in_tree = root / "__pycache__"
    if _writable(in_tree):
        return in_tree
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "femgrid-mpm" / root.name


def _prune(base: Path, current: Path) -> None:
    """Keep the ``KEPT`` most recently used fingerprint directories besides ``current``."""
    try:
        others = sorted((d for d in base.glob(PREFIX + "*") if d != current and d.is_dir()),
                        key=lambda d: d.stat().st_mtime, reverse=True)
    except OSError:
        return
    for stale in others[KEPT:]:
        shutil.rmtree(stale, ignore_errors=True)


@functools.lru_cache(maxsize=None)
def cache_directory(root: Path) -> Path:
    """The cache directory of the kernels of the package at ``root`` (made, and old ones pruned)."""
    base = _base(root)
    directory = base / (PREFIX + fingerprint(root))
    if _writable(directory):
        os.utime(directory)  # most recently used, for the pruning of other processes
        _prune(base, directory)
    return directory


def _package_root(function) -> Path:
    top = sys.modules[function.__module__.partition(".")[0]]
    path = Path(top.__file__).resolve()
    return path.parent if path.name == "__init__.py" else path.parent


def compiled(**options):
    """``numba.njit(cache=True, **options)``, cached in :func:`cache_directory` of the
    function's package.

    numba picks a function's cache directory when it is decorated (from
    ``numba.config.CACHE_DIR``); the setting is ours only for that moment, so
    other numba code in the process keeps its own.

    >>> from femgrid_mpm.kernels import transfer
    >>> str(cache_directory(_package_root(transfer.density_factor))) in transfer.density_factor._cache._cache_path
    True
    """
    def decorate(function):
        directory = cache_directory(_package_root(function))
        previous = numba.config.CACHE_DIR
        numba.config.CACHE_DIR = str(directory)
        try:
            return numba.njit(cache=True, **options)(function)
        finally:
            numba.config.CACHE_DIR = previous
    return decorate
