"""A compiled sparse ``L D L^T`` of the consistent mass, analysed once per layout and refactored every step.

Below a few thousand active nodes SuperLU's factorization was most of a consistent step, and
kept over the steps as CG's preconditioner it still left two to four preconditioned
iterations per solve (:mod:`.reused`).  Here the costly part of a factorization, the
ordering and the structure of ``L``, is done once for the step's *layout*, the matrix's
stored structure restricted to the free degrees of freedom, and kept while the free nodes
stay the same; each step then factors its own matrix in one compiled pass and solves
exactly, both solves of the step with the same factors.

* the ordering: SuperLU's minimum degree on ``A + A^T`` (what :mod:`.direct` uses), taken
  from a factorization of a matrix of the same structure, once per layout;
* the symbolic pass: the elimination tree and each column's count of ``L``;
* the numeric pass, up-looking: row ``k`` of ``L`` from a sparse triangular solve on
  column ``k`` of ``A``'s upper triangle, whose pattern is the reach in the tree.

``M`` is positive semi-definite (a Gram matrix with positive weights, its weak rows and
mixes adding positive semi-definite terms), so no pivoting is needed, and a pivot
``D_k`` below :data:`.direct.PIVOT_RATIO` of its diagonal entry ``A_kk`` says the node's
function is reproduced by the others, as SuperLU's pivots do in :mod:`.direct`: the
matrix is then singular and the caller falls back as it does there.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..kernels.arithmetic import fused
from ..kernels.compiled import compiled
from .direct import PIVOT_RATIO, symmetric_lu

#: a layout is factored every step when it has at most this many free nodes (a larger one
#: fills more than it pays: q1 at 2601 free nodes measured 1.6 ms a factorization against
#: 0.7 ms a solve of CG on kept factors) ...
EVERY_STEP_NODES = 1500
#: ... and its numeric pass, ``sum(c_j^2)`` over the columns' counts ``c_j`` of ``L``, is at
#: most this many times ``L``'s entries (a solve of two columns sweeps ``4 nnz(L)``; CG on kept
#: factors takes three to five such sweeps and products a solve, two solves a step):
#: q1, q2, serendipity at 1e3 points 15-18 (factor 56 us, two solves 36 us, against CG's
#: 140 us), cubic splines 58 and gimp 37 (factor 600 and 240 us) are left to the kept factors
EVERY_STEP_WORK = 24
#: ... or this many where the kept factors are made again at most steps anyway
#: (:class:`.trial.RefactorRate`): gimp at 1e3 points (37.7) 0.73-0.75 -> 0.55-0.62 ms a step
#: factored every step, at 4e3 points (72.4) 3.66 -> 4.45 ms
STALE_WORK = 48


@dataclass
class SymbolicLDL:
    """The ordering and the structure of ``L`` for one layout of a system's matrix.

    ``order[j]`` is the node eliminated ``j``-th (free nodes only); column ``j`` of the
    permuted upper triangle holds the entries ``source[upper_indptr[j]:upper_indptr[j+1]]``
    of the matrix's ``data`` at the rows ``upper_rows[...]`` (positions ``< j``), its
    diagonal ``diagonal_source[j]``."""

    excluded: np.ndarray
    order: np.ndarray
    upper_indptr: np.ndarray
    upper_rows: np.ndarray
    source: np.ndarray
    diagonal_source: np.ndarray
    parent: np.ndarray
    lower_indptr: np.ndarray
    structure: tuple  # (indptr, indices) analysed
    #: row ``k`` of ``L``: its columns ``row_columns[row_indptr[k]:row_indptr[k+1]]`` in the
    #: order the numeric pass takes them, each entry's place in the columns of ``L``
    #: (``row_slots``), and the rows of those columns (``lower_rows``): the same every step
    row_indptr: np.ndarray
    row_columns: np.ndarray
    row_slots: np.ndarray
    lower_rows: np.ndarray

    @classmethod
    def analyse(cls, indptr: np.ndarray, indices: np.ndarray, diagonal_index: np.ndarray,
                excluded: np.ndarray) -> "SymbolicLDL":
        """The layout of a CSR structure with every diagonal entry (``diagonal_index``) whose
        ``excluded`` rows and columns are left out."""
        free = np.flatnonzero(~excluded)
        compact = np.full(len(excluded), -1, dtype=np.int64)
        compact[free] = np.arange(len(free))
        rows = np.repeat(np.arange(len(excluded)), np.diff(indptr))
        keep = (compact[rows] >= 0) & (compact[indices] >= 0)
        structure = sp.csc_matrix((np.ones(int(keep.sum())), (compact[rows[keep]], compact[indices[keep]])),
                                  shape=(len(free), len(free)))
        # the ordering of a diagonally dominant matrix of this structure (the values do not enter it)
        degree = np.asarray(structure.sum(axis=0)).ravel()
        surrogate = (sp.diags(2.0 * degree + 1.0) - structure).tocsc()
        ordering = symmetric_lu(surrogate).perm_c
        order = np.empty(len(free), dtype=np.int64)
        order[ordering] = free  # SuperLU's perm_c[i]: where compact column i is eliminated
        position = np.full(len(excluded), -1, dtype=np.int64)
        position[order] = np.arange(len(order))
        upper_indptr, upper_rows, source = _permuted_upper(indptr.astype(np.int64), indices.astype(np.int64),
                                                           order, position)
        parent, counts = _elimination_tree(upper_indptr, upper_rows)
        lower_indptr = np.zeros(len(order) + 1, dtype=np.int64)
        np.cumsum(counts, out=lower_indptr[1:])
        row_indptr, row_columns, row_slots, lower_rows = _row_patterns(upper_indptr, upper_rows, parent, lower_indptr)
        return cls(excluded.copy(), order, upper_indptr, upper_rows, source,
                   diagonal_index[order].astype(np.int64), parent, lower_indptr, (indptr.copy(), indices.copy()),
                   row_indptr, row_columns, row_slots, lower_rows)

    def describes(self, matrix, excluded: np.ndarray) -> bool:
        """Whether this layout is that of ``matrix``'s structure with these excluded nodes."""
        return (np.array_equal(excluded, self.excluded) and np.array_equal(matrix.indptr, self.structure[0])
                and np.array_equal(matrix.indices, self.structure[1]))

    @functools.cached_property
    def work(self) -> float:
        """The numeric pass against a solve: ``sum(c_j^2)`` over the columns' counts of ``L``,
        per entry of ``L``."""
        counts = np.diff(self.lower_indptr).astype(float)
        return float(np.sum(counts**2)) / max(self.factor_entries, 1)

    def factors_within(self, work: float) -> bool:
        """At most :data:`EVERY_STEP_NODES` free nodes and a numeric pass of at most ``work``."""
        return len(self.order) <= EVERY_STEP_NODES and self.work <= work

    @functools.cached_property
    def every_step(self) -> bool:
        """Whether factoring this layout every step is cheaper than CG on kept factors
        (:data:`EVERY_STEP_WORK`)."""
        return self.factors_within(EVERY_STEP_WORK)

    @property
    def every_step_when_stale(self) -> bool:
        """The same where the kept factors are made again at most steps anyway
        (:class:`.trial.RefactorRate`, :data:`STALE_WORK`)."""
        return self.factors_within(STALE_WORK)

    @property
    def factor_entries(self) -> int:
        """Entries of ``L`` below its diagonal."""
        return int(self.lower_indptr[-1])

    def factor(self, data: np.ndarray) -> "tuple[NumericLDL | None, int | None]":
        """``(L D L^T, None)`` of the matrix whose entries are ``data`` (this layout's
        structure), or ``(None, node)`` if it is singular: the node of the first pivot below
        :data:`PIVOT_RATIO` of its diagonal entry."""
        lower_data = np.empty(self.factor_entries)
        pivots = np.empty(len(self.order))
        weakest = _numeric(data, self.upper_indptr, self.upper_rows, self.source, self.diagonal_source,
                           self.row_indptr, self.row_columns, self.row_slots, self.lower_indptr, self.lower_rows,
                           lower_data, pivots, PIVOT_RATIO)
        if weakest >= 0:
            return None, int(self.order[weakest])
        return NumericLDL(self, self.lower_rows, lower_data, pivots), None


