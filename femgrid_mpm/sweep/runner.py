"""Running a sweep's runs on Dask, each into ``DIR/runs/<key>/``, and finding the finished ones.

A run is the run of ``femgrid-mpm run SCENE --set ...`` with the same
overrides (:func:`compute_run`): its ``summary.json``, ``energy.csv``,
``final.npz`` and scene files, written by the worker into a temporary
directory beside ``DIR/runs/<key>/`` and renamed to it when the run has
ended, so a directory of that name is always a finished run.  Its
``sweep_run.json`` holds the digest of what it ran (:func:`run_digest`: the
scene as run, the overrides and the library's version); a later sweep
reuses the run when the digest is the same and computes it again otherwise.
``runs.csv`` is rewritten by the client as each run finishes, so a killed
sweep loses no finished run.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import shutil
import signal
import time as clock
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from .directories import TEMPORARY_SUFFIX, SweepLock, remove_stale, replace_directory
from .table import RUNS_FILE, row, run_failure, write_runs

RUNS_DIRECTORY = "runs"
MARKER_FILE = "sweep_run.json"
#: the preload of a local cluster's workers: Ctrl-C is the client's to handle
LOCAL_WORKER_SETUP = "femgrid_mpm.sweep.local_worker"
#: the most processes of a local cluster (each a Python with numba, ~200 MB): more is a typo
MAX_WORKERS = 256
#: runs.csv is rewritten whole, so at most this often (s) while runs finish, and at the end or
#: an interrupt: after each run it was quadratic (~30 GB written by a sweep of 10,000 runs).  A
#: sweep killed meanwhile loses no run: the next one reuses the finished runs' directories
TABLE_EVERY = 1.0


class SweepProgress(Protocol):
    """What a sweep reports as it goes (a progress bar, a log)."""

    def started(self, total: int, reused: int, running: list[str]) -> None:
        """``total`` runs, of which ``reused`` were finished before; ``running`` are those starting."""

    def finished(self, key: str, status: str, running: list[str]) -> None:
        """The run ``key`` ended with ``status``; ``running`` are those running now."""


@dataclass
class SweepCounts:
    """How many runs a sweep computed, reused from an earlier sweep, and how many failed; of
    those, how many could not write their files (a full disk), with the first such error."""

    computed: int = 0
    reused: int = 0
    failed: int = 0
    workers: int = 0
    unwritten: int = 0
    write_error: str = ""


def run_digest(planned) -> str:
    """SHA-256 of the scene as run (every default spelled out), the overrides and the
    library's version: a finished run with the same digest is the same run."""
    from .. import __version__
    from ..output import scene_to_toml

    text = "\n".join([scene_to_toml(planned.scene), json.dumps(planned.overrides, sort_keys=True), __version__])
    return hashlib.sha256(text.encode()).hexdigest()


def finished_summary(directory: Path, digest: str) -> dict | None:
    """The summary of the finished run in ``directory`` if it ran ``digest``, else None."""
    from ..output import SUMMARY_FILE
    from ..reading import read_regular_file

    try:  # a FIFO in a file's place is not opened for reading (it would block the sweep): no run
        marker = json.loads(read_regular_file(directory / MARKER_FILE))
        summary = json.loads(read_regular_file(directory / SUMMARY_FILE))
    except (OSError, ValueError):
        return None
    if not isinstance(marker, dict) or not isinstance(summary, dict) or marker.get("digest") != digest:
        return None
    if summary.get("status") not in ("completed", "stopped") or not _readable(summary):
        return None
    summary["workers"] = marker.get("workers")
    return summary


def _readable(summary: dict) -> bool:
    """Whether the fields a row takes from ``summary`` (:func:`.table.row`) have their types: a
    summary edited or damaged by hand is computed again, not written into ``runs.csv``."""
    def number(value) -> bool:
        return value is None or (isinstance(value, (int, float)) and not isinstance(value, bool))

    reference, consistent = summary.get("reference"), summary.get("consistent_mass")
    return (all(number(summary.get(key)) for key in ("steps", "points", "nodes", "dt", "wall_time", "energy_drift",
                                                     "critical_dt"))
            and (reference is None or (isinstance(reference, dict)
                                       and all(number(reference.get(key)) for key in ("error_end", "error_max",
                                                                                      "period_error"))))
            and (consistent is None or (isinstance(consistent, dict) and number(consistent.get("cg_iterations"))))
            and isinstance(summary.get("reason", ""), str))


