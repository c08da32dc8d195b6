"""The systems a consistent mass solves in one step, and their layout kept over the steps.

A system is the matrix for one or both velocity components with its excluded degrees of
freedom (empty nodes, and fixed ones) as identity rows (:class:`.system._System`).  What the
systems are, which nodes each excludes and how each is solved follows from the active and
weak nodes alone (the supports are fixed for the run), which most steps leave as they were:
:class:`SystemsLayout` holds it, with what is worth keeping while it holds (the small
systems' orderings and structures for the compiled ``L D L^T``, :mod:`.ldl`, and CG's test of
singularity near the edges, :mod:`.singular`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .exclusion import _exclude_in_place
from .ldl import small_layouts
from .reused import KeptFactors
from .system import _System

#: largest number of active nodes for which "auto" factors the matrix
DIRECT_LIMIT = 5000


@dataclass
class SystemsLayout:
    """One step's systems' layout: ``excluded`` (n, 2), the ``groups`` of columns solved
    together (one system for both components when they are fixed alike), whether they are
    factored (``direct``), the small systems' ``L D L^T`` layouts and CG's edge blocks."""

    active: np.ndarray
    weak: np.ndarray
    excluded: np.ndarray
    groups: list
    direct: bool
    small: dict | None = None  # {columns: SymbolicLDL}; None: not analysed yet
    edges: dict = field(default_factory=dict)  # {columns: SymbolicLDL or None} (.singular)

    @classmethod
    def of(cls, active: np.ndarray, weak: np.ndarray, fixed: np.ndarray | None, linear_solver: str) -> "SystemsLayout":
        excluded = ~active[:, None] if fixed is None else (~active[:, None] | fixed)
        excluded = np.broadcast_to(excluded, (len(active), 2))
        groups = [(0, 1)] if np.array_equal(excluded[:, 0], excluded[:, 1]) else [(0,), (1,)]
        direct = linear_solver == "direct" or (linear_solver == "auto" and np.count_nonzero(active) <= DIRECT_LIMIT)
        return cls(active.copy(), weak.copy(), excluded, groups, direct)

    @property
    def every_step(self) -> set:
        """The columns of the systems factored every step (:attr:`.ldl.SymbolicLDL.every_step`)."""
        return {columns for columns, layout in (self.small or {}).items() if layout.every_step}


def make_systems(matrix, diagonal_index: np.ndarray | None, layout: SystemsLayout, kept: KeptFactors,
                 weak: np.ndarray, keeps_factors: bool) -> tuple[list, tuple | None, KeptFactors]:
    """The step's systems of the assembled ``matrix``: ``(systems, correction, kept)``, the
    entries the exclusion overwrote if it was made into the one system in place, and the
    factors kept for the next steps (``kept``: those that fit the layout).

    Below DIRECT_LIMIT, "auto" (``keeps_factors``) factors a small system by the compiled
    ``L D L^T`` on its layout (:mod:`.ldl`), every step where that is cheap, and a larger one
    by SuperLU; factors not made every step are kept while they fit (:mod:`.reused`)."""
    if keeps_factors and (layout.small is None or diagonal_index is None):
        # (the scipy path's structure is its product's, of this step)
        layout.small = small_layouts(matrix, layout.excluded, layout.groups, diagonal_index, layout.small)
    excluded, every_step, small = layout.excluded, layout.every_step, layout.small or {}
    kept = KeptFactors({columns: factors for columns, factors in kept.items() if columns not in every_step})
    correction = None
    if diagonal_index is not None and len(layout.groups) == 1:
        # the one system is made from the assembled matrix in place (a copy of its data was
        # ~25 ns per point-step for cubic splines at 1e5 points); M is R with the entries the
        # exclusion overwrote put back
        correction = _exclude_in_place(matrix.indptr, matrix.indices, matrix.data, diagonal_index, excluded[:, 0])
        systems = [_System.build(matrix, [0, 1], excluded[:, 0], layout.direct and not kept and not small,
                                 diagonal_index, in_place=True)]
    else:
        systems = [_System.build(matrix, list(columns), excluded[:, columns[0]],
                                 layout.direct and columns not in kept and columns not in small, diagonal_index)
                   for columns in layout.groups]
    for system in systems:
        columns = tuple(system.columns)
        if columns in small and (columns in every_step or columns not in kept):
            system.factor_now(small[columns], matrix.data)  # its free rows and columns are the system's
    if keeps_factors:
        for system in systems:
            system.kept = kept.get(tuple(system.columns))
            if system.kept is None and tuple(system.columns) not in every_step:
                kept.keep(system, weak)
    return systems, correction, kept
