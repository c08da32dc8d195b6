"""The test of singularity of CG's system on a signed basis, near the bodies' edges."""

from __future__ import annotations

import numpy as np

from .direct import PIVOT_RATIO, _pivots, _rows_and_block
from .ldl import SymbolicLDL
from .preconditioners import _near_empty_nodes


def singular_near_edges(system, lattice: np.ndarray, active: np.ndarray, layer_width: int,
                        layouts: dict | None = None) -> bool:
    """Whether CG's system is singular, decided as the direct solver decides, for a
    signed basis (q2, serendipity): by SuperLU's pivots (:data:`PIVOT_RATIO`) of its
    block on the kept nodes within one element of an empty node or of the grid's
    edge, once per step.

    CG alone does not see it.  A momentum ``N.T (m v)`` (and gravity's
    ``N.T (m g)``) lies in the range of ``M = N.T diag(m) N``, so CG solves
    such a system even where M is singular, and the solution keeps whatever
    its first guess held in M's null space: that moves no point but changes
    the velocity gradient.  Where q2 and serendipity elements were partly
    filled, CG's stresses differed from the direct solver's by O(1) after
    one step (it blended the acceleration solve only, when the force had a
    part in the null space).  A null vector vanishes on the nodes of every
    element whose points determine its polynomials, so it lives on partly
    filled elements, next to empty nodes or the grid's edge; and M being positive
    semi-definite, M is singular along a vector of the block exactly when
    the block is.  (A body too sparse everywhere, fewer points per element
    than functions, is singular in its interior: only the direct solver
    finds that.)  Non-negative bases lump their weakly supported nodes
    instead (:meth:`_prepare`) and are not checked.

    ``layouts``, kept by the caller while the active nodes stay, holds each system's block as a
    compiled ``L D L^T``'s ordering and structure (:mod:`.ldl`), so that a step's test is one
    numeric pass (q2 at 1e4 points: SuperLU's ordering and factorization of the block, with
    scipy's extraction of it, were ~1 ms a step); without it SuperLU factors the block.
    """
    if system.singular is not None:
        return system.singular
    system.singular, system.weakest = False, None
    columns = tuple(system.columns)
    if layouts is not None and columns in layouts:
        symbolic = layouts[columns]
    else:
        layer = _near_empty_nodes(lattice, ~active, layer_width) & ~system.excluded
        if layouts is None:  # SuperLU on the block
            nodes = np.flatnonzero(layer)
            pivots = _pivots(_rows_and_block(system.matrix, nodes)[1]) if nodes.size else None
            if nodes.size and pivots is None:
                system.singular = True
            elif pivots is not None and np.min(pivots[1]) < PIVOT_RATIO:
                system.singular, system.weakest = True, int(nodes[pivots[2][np.argmin(pivots[1])]])
            return system.singular
        matrix = system.matrix
        symbolic = layouts[columns] = None if not layer.any() else SymbolicLDL.analyse(
            matrix.indptr, matrix.indices, matrix.upper_start, ~layer)
    if symbolic is not None:
        factors, system.weakest = symbolic.factor(system.matrix.data)
        system.singular = factors is None
    return system.singular