def compute_run(scene_file: str, overrides: dict, directory: str, digest: str, workers: int) -> dict:
    """Run the scene with ``overrides`` into ``directory`` (on a worker) and return its
    summary, with ``"warnings"``: the warnings the run gave, one line each.

    A run that stops on a numerical event is a finished run (status ``stopped``).

    Raises
    ------
    ValueError
        If the simulation cannot be built from the scene (e.g. a support selects no node), or its
        records would exceed ``output.max_bytes``.
    OSError
        If the files cannot be written.
    """
    from ..diagnostics import SimulationStopped
    from ..output import RunOutputs, atomic_write
    from ..scene import load_scene
    from ..scene.limits import check_records
    from ..solver import Simulation

    final = Path(directory)
    temporary = final.with_name(f".{final.name}.{os.getpid()}{TEMPORARY_SUFFIX}")
    shutil.rmtree(temporary, ignore_errors=True)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            scene = load_scene(scene_file, overrides)
            outputs = RunOutputs(temporary, scene, source=scene_file, overrides=overrides)
            _warm_up(scene)
            simulation = Simulation(scene, observers=outputs.observers)
            # records beyond output.max_bytes are refused as `run` refuses them (a run goes to its end)
            check_records(scene, simulation.n_steps, simulation.particles.n, simulation.grid.n_nodes)
            _estimate_critical_dt(simulation)
            outputs.start(simulation)
            try:
                summary = outputs.finish(simulation.run())
            except SimulationStopped as stop:
                summary = outputs.finish(stop.result, stop)
        atomic_write(temporary / MARKER_FILE, json.dumps(
            {"key": final.name, "digest": digest, "overrides": overrides, "workers": workers}, indent=2) + "\n")
        replace_directory(temporary, final)
    except BaseException:
        shutil.rmtree(temporary, ignore_errors=True)
        raise
    summary["warnings"] = [" ".join(str(w.message).split()) for w in caught]
    summary["workers"] = workers
    return summary


#: the warm-up run: two steps of a microsecond
WARM_UP = {"time.dt": 1e-6, "time.end": 2e-6}


def _warm_up(scene) -> None:
    """Step a two-step copy of ``scene``, so that loading its compiled kernels (about a
    second the first time in a process) is not counted in the wall time of the run."""
    from ..diagnostics import SimulationStopped
    from ..solver import Simulation

    try:
        # its warnings are the two-step copy's (an energy balance over two steps, say), not the run's
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            Simulation(scene.with_overrides(**WARM_UP)).run()
    except (SimulationStopped, ValueError, ArithmeticError):
        pass  # the run itself reports what is wrong with its scene


def _estimate_critical_dt(simulation) -> None:
    """The critical step, estimated as ``femgrid-mpm run`` does before a run (it is in the
    summary); a warning if it exceeds the stable one."""
    try:
        critical = simulation.critical_dt
    except MemoryError:
        warnings.warn("the critical time step could not be estimated: not enough memory", RuntimeWarning)
        return
    if critical is not None and 0 < critical < simulation.dt:
        warnings.warn(f"dt = {simulation.dt:.6g} s exceeds the estimated critical time step {critical:.6g} s",
                      RuntimeWarning)


