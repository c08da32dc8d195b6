"""The rows of the consistent mass that set its critical step, and the mixed mass.

A node's ratio ``M_ii / m_i`` (consistent diagonal over row sum) is the
``N_i``-weighted mean of its own function at the points that see it:
``sum m_p N_ip^2 / sum m_p N_ip``.  A node inside a body has the basis' interior
value, ``integral(phi^2) / integral(phi)`` (q1 4/9, quadratic splines 0.30,
cubic splines 0.23); a node that the body sees through the tail of its
function only (the ring of nodes just outside a free edge or a support for
the splines, the next node of a GIMP point whose square has just reached past
a node line) has a small one.  Such a row has little consistent mass against
its stiffness: the modes on it bound the step (cubic splines on the bar: 0.18
element widths over c_p against 0.55 in the interior).  A row whose ratio is
below ``weak_ratio`` times the interior value moves the share ``weak_mix`` of
each of its couplings onto both diagonals (``weak_mix = 1`` lumps it like a node
of small volume fraction, :func:`.exclusion._lump_couplings`), which keeps every
row sum and only adds positive semi-definite terms.  It makes ``M`` differ from
``N.T diag(m) N``: the projection then no longer keeps the points' kinetic
energy, which is why it is off by default (docs/time_step.md).

The mixed mass ``(1 - a) M_C + a D`` (``D`` the row sums, or where they are
not all positive the HRZ diagonal, as the singular fallback's blend) is the
same on the whole grid, for any basis.
"""

from __future__ import annotations

import numpy as np

import scipy.sparse as sp

from ..kernels.compiled import compiled
from .exclusion import _lump_couplings, _lump_couplings_in_place, _rows_touching

#: samples per lattice cell and axis for the interior value (midpoints: 2e-3 relative for cubic splines)
SAMPLES = 8


def interior_ratio(grid) -> float:
    """``integral(phi^2) / integral(phi)`` of the function of the node nearest the grid's
    centre, by a midpoint rule over its support (as points filling it would weigh it);
    for a grid smaller than a support, that of the node the grid cuts least."""
    nodes, spacing = grid.nodes, grid.spacing
    centre = nodes[np.argmin(np.linalg.norm(nodes - 0.5 * (grid.lower + grid.upper), axis=1))]
    reach = (0.5 * grid.definition.support_width + 1) * spacing  # GIMP: the squares reach past the hats
    low = np.maximum(grid.lower, centre - reach)
    high = np.minimum(grid.upper, centre + reach)
    counts = np.maximum(1, np.rint((high - low) / spacing * SAMPLES).astype(int))
    axes = [low[k] + (high[k] - low[k]) * (np.arange(counts[k]) + 0.5) / counts[k] for k in range(2)]
    samples = np.column_stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")])
    N, _, _ = grid.shape_functions(samples)
    column = np.argmin(np.linalg.norm(nodes - centre, axis=1))
    values = N.tocsc()[:, column].toarray().ravel()
    return float(np.sum(values**2) / np.sum(values))


def weak_by_ratio(diagonal: np.ndarray, lumped: np.ndarray, active: np.ndarray, threshold: float) -> np.ndarray:
    """The active nodes whose ``M_ii / m_i`` is below ``threshold`` (the interior value
    times ``weak_ratio``)."""
    ratio = np.divide(diagonal, lumped, out=np.ones_like(diagonal), where=active & (lumped > 0))
    return active & (ratio < threshold)


def mix_target(lumped: np.ndarray, diagonal: np.ndarray, active: np.ndarray) -> np.ndarray:
    """The diagonal the mixed mass moves toward: the row sums, or where they are not all
    positive (q2, serendipity) the HRZ diagonal, ``M_ii`` scaled to the total mass."""
    if np.all(lumped[active] > 0):
        return np.where(active, lumped, 1.0)
    scale = lumped[active].sum() / diagonal[active].sum()
    return np.where(active, scale * diagonal, 1.0)


@compiled()
def _move_couplings(indptr, indices, data, diagonal_index, share):
    """Move the share ``max(share_i, share_j)`` of every coupling ``M_ij`` onto both diagonals
    (share 1: :func:`.exclusion._lump_couplings_in_place`); the row sums stay, and the terms
    added, ``s M_ij (e_i - e_j)(e_i - e_j)^T`` with ``M_ij >= 0``, are positive semi-definite.
    Only the weak rows and their neighbours have such couplings: the others are not read."""
    touched = _rows_touching(indptr, indices, share > 0.0)
    for i in range(len(indptr) - 1):
        if not touched[i]:
            continue
        for entry in range(indptr[i], indptr[i + 1]):
            j = indices[entry]
            moved = max(share[i], share[j])
            if j != i and moved > 0.0:
                amount = moved * data[entry]
                data[diagonal_index[i]] += amount
                data[entry] -= amount


@compiled()
def _mix_in_place(data, diagonal_index, target, weight):
    """``(1 - weight) M + weight diag(target)`` in ``data`` itself (every stored entry scaled,
    the diagonal then moved toward its target)."""
    keep = 1.0 - weight
    for entry in range(data.shape[0]):
        data[entry] *= keep
    for i in range(diagonal_index.shape[0]):
        data[diagonal_index[i]] += weight * target[i]


def lumped_and_mixed(matrix: sp.csr_matrix, diagonal_index, weak: np.ndarray | None, rows: np.ndarray | None,
                     mix: float, target: np.ndarray | None) -> sp.csr_matrix:
    """The weak nodes' couplings moved onto the diagonals, then the share ``rows[i]`` of each
    coupling of the weak rows (:func:`_move_couplings`), then ``(1 - mix) M + mix
    diag(target)``: in place on the fixed pattern (``diagonal_index`` given), else a new
    matrix (the assembled one is left as it is)."""
    if weak is not None:
        if diagonal_index is None:
            matrix = _lump_couplings(matrix, weak)
        else:
            _lump_couplings_in_place(matrix.indptr, matrix.indices, matrix.data, diagonal_index, weak)
    if rows is not None:
        if diagonal_index is None:  # a copy, with the position of each stored diagonal entry
            matrix = sp.csr_matrix(matrix, copy=True)
            row_of = np.repeat(np.arange(matrix.shape[0]), np.diff(matrix.indptr))
            on_diagonal = np.flatnonzero(matrix.indices == row_of)
            positions = np.zeros(matrix.shape[0], dtype=np.int64)  # a row without one has no entries
            positions[row_of[on_diagonal]] = on_diagonal
            _move_couplings(matrix.indptr, matrix.indices, matrix.data, positions, rows)
        else:
            _move_couplings(matrix.indptr, matrix.indices, matrix.data, diagonal_index, rows)
    if mix > 0:
        if diagonal_index is None:
            matrix = ((1.0 - mix) * matrix + mix * sp.diags(target)).tocsr()
        else:
            _mix_in_place(matrix.data, diagonal_index, target, mix)
    return matrix
