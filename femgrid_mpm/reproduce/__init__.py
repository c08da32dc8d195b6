"""The paper's cases, each a function ``run(out_dir) -> summary`` writing its figures and tables.

``femgrid-mpm reproduce`` runs them all; ``experiments/*.py`` run one each.
"""

from . import vibrating_bar

CASES = {"vibrating_bar": vibrating_bar.run}

__all__ = ["CASES"]
