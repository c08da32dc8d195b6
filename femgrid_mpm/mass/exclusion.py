"""The consistent matrix made into the solve's system: weak nodes lumped, empty and fixed
degrees of freedom excluded (identity rows), in place on the grid's fixed pattern."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..kernels.arithmetic import quotient
from ..kernels.compiled import compiled
from .sparse import _CompiledCSR


def _lump_couplings(matrix: sp.csr_matrix, weak: np.ndarray) -> sp.csr_matrix:
    """Move every off-diagonal entry that touches a weak node onto both diagonals."""
    coo = matrix.tocoo()
    moved = (coo.row != coo.col) & (weak[coo.row] | weak[coo.col])
    to_diagonal = np.bincount(coo.row[moved], weights=coo.data[moved], minlength=matrix.shape[0])
    data = np.where(moved, 0.0, coo.data)
    kept = sp.csr_matrix((data, (coo.row, coo.col)), shape=matrix.shape)
    kept.eliminate_zeros()
    return (kept + sp.diags(to_diagonal)).tocsr()


NO_NODES = np.zeros(0, dtype=bool)  # no layout yet: nothing to compare the nodes' tests with


@compiled()
def active_and_weak(diagonal, uniform, per_node, lumped, node_volume, node_integrals, weak_fraction,
                    active, weak, last_active, last_weak):
    """The nodes' tests of a step in one pass (numpy took ~10 calls of 1-3 us each at 1e3 points):
    ``active``, a diagonal entry above ``1e-24`` of a full cell's mass (``per_node[i]``, or
    ``uniform`` if ``per_node`` is empty), and ``weak``, an active node whose material volume
    fraction ``node_volume / node_integrals`` is below ``weak_fraction`` (none if
    ``node_volume`` is empty).  Returns ``(weak count, smallest row sum, unchanged)``,
    ``unchanged`` whether both are ``last_active`` and ``last_weak`` (False if those are empty)."""
    per_node_scales = per_node.shape[0] > 0
    test_weak = node_volume.shape[0] > 0
    unchanged = last_active.shape[0] == diagonal.shape[0]
    count = 0
    smallest = np.inf
    for i in range(diagonal.shape[0]):
        scale = per_node[i] if per_node_scales else uniform
        active[i] = diagonal[i] > 1e-24 * scale
        weak[i] = test_weak and active[i] and quotient(node_volume[i], node_integrals[i]) < weak_fraction
        count += weak[i]
        smallest = min(smallest, lumped[i])
        if unchanged and (active[i] != last_active[i] or weak[i] != last_weak[i]):
            unchanged = False
    return count, smallest, unchanged


@compiled()
def _rows_touching(indptr, indices, marked):
    """The rows of marked nodes and of their neighbours, on a structurally symmetric
    pattern with every diagonal entry (the neighbours are the marked rows' columns)."""
    touched = np.zeros(len(indptr) - 1, dtype=np.bool_)
    for i in range(len(indptr) - 1):
        if marked[i]:
            for entry in range(np.uint64(indptr[i]), np.uint64(indptr[i + 1])):  # the diagonal too: the row itself
                touched[np.uint64(indices[entry])] = True  # unsigned: no wraparound test (:mod:`.ldl`)
    return touched


@compiled()
def _lump_couplings_in_place(indptr, indices, data, diagonal_index, weak):
    """:func:`_lump_couplings` keeping the structure (moved entries become explicit zeros).

    Only the rows of weak nodes and of their neighbours have such couplings: the
    structure is symmetric (the entry (i, j) exists where (j, i) does), so the
    neighbours are the columns of the weak rows.  The other rows are not read
    (a handful of weak nodes among 27,000: 2.5 ms -> ~30 us per step).
    """
    touched = _rows_touching(indptr, indices, weak)
    for i in range(len(indptr) - 1):
        if not touched[i]:
            continue
        for entry in range(indptr[i], indptr[i + 1]):
            j = indices[entry]
            if j != i and (weak[i] or weak[j]):
                data[diagonal_index[i]] += data[entry]
                data[entry] = 0.0


@compiled()
def _exclude_in_place(indptr, indices, data, diagonal_index, excluded):
    """``keep M keep + diag(excluded)`` in ``data`` itself, on a structure with every
    diagonal entry, returning what it overwrote, ``(positions, rows, old)``: every
    nonzero entry of an excluded row, the diagonal of an excluded row whatever its
    value, and the nonzero entries of kept rows in excluded columns.  The matrix before
    is the one after with those entries put back (exactly, :attr:`ConsistentMass.matrix`),
    and its product is the one after with the excluded rows replaced
    (:meth:`ConsistentMass.apply`).

    As in :func:`_lump_couplings_in_place`, only the rows of excluded nodes and of
    their neighbours change; the others are not read."""
    touched = _rows_touching(indptr, indices, excluded)
    size = 0
    for i in range(len(indptr) - 1):
        if touched[i]:
            size += indptr[i + 1] - indptr[i]
    positions = np.empty(size, dtype=np.int64)
    rows = np.empty(size, dtype=np.int64)
    old = np.empty(size)
    count = 0
    for i in range(len(indptr) - 1):
        if not touched[i]:
            continue
        for entry in range(np.uint64(indptr[i]), np.uint64(indptr[i + 1])):
            if excluded[i] or excluded[np.uint64(indices[entry])]:
                diagonal = excluded[i] and entry == np.uint64(diagonal_index[i])
                if data[entry] != 0.0 or diagonal:
                    positions[count] = entry
                    rows[count] = i
                    old[count] = data[entry]
                    count += 1
                data[entry] = 1.0 if diagonal else 0.0
    return positions[:count], rows[:count], old[:count]


@compiled()
def _unexcluded_product(product, excluded, indices, positions, rows, old, vector):
    """``M @ vector`` from ``product = R @ vector`` (R: M with the excluded rows and columns
    made identity) and the entries the exclusion overwrote (:func:`_exclude_in_place`):
    an excluded row of R is exactly its unit row, so it is cleared and summed afresh; a kept
    row gains the couplings to excluded columns that R left out.  vector, product (n, k)."""
    for i in range(product.shape[0]):
        if excluded[i]:
            for c in range(product.shape[1]):
                product[i, c] = 0.0
    for t in range(rows.shape[0]):
        j = indices[positions[t]]
        for c in range(vector.shape[1]):
            product[rows[t], c] += old[t] * vector[j, c]
    return product


def unexcluded_matrix(system_matrix: _CompiledCSR, correction: tuple) -> _CompiledCSR:
    """``M`` rebuilt from the system ``R`` made from it in place and the entries the exclusion
    overwrote (:func:`_exclude_in_place`): the same structure, its own index arrays (scipy
    sorts indices in place, e.g. in abs(), which must not scramble the system's)."""
    positions, _, old = correction
    data = system_matrix.data.copy()
    data[positions] = old  # the entries themselves, not a difference: exact at any scale
    full = _CompiledCSR((data, system_matrix.indices.copy(), system_matrix.indptr.copy()),
                        shape=system_matrix.shape, copy=False)
    full.upper_start, full.upper_ordered = system_matrix.upper_start, system_matrix.upper_ordered
    return full


def unexcluded_apply(system_matrix, correction: tuple, excluded: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """``M @ vector`` from ``R @ vector`` and the overwritten entries (:func:`_unexcluded_product`)."""
    positions, rows, old = correction
    columns_of = np.ascontiguousarray(np.reshape(vector, (vector.shape[0], -1)), dtype=float)
    product = _unexcluded_product(np.reshape(system_matrix @ columns_of, columns_of.shape), excluded,
                                  system_matrix.indices, positions, rows, old, columns_of)
    return product.reshape(vector.shape)
