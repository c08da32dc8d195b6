"""The direct solver of the consistent mass: SuperLU, and its pivots as the test of singularity."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


#: a pivot this small against its own diagonal entry means singular.
#: Measured: well-posed matrices >= 1e-4 (cubic splines at a clamp); the
#: rank-deficient case (cubic splines, 2 points per cell, a body 2 cells
#: thick) between 1e-17 and 2e-10 from step to step, so 1e-10 let a few
#: singular steps through and the run blew up.
PIVOT_RATIO = 1e-8


def _rows_and_block(matrix: sp.csr_matrix, nodes: np.ndarray) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """``M[nodes, :]`` and ``M[nodes][:, nodes]``, plain scipy matrices over ``matrix``'s arrays."""
    rows = sp.csr_matrix((matrix.data, matrix.indices, matrix.indptr), shape=matrix.shape)[nodes]
    return rows, rows[:, nodes]


def symmetric_lu(matrix: sp.spmatrix):
    """SuperLU's factors of a symmetric matrix in minimum-degree order on ``A + A^T``, with
    diagonal pivots preferred (raises RuntimeError if it is exactly singular)."""
    return spla.splu(sp.csc_matrix(matrix), permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})


def _pivots(matrix: sp.csr_matrix):
    """SuperLU factors of a symmetric matrix and each pivot against its own diagonal
    entry with that pivot's node, ``(factors, ratios, nodes)``; None if SuperLU finds
    it exactly singular.

    SuperLU does not warn on a numerically singular matrix; its smallest
    pivot does tell (in symmetric mode the pivots are the diagonal of an
    LDL^T-like factorization, bounded below by the smallest eigenvalue):
    ~1 for an independent node of any mass, ~1e-16 for a node whose function
    the others reproduce.

    The matrices of the fixed mass pattern store every stencil entry, also
    the zeros left where empty, fixed or weak nodes were taken out; SuperLU
    orders and fills by the stored structure, so they are dropped from a
    copy first (cubic splines, cantilever 8 cells deep, 737 of 2025 nodes
    active: 2/3 of the entries zero, 85 -> 3.8 ms per factorization).
    """
    compact = sp.csc_matrix(matrix)  # a copy: the pattern's index arrays stay as they are
    compact.eliminate_zeros()
    try:
        factors = symmetric_lu(compact)
    except RuntimeError:  # "Factor is exactly singular"
        return None
    nodes = np.empty_like(factors.perm_c)
    nodes[factors.perm_c] = np.arange(len(nodes))
    return factors, np.abs(factors.U.diagonal()) / matrix.diagonal()[nodes], nodes


def _factor(matrix: sp.csr_matrix):
    """SuperLU factors of a symmetric matrix, or None if it is singular (a pivot below
    :data:`PIVOT_RATIO` of its diagonal entry, see :func:`_pivots`)."""
    pivots = _pivots(matrix)
    if pivots is None or np.min(pivots[1]) < PIVOT_RATIO:
        return None
    return pivots[0]


def _smallest_pivot_node(matrix: sp.csr_matrix) -> int | None:
    """The node of the smallest pivot against its diagonal entry (see :func:`_pivots`),
    or None if SuperLU finds the matrix exactly singular."""
    pivots = _pivots(matrix)
    return None if pivots is None else int(pivots[2][np.argmin(pivots[1])])


def _direct_solve(factors, matrix: sp.csr_matrix, rhs: np.ndarray) -> tuple[np.ndarray, bool]:
    """Solve with the factors and check the backward error."""
    if factors is None:
        return np.zeros_like(rhs), False
    solution = factors.solve(rhs)
    residual = np.linalg.norm(matrix @ solution - rhs, axis=0)
    scale = np.linalg.norm(rhs, axis=0) + matrix.diagonal().max() * np.linalg.norm(solution, axis=0)
    converged = bool(np.all(np.isfinite(solution)) and np.all(residual <= 1e-10 * scale))
    return np.ascontiguousarray(solution), converged  # SuperLU's is in column order: G2P would compile again