def small_layouts(matrix, excluded: np.ndarray, groups, diagonal_index: np.ndarray | None = None,
                  last: dict | None = None) -> dict:
    """``{columns: SymbolicLDL}`` of the systems (``groups`` of columns, ``excluded`` (n, 2))
    of at most :data:`EVERY_STEP_NODES` free nodes, the ones factored every step among them
    (:attr:`SymbolicLDL.every_step`), the others when they have no kept factors.  Without ``diagonal_index``
    (the scipy engine's product, its structure its own each step) the diagonal is found, and
    ``last``'s layouts are kept where the structure and the excluded nodes are theirs."""
    if diagonal_index is None:
        diagonal_index = _diagonal_index(matrix.indptr.astype(np.int64), matrix.indices.astype(np.int64))
    layouts = {}
    for columns in groups:
        free = ~excluded[:, columns[0]]
        if np.count_nonzero(free) > EVERY_STEP_NODES or np.any(diagonal_index[free] < 0):
            continue
        symbolic = (last or {}).get(tuple(columns))
        if symbolic is None or not symbolic.describes(matrix, excluded[:, columns[0]]):
            symbolic = SymbolicLDL.analyse(matrix.indptr, matrix.indices, diagonal_index, excluded[:, columns[0]])
        layouts[tuple(columns)] = symbolic
    return layouts


