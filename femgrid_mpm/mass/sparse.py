"""Compiled products of the consistent mass matrix with (n, k) arrays of nodal vectors."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..kernels.arithmetic import fused
from ..kernels.compiled import compiled


class _CompiledCSR(sp.csr_matrix):
    """A CSR matrix whose product with a dense (n, k) array is a compiled loop
    (scipy's ``csr_matvecs`` took ~3 ns per stored entry with two columns).

    ``upper_start`` (set by whoever knows it): the matrix is symmetric bit for
    bit and stored in stencil order, row i's entries after ``upper_start[i]``
    (its diagonal) one of each symmetric pair: the product then reads that half
    (:func:`_symmetric_times_dense_dot`).  Operations that make a new matrix
    (scipy's) do not carry it.
    """

    upper_start: np.ndarray | None = None
    #: every entry after a row's diagonal has a larger column (:func:`upper_is_later`): the
    #: stored half is the upper triangle, as :mod:`.gauss_seidel`'s sweeps read it
    upper_ordered: bool = False

    def upper_start_or_none(self) -> np.ndarray:
        """``upper_start`` for the kernels (an empty array: row by row)."""
        return _ROW_BY_ROW if self.upper_start is None else self.upper_start

    def __matmul__(self, other):
        if isinstance(other, np.ndarray) and other.ndim == 2 and other.dtype == np.float64:
            out = np.empty((self.shape[0], other.shape[1]))
            _product_dot(self.indptr, self.indices, self.data, self.upper_start_or_none(),
                         np.ascontiguousarray(other), out, np.zeros(other.shape[1]))
            return out
        return super().__matmul__(other)


_ROW_BY_ROW = np.zeros(0, dtype=np.int64)


class PatternMatrix:
    """The :class:`_CompiledCSR` of a mass pattern, made once per pattern and given the
    pattern's data every step (a copy, as a new matrix had: the solve's system is made from
    it in place): a new scipy matrix, its format checks, cost ~50 us a step, a sixth of
    q1's consistent step at 1e3 points."""

    def __init__(self):
        self._pattern = self._matrix = None

    def of(self, pattern) -> _CompiledCSR:
        """The matrix of ``pattern``'s entries now (symmetric bit for bit, in stencil order)."""
        if self._pattern is not pattern or self._matrix.data.shape != pattern.data.shape:
            self._matrix = _CompiledCSR(pattern.matrix())
            self._matrix.upper_start = pattern.diagonal
            self._matrix.upper_ordered = upper_is_later(self._matrix.indptr, self._matrix.indices, pattern.diagonal)
            self._pattern = pattern
        else:
            np.copyto(self._matrix.data, pattern.data)
        return self._matrix


@compiled(forceinline=True)
def _row_times_dense(indptr, indices, data, x, i):
    """Row i of ``A @ x`` for x of shape (n, 2), as four partial sums per column:
    the sums of a row (49 entries for cubic splines) are chains of dependent
    additions in strict IEEE arithmetic, and one chain per column left the
    product bound by the adder's latency (partial sums: 25% faster).

    Positions and column indices are taken as unsigned: numba tests a signed
    index for Python's negative wraparound on every access, and without the
    tests the consistent steps at 1e5 points ran 9-11% faster (q1 147 -> 131,
    q2 300 -> 265, cubic splines 500 -> 455 ns, together with the unsigned
    positions of the assembly in :mod:`femgrid_mpm.kernels.p2g`)."""
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    a3 = 0.0
    b0 = 0.0
    b1 = 0.0
    b2 = 0.0
    b3 = 0.0
    one, two, three, four = np.uint64(1), np.uint64(2), np.uint64(3), np.uint64(4)
    entry = np.uint64(indptr[i])
    stop = np.uint64(indptr[i + 1])
    while entry + three < stop:
        j0, j1 = np.uint64(indices[entry]), np.uint64(indices[entry + one])
        j2, j3 = np.uint64(indices[entry + two]), np.uint64(indices[entry + three])
        d0, d1, d2, d3 = data[entry], data[entry + one], data[entry + two], data[entry + three]
        a0 = fused(d0, x[j0, 0], a0)
        b0 = fused(d0, x[j0, 1], b0)
        a1 = fused(d1, x[j1, 0], a1)
        b1 = fused(d1, x[j1, 1], b1)
        a2 = fused(d2, x[j2, 0], a2)
        b2 = fused(d2, x[j2, 1], b2)
        a3 = fused(d3, x[j3, 0], a3)
        b3 = fused(d3, x[j3, 1], b3)
        entry += four
    while entry < stop:
        j = np.uint64(indices[entry])
        d = data[entry]
        a0 = fused(d, x[j, 0], a0)
        b0 = fused(d, x[j, 1], b0)
        entry += one
    return (a0 + a1) + (a2 + a3), (b0 + b1) + (b2 + b3)


@compiled()
def _csr_times_dense_dot(indptr, indices, data, x, out, dot):
    """``out = A @ x`` and ``dot[c] = x[:, c] . out[:, c]`` in one pass (x of shape (n, k))."""
    dot[:] = 0.0
    if x.shape[1] == 2:
        for i in range(len(indptr) - 1):
            first, second = _row_times_dense(indptr, indices, data, x, i)
            out[i, 0] = first
            out[i, 1] = second
            dot[0] = fused(x[i, 0], first, dot[0])
            dot[1] = fused(x[i, 1], second, dot[1])
    else:  # any number of columns, one at a time
        for i in range(len(indptr) - 1):
            for c in range(x.shape[1]):
                total = 0.0
                for entry in range(indptr[i], indptr[i + 1]):
                    total = fused(data[entry], x[indices[entry], c], total)
                out[i, c] = total
                dot[c] = fused(x[i, c], total, dot[c])


@compiled()
def upper_is_later(indptr, indices, upper_start) -> bool:
    """Whether every entry after a row's diagonal has a larger column."""
    for i in range(len(indptr) - 1):
        for entry in range(upper_start[i] + 1, indptr[i + 1]):
            if indices[entry] <= i:
                return False
    return True


@compiled()
def _symmetric_times_dense_dot(indptr, indices, data, upper_start, x, out, dot):
    """:func:`_csr_times_dense_dot` of a symmetric matrix from one entry of each pair.

    ``upper_start[i]`` is row i's diagonal entry; the entries after it are one of
    each symmetric pair (i, j), j != i (those of a stencil-ordered mass pattern:
    slot > centre).  Each such entry adds ``a_ij x_j`` to row i and ``a_ij x_i`` to
    row j, so the product reads half of the matrix (cubic splines at 1e5 points:
    1.31 -> 0.99 ms for two columns).  The sums run in another order than the
    row-wise product's: the same to round-off, reproducible bit for bit.
    """
    n, k = x.shape
    out[:] = 0.0
    dot[:] = 0.0
    if k == 2:
        for i in range(n):
            diagonal = upper_start[i]
            xi0 = x[i, 0]
            xi1 = x[i, 1]
            # two partial sums per column: chains of dependent additions (see _row_times_dense)
            a0 = data[diagonal] * xi0
            b0 = data[diagonal] * xi1
            a1 = 0.0
            b1 = 0.0
            one = np.uint64(1)
            entry = np.uint64(diagonal) + one
            stop = np.uint64(indptr[i + 1])
            while entry + one < stop:
                j0, j1 = np.uint64(indices[entry]), np.uint64(indices[entry + one])
                d0, d1 = data[entry], data[entry + one]
                a0 = fused(d0, x[j0, 0], a0)
                b0 = fused(d0, x[j0, 1], b0)
                a1 = fused(d1, x[j1, 0], a1)
                b1 = fused(d1, x[j1, 1], b1)
                out[j0, 0] = fused(d0, xi0, out[j0, 0])
                out[j0, 1] = fused(d0, xi1, out[j0, 1])
                out[j1, 0] = fused(d1, xi0, out[j1, 0])
                out[j1, 1] = fused(d1, xi1, out[j1, 1])
                entry += np.uint64(2)
            if entry < stop:
                j0 = np.uint64(indices[entry])
                d0 = data[entry]
                a0 = fused(d0, x[j0, 0], a0)
                b0 = fused(d0, x[j0, 1], b0)
                out[j0, 0] = fused(d0, xi0, out[j0, 0])
                out[j0, 1] = fused(d0, xi1, out[j0, 1])
            out[i, 0] += a0 + a1
            out[i, 1] += b0 + b1
    else:
        for i in range(n):
            diagonal = upper_start[i]
            for c in range(k):
                total = data[diagonal] * x[i, c]
                for entry in range(diagonal + 1, indptr[i + 1]):
                    j = indices[entry]
                    total = fused(data[entry], x[j, c], total)
                    out[j, c] = fused(data[entry], x[i, c], out[j, c])
                out[i, c] += total
    for i in range(n):  # every row is complete only now
        for c in range(k):
            dot[c] = fused(x[i, c], out[i, c], dot[c])


@compiled(forceinline=True)
def _product_dot(indptr, indices, data, upper_start, x, out, dot):
    """``out = A @ x`` and the dots ``x . out``: from one half when ``upper_start`` is given
    (a symmetric stencil-ordered matrix), else row by row."""
    if upper_start.shape[0] > 0:
        _symmetric_times_dense_dot(indptr, indices, data, upper_start, x, out, dot)
    else:
        _csr_times_dense_dot(indptr, indices, data, x, out, dot)


@compiled()
def _transpose_times_dense(indptr, indices, data, y, n_columns):
    """``A.T @ y`` for a CSR matrix A of shape (len(y), n_columns) and y of shape (len(y), k)."""
    out = np.zeros((n_columns, y.shape[1]))
    for row in range(len(indptr) - 1):
        for entry in range(indptr[row], indptr[row + 1]):
            j = indices[entry]
            for c in range(y.shape[1]):
                out[j, c] = fused(data[entry], y[row, c], out[j, c])
    return out