def run_sweep(planned_runs: list, out: Path, *, workers: int | None = None, scheduler: str | None = None,
              progress: SweepProgress | None = None, prepare=None) -> SweepCounts:
    """Compute the runs of ``planned_runs`` not finished in ``out`` on Dask and write ``out/runs.csv``.

    Parameters
    ----------
    planned_runs : list of PlannedRun
    out : Path
        The sweep's directory.
    workers : int, optional
        Runs at once on a local cluster (default: the number of cores), at most
        :data:`MAX_WORKERS` and the number of runs missing.
    scheduler : str, optional
        An existing Dask scheduler (``tcp://HOST:PORT``); its workers must see ``out``
        and the scene file at the same paths.
    progress : SweepProgress, optional
    prepare : callable, optional
        Called before anything is written in ``out`` (once the cluster is reached, if a run
        is missing): a scheduler that cannot be reached leaves ``out`` untouched.

    Raises
    ------
    OSError
        If a scheduler cannot be reached, or ``out`` cannot be written;
        :class:`SweepBusy` if another sweep holds ``out`` (:class:`SweepLock`).
    KeyboardInterrupt
        After closing the cluster; the finished runs and ``runs.csv`` are kept.
    ValueError
        If ``workers`` is not a whole number of at least 1 (before anything is written: a cluster of
        no worker would wait for ever).
    """
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ValueError(f"workers: must be a whole number of at least 1, or None for the number of cores "
                         f"(got {workers!r})")
    out = Path(out)
    lock = SweepLock(out)
    if out.is_dir():  # refused before a cluster is started
        lock.acquire()
    try:
        return _run_locked(planned_runs, out, lock, workers, scheduler, progress, prepare)
    finally:
        lock.release()


def _run_locked(planned_runs, out: Path, lock: SweepLock, workers, scheduler, progress, prepare) -> SweepCounts:
    runs_directory = out / RUNS_DIRECTORY
    varied = list(planned_runs[0].varied) if planned_runs else []
    digests = {planned.key: run_digest(planned) for planned in planned_runs}
    rows: dict[str, dict] = {}
    missing = []
    for planned in planned_runs:
        summary = finished_summary(runs_directory / planned.key, digests[planned.key])
        if summary is None:
            missing.append(planned)
        else:
            rows[planned.key] = row(planned, summary, summary.get("workers"))

    def write_table() -> None:
        write_runs(out / RUNS_FILE, varied, [rows[p.key] for p in planned_runs if p.key in rows])

    def start() -> None:
        out.mkdir(parents=True, exist_ok=True)
        lock.acquire()
        if prepare is not None:
            prepare()
        runs_directory.mkdir(parents=True, exist_ok=True)
        remove_stale(runs_directory)
        write_table()

    counts = SweepCounts(reused=len(rows))
    if not missing:
        start()
        if progress is not None:
            progress.started(len(planned_runs), len(rows), [])
        return counts
    started = False
    # no more processes than runs to compute
    try:
        with _dask_client(min(workers or os.cpu_count() or 1, MAX_WORKERS, len(missing)), scheduler) as (client, concurrency):
            from dask.distributed import as_completed

            start()
            started = True
            counts.workers = concurrency
            futures = {
                client.submit(compute_run, str(planned.scene_file), planned.overrides, str(runs_directory / planned.key),
                              digests[planned.key], concurrency, key=f"femgrid-run-{planned.key}-{digests[planned.key][:12]}",
                              pure=False): planned
                for planned in missing
            }
            pending = list(futures)
            if progress is not None:
                progress.started(len(planned_runs), len(rows), [p.key for p in missing[:concurrency]])
            written = clock.monotonic()
            try:
                for future in as_completed(list(futures), loop=client.loop):
                    planned = futures[future]
                    pending.remove(future)
                    try:
                        summary = future.result()
                    except Exception as error:  # noqa: BLE001 - a run that could not run is a row of the table
                        rows[planned.key] = row(planned, None, concurrency, failure=run_failure(error, local=scheduler is None))
                        counts.failed += 1
                        if isinstance(error, OSError) and error.errno is not None:  # not a lost connection's
                            counts.unwritten += 1
                            counts.write_error = counts.write_error or f"{planned.key}: {error}"
                    else:
                        rows[planned.key] = row(planned, summary, concurrency)
                        for message in summary.get("warnings", []):
                            warnings.warn(f"run {planned.key}: {message}", RuntimeWarning, stacklevel=1)
                        counts.computed += 1
                    if not pending or clock.monotonic() - written >= TABLE_EVERY:
                        write_table()
                        written = clock.monotonic()
                    if progress is not None:
                        progress.finished(planned.key, rows[planned.key]["status"],
                                          [futures[f].key for f in pending[:concurrency]])
            except BaseException:
                client.cancel(pending)
                with contextlib.suppress(OSError):  # the rows so far; a full disk's error is not the sweep's end
                    write_table()
                raise
    finally:
        if started:  # runs cut short by the end of their workers (an interrupt's too), once the cluster is closed
            remove_stale(runs_directory)
    return counts