@compiled()
def _diagonal_index(indptr, indices):
    """Each row's diagonal entry in a CSR structure, -1 where it has none."""
    n = len(indptr) - 1
    index = np.full(n, -1, dtype=np.int64)
    for i in range(n):
        for entry in range(indptr[i], indptr[i + 1]):
            if indices[entry] == i:
                index[i] = entry
    return index


@dataclass
class NumericLDL:
    """One step's factors on a :class:`SymbolicLDL`."""

    symbolic: SymbolicLDL
    lower_rows: np.ndarray
    lower_data: np.ndarray
    pivots: np.ndarray

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``A^-1 rhs`` for rhs (n_nodes, k), zero on the excluded nodes."""
        out = np.zeros((rhs.shape[0], rhs.shape[1]))
        _solve(np.ascontiguousarray(rhs, dtype=float), out, self.symbolic.order, self.symbolic.lower_indptr,
               self.lower_rows, self.lower_data, self.pivots)
        return out


@compiled()
def _permuted_upper(indptr, indices, order, position):
    """Column ``j`` of ``P^T A P``'s strict upper triangle from the CSR rows of node
    ``order[j]`` (``A`` symmetric), with each entry's index in ``A``'s data."""
    n = len(order)
    counts = np.zeros(n + 1, dtype=np.int64)
    for j in range(n):
        node = order[j]
        for entry in range(indptr[node], indptr[node + 1]):
            i = position[indices[entry]]
            if i >= 0 and i < j:
                counts[j + 1] += 1
    upper_indptr = np.cumsum(counts)
    rows = np.empty(upper_indptr[n], dtype=np.int64)
    source = np.empty(upper_indptr[n], dtype=np.int64)
    for j in range(n):
        node = order[j]
        slot = upper_indptr[j]
        for entry in range(indptr[node], indptr[node + 1]):
            i = position[indices[entry]]
            if i >= 0 and i < j:
                rows[slot] = i
                source[slot] = entry
                slot += 1
    return upper_indptr, rows, source


@compiled()
def _elimination_tree(upper_indptr, upper_rows):
    """The parent of each column in the elimination tree and each column's count of
    entries of ``L`` below the diagonal: row ``k`` of ``L`` is the set of columns met
    walking up the tree from each ``i`` of column ``k``'s upper entries until ``k``."""
    n = len(upper_indptr) - 1
    parent = np.full(n, -1, dtype=np.int64)
    counts = np.zeros(n, dtype=np.int64)
    mark = np.full(n, -1, dtype=np.int64)
    for k in range(n):
        mark[k] = k
        for entry in range(upper_indptr[k], upper_indptr[k + 1]):
            i = upper_rows[entry]
            while mark[i] != k:
                if parent[i] == -1:
                    parent[i] = k
                counts[i] += 1  # L[k, i] is an entry
                mark[i] = k
                i = parent[i]
    return parent, counts


@compiled()
def _row_patterns(upper_indptr, upper_rows, parent, lower_indptr):
    """Each row of ``L``'s columns, in the tree's order (the reach of the row's upper
    entries: each entry's path up the tree to the row, the paths stacked from the last
    entry's down), with each entry's place in its column and the rows of each column."""
    n = len(upper_indptr) - 1
    entries = lower_indptr[n]
    row_indptr = np.zeros(n + 1, dtype=np.int64)
    row_columns = np.empty(entries, dtype=np.int64)
    row_slots = np.empty(entries, dtype=np.int64)
    lower_rows = np.empty(entries, dtype=np.int64)
    filled = np.zeros(n, dtype=np.int64)  # entries of each column of L placed so far
    mark = np.full(n, -1, dtype=np.int64)
    reach = np.empty(n, dtype=np.int64)
    path = np.empty(n, dtype=np.int64)
    for k in range(n):
        mark[k] = k
        top = n
        for entry in range(upper_indptr[k], upper_indptr[k + 1]):
            i = upper_rows[entry]
            length = 0
            while mark[i] != k:
                path[length] = i
                length += 1
                mark[i] = k
                i = parent[i]
            while length > 0:
                top -= 1
                length -= 1
                reach[top] = path[length]
        start = row_indptr[k]
        for slot in range(top, n):
            i = reach[slot]
            place = lower_indptr[i] + filled[i]
            filled[i] += 1
            row_columns[start + slot - top] = i
            row_slots[start + slot - top] = place
            lower_rows[place] = k
        row_indptr[k + 1] = start + n - top
    return row_indptr, row_columns, row_slots, lower_rows


