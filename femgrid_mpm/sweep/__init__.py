"""Sweeps: the runs of a scene over the product of the values of some of its keys.

``spec``
    The sweep file (:class:`SweepSpec`, :func:`read_sweep`) and its runs, each checked
    before any runs (:func:`plan`).
``runner``
    The runs on Dask, each into ``DIR/runs/<key>/``, finished runs reused (:func:`run_sweep`).
``table``
    ``DIR/runs.csv``, one row per run.
``analysis``, ``figures``, ``report``
    The report: orders of convergence, the Pareto front, the cheapest run for a target
    error (pure functions), the figures and ``report.md`` / ``report.html``.
"""

from .runner import SweepCounts, SweepProgress, run_sweep
from .spec import PlannedRun, SweepError, SweepSpec, plan, read_sweep
from .table import RUNS_FILE, read_runs

__all__ = ["PlannedRun", "RUNS_FILE", "SweepCounts", "SweepError", "SweepProgress", "SweepSpec", "plan",
           "read_runs", "read_sweep", "run_sweep"]
