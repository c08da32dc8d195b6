"""The paper's cases, each a function ``run(out_dir) -> summary`` writing its figures and tables.

``femgrid-mpm reproduce`` runs them all; ``experiments/*.py`` run one each.
"""

from . import box_impact, cantilever, vibrating_bar

CASES = {"vibrating_bar": vibrating_bar.run, "cantilever": cantilever.run, "box_impact": box_impact.run}

__all__ = ["CASES"]