@compiled()
def _numeric(data, upper_indptr, upper_rows, source, diagonal_source, row_indptr, row_columns, row_slots,
             lower_indptr, lower_rows, lower_data, pivots, pivot_ratio):
    """The numeric ``L D L^T``, row by row on the rows' kept patterns (:func:`_row_patterns`):
    returns -1, or the position of the first pivot below ``pivot_ratio`` of its diagonal
    entry (or not finite).

    The positions read from the index arrays are taken unsigned: numba tests a signed index
    for Python's wraparound on every access (q1 at 1e3 points 45 -> 25 us a factorization)."""
    n = len(upper_indptr) - 1
    y = np.zeros(n)  # row k of L D, scattered
    for k in range(n):
        for entry in range(upper_indptr[k], upper_indptr[k + 1]):
            y[np.uint64(upper_rows[entry])] += data[np.uint64(source[entry])]
        diagonal = data[np.uint64(diagonal_source[k])]
        d = diagonal
        for s in range(row_indptr[k], row_indptr[k + 1]):
            i = np.uint64(row_columns[s])
            yi = y[i]
            y[i] = 0.0
            end = np.uint64(row_slots[s])  # column i's entries above row k precede it
            for p in range(np.uint64(lower_indptr[i]), end):
                r = np.uint64(lower_rows[p])
                y[r] = fused(-lower_data[p], yi, y[r])
            factor = yi / pivots[i]
            d = fused(-factor, yi, d)
            lower_data[end] = factor
        if not d >= pivot_ratio * diagonal:  # NaN too
            return k
        pivots[k] = d
    return -1


@compiled()
def _solve(rhs, out, order, lower_indptr, lower_rows, lower_data, pivots):
    """``out[order] = L^-T D^-1 L^-1 rhs[order]``; two columns of rhs (both velocity
    components) in the same sweeps, each entry of ``L`` read once for both, written out as a
    pair (a loop over the columns inside the sweeps took 24 us against 14 for q1 at 1e3
    points); one column (a system of one component) by the same sweeps alone.  Positions
    unsigned, as in :func:`_numeric`."""
    n = len(order)
    if rhs.shape[1] == 2:
        a = np.empty(n)
        b = np.empty(n)
        for j in range(n):
            node = np.uint64(order[j])
            a[j] = rhs[node, 0]
            b[j] = rhs[node, 1]
        for j in range(n):  # L, unit diagonal, by columns
            aj = a[j]
            bj = b[j]
            for p in range(np.uint64(lower_indptr[j]), np.uint64(lower_indptr[j + 1])):
                r, value = np.uint64(lower_rows[p]), lower_data[p]
                a[r] = fused(-value, aj, a[r])
                b[r] = fused(-value, bj, b[r])
        for j in range(n):
            a[j] = a[j] / pivots[j]
            b[j] = b[j] / pivots[j]
        for j in range(n - 1, -1, -1):  # L^T
            aj = a[j]
            bj = b[j]
            for p in range(np.uint64(lower_indptr[j]), np.uint64(lower_indptr[j + 1])):
                r, value = np.uint64(lower_rows[p]), lower_data[p]
                aj = fused(-value, a[r], aj)
                bj = fused(-value, b[r], bj)
            a[j] = aj
            b[j] = bj
        for j in range(n):
            node = np.uint64(order[j])
            out[node, 0] = a[j]
            out[node, 1] = b[j]
        return
    x = np.empty(n)
    for c in range(rhs.shape[1]):
        for j in range(n):
            x[j] = rhs[np.uint64(order[j]), c]
        for j in range(n):
            xj = x[j]
            for p in range(np.uint64(lower_indptr[j]), np.uint64(lower_indptr[j + 1])):
                r = np.uint64(lower_rows[p])
                x[r] = fused(-lower_data[p], xj, x[r])
        for j in range(n):
            x[j] = x[j] / pivots[j]
        for j in range(n - 1, -1, -1):
            xj = x[j]
            for p in range(np.uint64(lower_indptr[j]), np.uint64(lower_indptr[j + 1])):
                xj = fused(-lower_data[p], x[np.uint64(lower_rows[p])], xj)
            x[j] = xj
        for j in range(n):
            out[np.uint64(order[j]), c] = x[j]