class _dask_client:
    """A Dask client on a new local cluster (``workers`` processes of one thread each) or on
    the ``scheduler`` given, closed at the end of the block; with the number of runs at once."""

    def __init__(self, workers: int | None, scheduler: str | None):
        self.workers = workers or os.cpu_count() or 1
        self.scheduler = scheduler
        self.cluster = self.client = None
        #: the levels of the handlers of Dask's logs, silenced while the client runs
        self.handler_levels: dict = {}

    def __enter__(self):
        try:
            return self._start()
        except BaseException:  # an interrupt while it started: what was started is closed
            self.__exit__()
            raise

    def _start(self):
        from multiprocessing import resource_tracker

        from dask.distributed import Client, LocalCluster

        from .local_worker import TERMINAL_SIGNALS

        # Dask's logs (a lost connection, a retry, a worker ended by a signal) stay off stderr to the
        # end of the close: the handler of its "distributed" logger is silenced (a level on that logger
        # does not filter "distributed.client", which has a level of its own, and LocalCluster's
        # silence_logs ends before its close has finished)
        self.handler_levels = {handler: handler.level for handler in logging.getLogger("distributed").handlers}
        for handler in self.handler_levels:
            handler.setLevel(logging.CRITICAL + 10)
        if self.scheduler:
            try:
                self.client = Client(self.scheduler, timeout="10s", set_as_default=False)
            except (OSError, TimeoutError) as error:
                raise OSError(f"cannot reach the Dask scheduler at {self.scheduler}: {error}") from None
            concurrency = max(1, sum(self.client.nthreads().values()))
            if not self.client.nthreads():  # the runs would wait, unsaid, for a worker to join
                warnings.warn(f"the Dask scheduler at {self.scheduler} has no workers yet: the runs wait until one "
                              "joins (dask worker ...)", RuntimeWarning, stacklevel=2)
        else:
            # one BLAS thread per worker: runs share the cores already
            # no dashboard; its HTTP server (health checks) on a free port, not 8787 with a
            # warning when that is taken; no log of the cluster's on stderr (a run's failure
            # is its row in runs.csv).
            # SIGINT and SIGHUP are blocked while the cluster starts: the threads it starts inherit
            # the mask, and so do the processes they spawn (its workers, multiprocessing's
            # resource tracker), which a Ctrl-C or a hang-up of the terminal's process group
            # would otherwise end with tracebacks of their own (a worker's preload then ignores
            # them); and one that comes meanwhile is raised here once the cluster is whole, not
            # in the middle of its start.  SIGTERM is not delayed: a supervisor's stop, or the
            # way out of a start that hangs.
            previous = signal.pthread_sigmask(signal.SIG_BLOCK, TERMINAL_SIGNALS)
            try:
                # multiprocessing starts its resource tracker with SIGINT and SIGTERM blocked, then
                # unblocks them in the thread that started it: started here, then SIGINT blocked
                # again, it leaves the mask of the cluster's threads alone
                resource_tracker.ensure_running()
                signal.pthread_sigmask(signal.SIG_BLOCK, TERMINAL_SIGNALS)
                self.cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                            dashboard_address=None,
                                            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                                            silence_logs=logging.CRITICAL + 10, env={"OPENBLAS_NUM_THREADS": "1"},
                                            preload=[LOCAL_WORKER_SETUP])
                self.client = Client(self.cluster, set_as_default=False)
            finally:
                signal.pthread_sigmask(signal.SIG_SETMASK, previous)
            concurrency = self.workers
        return self.client, concurrency

    def __exit__(self, *exc):
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()
        for handler, level in self.handler_levels.items():
            handler.setLevel(level)
        return False
