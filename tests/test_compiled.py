"""The kernels' disk cache follows every module a kernel inlines (:mod:`femgrid_mpm.kernels.compiled`).

numba alone checks a cached kernel against its own file, so an edit of an
inlined helper in another file would load the old machine code.  These tests
build a two-module package in a temporary directory, run its kernel in fresh
processes, and edit the helper between the runs.
"""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from femgrid_mpm.kernels import compiled as compiled_module
from femgrid_mpm.kernels.compiled import PREFIX, cache_key, fingerprint


def _write_package(root: Path, value: float, note: str = "", inlining: str = 'inline="always"') -> None:
    package = root / "inlining"
    package.mkdir(exist_ok=True)
    (package / "__init__.py").write_text("")
    (package / "helpers.py").write_text(textwrap.dedent(f"""
        from femgrid_mpm.kernels.compiled import compiled

        @compiled({inlining})
        def constant():
            return {value!r}
        """))
    (package / "kernels.py").write_text(textwrap.dedent("""
        from femgrid_mpm.kernels.compiled import compiled
        from .helpers import constant

        @compiled()
        def kernel(x):
            return x * constant()
        """))
    (package / "notes.py").write_text(f"TEXT = {note!r}\n")  # mentions neither numba nor the decorator


def _run_kernel(root: Path, cache: Path, stderr: list | None = None) -> tuple[float, bool]:
    """The kernel's value at 1.0 in a fresh process, and whether it was loaded from the cache."""
    program = ("from inlining.kernels import kernel; value = kernel(1.0); "
               "print(value, bool(kernel.stats.cache_hits))")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(root))
    result = subprocess.run([sys.executable, "-c", program], env=env, capture_output=True, text=True, check=True)
    if stderr is not None:
        stderr.append(result.stderr)
    value, hit = result.stdout.split()
    return float(value), hit == "True"


@pytest.mark.parametrize("inlining", ['inline="always"', "forceinline=True"])
def test_an_edit_of_an_inlined_helper_recompiles_the_kernel(tmp_path, inlining):
    """Inlined in numba's IR or by LLVM (the library's helpers), an edit of the helper alone
    gives the caller a fresh compilation."""
    cache = tmp_path / "cache"
    _write_package(tmp_path, 1.0, inlining=inlining)
    assert _run_kernel(tmp_path, cache) == (1.0, False)  # compiled
    assert _run_kernel(tmp_path, cache) == (1.0, True)   # loaded
    _write_package(tmp_path, 2.0, inlining=inlining)  # kernels.py unchanged: plain numba would load 1.0 here
    assert _run_kernel(tmp_path, cache) == (2.0, False)
    assert _run_kernel(tmp_path, cache) == (2.0, True)
    (own,) = cache.iterdir()  # one directory for this package's path
    assert len(list(own.glob(PREFIX + "*"))) == 2


