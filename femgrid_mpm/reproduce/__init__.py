"""The paper's cases, each a function ``run(out_dir) -> summary`` writing its figures and tables.

``femgrid-mpm reproduce`` runs them all; ``experiments/*.py`` run one each.  Each
simulation is timed after its kernels are loaded (:mod:`.timing`).
"""

from . import box_impact, cantilever, cost_accuracy, vibrating_bar

CASES = {"vibrating_bar": vibrating_bar.run, "cantilever": cantilever.run, "box_impact": box_impact.run,
         "cost_accuracy": cost_accuracy.run}
#: how many simulations each case's ``run`` makes in this process (for a progress bar over them)
PLANNED_RUNS = {"vibrating_bar": vibrating_bar.planned_runs, "cantilever": cantilever.planned_runs,
                "box_impact": box_impact.planned_runs, "cost_accuracy": cost_accuracy.planned_runs}

__all__ = ["CASES", "PLANNED_RUNS"]