def test_without_a_writable_cache_directory_kernels_compile_in_every_process(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    cache = blocker / "cache"  # cannot be made: numba's own locators would load stale code here
    _write_package(tmp_path, 1.0)
    messages = []
    assert _run_kernel(tmp_path, cache, messages) == (1.0, False)
    assert "no writable cache directory" in messages[0]
    _write_package(tmp_path, 2.0)
    assert _run_kernel(tmp_path, cache) == (2.0, False)
    assert not list(tmp_path.rglob("*.nbi"))  # numba's own locators were not used


def test_the_fingerprint_covers_the_modules_that_compile_and_only_them(tmp_path):
    _write_package(tmp_path, 1.0, note="first")
    root = tmp_path / "inlining"
    first = fingerprint(root)
    _write_package(tmp_path, 1.0, note="second")  # a module without kernels changed
    assert fingerprint(root) == first
    _write_package(tmp_path, 3.0, note="second")
    assert fingerprint(root) != first
    assert len(first) == 16


def test_a_single_module_is_its_own_root(tmp_path):
    module = tmp_path / "script.py"
    module.write_text("import numba\n")
    first = fingerprint(module)
    (tmp_path / "other.py").write_text("import numba\n")  # a neighbour is not part of it
    assert fingerprint(module) == first
    module.write_text("import numba  # edited\n")
    assert fingerprint(module) != first


def test_the_library_kernels_use_the_fingerprinted_directory():
    from femgrid_mpm.kernels import g2p, p2g

    import femgrid_mpm.mass.cg as mass

    for kernel in (p2g.tensor_p2g_sums, g2p.local_g2p, mass._compiled_cg):
        directory = Path(kernel._cache._cache_path).parent
        assert directory.name == PREFIX + fingerprint(Path(p2g.__file__).parents[1])


def test_numbas_own_cache_files_are_removed_from_the_package(tmp_path):
    _write_package(tmp_path, 1.0)
    pycache = tmp_path / "inlining" / "__pycache__"
    pycache.mkdir()
    stale = [pycache / "kernels.kernel-5.py311.nbi", pycache / "kernels.kernel-5.py311.1.nbc"]
    for path in stale:
        path.write_bytes(b"")  # as numba's in-tree locator names them
    bytecode = pycache / "kernels.cpython-311.pyc"
    bytecode.write_bytes(b"")
    env = dict(os.environ, PYTHONPATH=str(tmp_path))
    env.pop("NUMBA_CACHE_DIR", None)  # the in-tree cache
    subprocess.run([sys.executable, "-c", "from inlining.kernels import kernel; kernel(1.0)"], env=env, check=True)
    assert not any(path.exists() for path in stale)
    assert bytecode.exists()
    (own,) = pycache.glob(PREFIX + "*")
    assert list(own.rglob("*.nbi"))  # the kernel's cache, kept


def test_code_outside_the_library_is_keyed_by_the_library_too(tmp_path, monkeypatch):
    """A kernel outside the library (the yardstick) inlines the library's helpers: an edit
    of the library must give it a new cache too."""
    _write_package(tmp_path, 1.0)
    package = tmp_path / "inlining"
    library = tmp_path / "library"
    library.mkdir()
    (library / "helpers.py").write_text("import numba\n")
    monkeypatch.setattr(compiled_module, "LIBRARY", library)
    first = cache_key(package)
    assert cache_key(library) == fingerprint(library)
    (library / "helpers.py").write_text("import numba  # edited\n")
    assert cache_key(package) != first


def _save_many(directory: str, worker: int, count: int, locked: bool) -> None:
    """One process' saves of ``count`` entries of its own into one kernel's cache files."""
    from numba.core.caching import IndexDataCacheFile

    cache_file = IndexDataCacheFile(cache_path=directory, filename_base="kernel", source_stamp=("stamp", 1))
    for entry in range(count):
        key, data = (f"signature {worker} {entry}",), ("machine code of", worker, entry)
        if locked:
            compiled_module.locked_save(cache_file, Path(directory) / compiled_module.LOCK, key, data)
        else:
            cache_file.save(key, data)


def test_processes_that_compile_into_one_cache_at_once_keep_every_entry_as_its_own(tmp_path):
    """Four processes save 30 specialisations each of one kernel at once (a sweep's workers
    on a cold cache): every key loads the data saved under it (numba's unlocked save, run
    the same way here, lost entries or swapped their data in most runs)."""
    import multiprocessing
    from numba.core.caching import IndexDataCacheFile

    workers, count = 4, 30
    context = multiprocessing.get_context("spawn")
    processes = [context.Process(target=_save_many, args=(str(tmp_path), w, count, True)) for w in range(workers)]
    for process in processes:
        process.start()
    for process in processes:
        process.join(60)
        assert process.exitcode == 0
    cache_file = IndexDataCacheFile(cache_path=str(tmp_path), filename_base="kernel", source_stamp=("stamp", 1))
    loaded = {(w, e): cache_file.load((f"signature {w} {e}",)) for w in range(workers) for e in range(count)}
    assert loaded == {(w, e): ("machine code of", w, e) for w in range(workers) for e in range(count)}


def test_the_library_kernels_save_under_the_lock():
    from femgrid_mpm.kernels import g2p

    save = g2p.density_factor._cache._cache_file.save
    assert save.func is compiled_module.locked_save
    assert save.args[1].name == compiled_module.LOCK
