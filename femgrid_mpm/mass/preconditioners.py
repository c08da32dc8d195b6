"""CG's preconditioners for the consistent mass of cubic B-splines: a tensor Gram solve
completed by an exact solve in a layer along the bodies' edges."""

from __future__ import annotations

import dataclasses
import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from ..kernels.arithmetic import fused
from ..kernels.compiled import compiled
from .ldl import NumericLDL, SymbolicLDL, _diagonal_index, _solve
from .sparse import _csr_times_dense_dot, _transpose_times_dense

if TYPE_CHECKING:  # system.py imports this module
    from .system import _System


@dataclass(frozen=True)
class TensorPreconditioner:
    """CG's preconditioner for tensor-product cubic B-splines: ``z = S^-1 (K_x ⊗ K_y)^-1 S^-1 r``.

    Inside a body of uniform density, ``N.T diag(m) N`` approaches ``rho h^2
    K_x ⊗ K_y`` with ``K`` the 1D Gram matrix of the splines (stencil
    ``(1, 120, 1191, 2416, 1191, 120, 1) / 5040``); its Jacobi-scaled form
    has a condition number near 350 in 2D, where CG needed ~340 iterations
    at 1e5 nodes.  ``S = sqrt(M_ii / K_ii)`` carries each node's mass and the
    tensor inverse is two sweeps of banded Cholesky solves, O(n); CG then
    needs ~25.  It is symmetric positive definite on the kept degrees of
    freedom (a principal block of the inverse of an SPD matrix), the excluded
    ones keep their identity rows.
    """

    factor_x: np.ndarray  # (4, n_x) upper banded Cholesky factor of K_x
    factor_y: np.ndarray
    gram_diagonal: float

    @property
    def lattice_shape(self) -> tuple[int, int]:
        """Nodes along x and y (node ``ix * n_y + iy``)."""
        return self.factor_x.shape[1], self.factor_y.shape[1]

    def scaled(self, system: "_System") -> tuple:
        """The arguments of :func:`_apply_tensor` for one system."""
        diagonal = 1.0 / system.inverse_diagonal
        scale = np.where(system.excluded, 0.0, 1.0 / np.sqrt(np.abs(diagonal) / self.gram_diagonal))
        return (scale, system.excluded, self.factor_x, self.factor_y)


#: lattice steps from an excluded or weak node, or from the lattice's edge, within
#: which :class:`BoundaryLayer` solves exactly.  Cubic splines' block with ``dt = "auto"``:
#: at 1e4 points widths 2, 3 and 4 take 6.2, 5.0 and 4.0 CG iterations a step and
#: 4.5-4.7 ms alike; at 1e5 points 3 and 4 both 4.0 iterations, 31.9-33.9 against
#: 33.3-34.5 ms a step
LAYER_WIDTH = 3


#: the largest share of the kept nodes a :class:`BoundaryLayer` may hold
LAYER_LIMIT = 0.5


@dataclass(frozen=True, eq=False)
class LayerLayout:
    """What a :class:`BoundaryLayer` keeps while its system's excluded and weak nodes and the
    layer's rows of the matrix's structure stay: its nodes, ``M[nodes, :]``'s structure with
    each entry's place in ``M``'s data, and the ordering and structure of the block's factors,
    analysed on the block alone (in the layer's own numbering, ``block_source`` its entries'
    places in ``M``'s data).  Finding the nodes and taking the rows by scipy's indexing took
    0.5 of a step's 0.9 ms of layer on cubic splines' block at 1e4 points."""

    empty: np.ndarray  # the excluded or weak nodes it was made for
    excluded: np.ndarray
    nodes: np.ndarray
    symbolic: SymbolicLDL
    rows_indptr: np.ndarray
    rows_indices: np.ndarray
    rows_source: np.ndarray
    block_source: np.ndarray
    #: weak references to the index arrays it was made from: the one system made in place from
    #: the mass pattern holds the same arrays every step, never changed in place
    #: (:meth:`.system._System.build`), so meeting them again settles it; other systems' (new
    #: every step on the scipy engine, or blended) are compared by value, and are not kept alive
    #: by the layout (at 1e5 points ~5 MB a layout)
    structure: tuple

    def fits(self, matrix, excluded: np.ndarray, empty: np.ndarray) -> bool:
        """Whether it is this system's layer: the same excluded and weak nodes, and the layer's
        rows stored where and as they were (so that both gathers still read them)."""
        nodes = self.nodes
        if not (np.array_equal(empty, self.empty) and np.array_equal(excluded, self.excluded)):
            return False
        if matrix.indptr is self.structure[0]() and matrix.indices is self.structure[1]():
            return True
        return (np.array_equal(matrix.indptr[nodes + 1] - matrix.indptr[nodes], np.diff(self.rows_indptr))
                and np.array_equal(matrix.indptr[nodes], self.rows_source[self.rows_indptr[:-1]])
                and np.array_equal(matrix.indices[self.rows_source], self.rows_indices))

    @classmethod
    def of(cls, matrix, excluded: np.ndarray, empty: np.ndarray, lattice_shape: tuple) -> "LayerLayout | None":
        """The layout of a system's layer, None if it is empty, holds more than
        :data:`LAYER_LIMIT` of the kept nodes, or a row of its block stores no diagonal entry."""
        lattice = np.column_stack(np.unravel_index(np.arange(len(excluded)), lattice_shape))
        nodes = np.flatnonzero(_near_empty_nodes(lattice, empty, LAYER_WIDTH) & ~excluded)
        if nodes.size == 0 or nodes.size > LAYER_LIMIT * np.count_nonzero(~excluded):
            return None
        starts, stops = matrix.indptr[nodes].astype(np.int64), matrix.indptr[nodes + 1].astype(np.int64)
        rows_indptr = np.zeros(len(nodes) + 1, dtype=np.int64)
        np.cumsum(stops - starts, out=rows_indptr[1:])
        source = np.repeat(starts - rows_indptr[:-1], stops - starts) + np.arange(rows_indptr[-1])
        columns = np.asarray(matrix.indices)[source].astype(np.int64)
        # the block in the layer's numbering: its analysis and factors read the layer's entries
        # only (on the whole matrix's structure an analysis cost 13 ms at 1e5 points)
        local = np.full(len(excluded), -1, dtype=np.int64)
        local[nodes] = np.arange(len(nodes))
        inside = local[columns] >= 0
        block_indptr = np.concatenate(([0], np.cumsum(inside)))[rows_indptr]
        block_indices = local[columns[inside]]
        diagonal = _diagonal_index(block_indptr, block_indices)
        if np.any(diagonal < 0):  # (every active node stores its diagonal; a block without one is not factored)
            return None
        symbolic = SymbolicLDL.analyse(block_indptr, block_indices, diagonal, np.zeros(len(nodes), dtype=bool))
        # eliminated in the layer's numbering, read and written in the system's: the solves and the
        # weakest pivot's node are the system's
        symbolic = dataclasses.replace(symbolic, order=nodes[symbolic.order])
        # the matrix's own index types for the rows: the products compile once for both
        return cls(empty.copy(), excluded.copy(), nodes, symbolic, rows_indptr.astype(matrix.indptr.dtype),
                   columns.astype(matrix.indices.dtype), source, source[inside],
                   (weakref.ref(matrix.indptr), weakref.ref(matrix.indices)))


def layout_of(matrix, excluded: np.ndarray, weak: np.ndarray, lattice_shape: tuple,
              last: LayerLayout | None = None) -> LayerLayout | None:
    """A system's :class:`LayerLayout`: ``last`` where it fits, else made afresh."""
    empty = excluded | weak
    return last if last is not None and last.fits(matrix, excluded, empty) else \
        LayerLayout.of(matrix, excluded, empty, lattice_shape)


@dataclass
class BoundaryLayer:
    """Completes :class:`TensorPreconditioner` where a body's edge makes ``M`` unlike a tensor product.

    The tensor preconditioner is exact for a uniform body that fills the
    lattice; near an edge (partly filled supports, lumped weak nodes, a
    support's excluded nodes) it is not, and CG's residual lingers there:
    after 8 iterations, 90% of it sat within 3 nodes of an excluded one
    (cubic splines, 1e5 points).  The layer of nodes within
    :data:`LAYER_WIDTH` of such nodes gets an exact solve with its block
    ``M_LL`` (the compiled ``L D L^T`` of :mod:`.ldl`, factored every step on the
    layer's :class:`LayerLayout`, analysed again when the excluded or weak nodes or the
    layer's rows of the matrix's structure change), in a symmetric
    multiplicative Schwarz sweep, layer - tensor - layer::

        z  = R^T M_LL^-1 R r
        z += T^-1 (r - M z)
        z += R^T M_LL^-1 R (r - M z)

    ``M z`` needs only the layer's rows (``M`` is symmetric, ``z`` lives on
    the layer in the first product), so a sweep costs the tensor solve, two
    small triangular solves and two products with the layer's rows.  With
    ``B = R^T M_LL^-1 R`` and ``Q = I - B M`` the sweep is
    ``P^-1 = B + Q T^-1 Q^T``: symmetric, and positive definite whenever
    ``T`` is (the layer's solve being exact; a second review found
    ``T^-1 M`` with eigenvalues up to 9 and ``P^-1 M`` still in [0.68, 1.01]).
    Only an inaccurate factorization could spoil it: CG checks ``r.z > 0``
    as it goes and :class:`ConsistentMass` then falls back to the tensor
    preconditioner alone.  A layer holding more than :data:`LAYER_LIMIT` of
    the kept nodes (a thin body) is not built: factoring it costs more than
    the iterations it saves (a body 4 cells thick, 86% in the layer: 109
    against 89 ms per step).  Cubic splines, 1e5 points: 5 + 14 -> 1 + 4
    iterations per step (velocity + acceleration).  The layer's block is a
    band a few nodes wide along the edges, whose factor fills little (21
    entries of ``L`` a node): on the block of 1e4 points its ``L D L^T`` on a
    kept layout took 0.2 ms a step where SuperLU's factorization with the
    check of its pivots, and scipy's extraction of the block, took 2.4 ms.

    Attributes
    ----------
    nodes : ndarray of int, shape (n_layer,)
    factors : NumericLDL
        ``M_LL = L D L^T`` on ``layout``; its solves take and give arrays of the
        system's size, reading and writing the layer's rows only (zero elsewhere).
    rows_data : ndarray, shape (entries,)
        The entries of ``M[nodes, :]`` (shape (n_layer, n_nodes), stored as the layout's
        ``rows_indptr`` and ``rows_indices`` say); ``M[:, nodes]`` is its transpose (``M``
        symmetric), applied by :func:`_transpose_times_dense` (a CSR matrix of the transpose
        loops over every node's row: 0.25 against 0.09 ms).
    """

    nodes: np.ndarray
    factors: NumericLDL
    rows_data: np.ndarray
    layout: LayerLayout

    @classmethod
    def on(cls, layout: LayerLayout | None, matrix: sp.csr_matrix) -> "BoundaryLayer | None":
        """The layer on a layout (:func:`layout_of`) for this step's matrix; None without a
        layout (no layer, or more than :data:`LAYER_LIMIT` of the kept nodes), or where the block
        is singular (a pivot below :data:`.direct.PIVOT_RATIO` of its diagonal entry: CG then
        meets the singularity and reports it, as without a layer)."""
        if layout is None:
            return None
        factors, _ = layout.symbolic.factor(matrix.data[layout.block_source])
        if factors is None:
            return None
        return cls(layout.nodes, factors, matrix.data[layout.rows_source], layout)

    def arguments(self) -> tuple:
        """The layer's arrays, as :func:`_layer_sweep` takes them after ``r``."""
        factors, layout = self.factors, self.layout
        return (self.nodes, layout.rows_indptr, layout.rows_indices, self.rows_data, factors.symbolic.order,
                factors.symbolic.lower_indptr, factors.lower_rows, factors.lower_data, factors.pivots)

    def sweep(self, r: np.ndarray, tensor: tuple) -> np.ndarray:
        """``z = P^-1 r`` for r of shape (n_nodes, k); ``tensor``: the arguments of
        :func:`_apply_tensor` after its two arrays (:meth:`TensorPreconditioner.scaled`)."""
        return _layer_sweep(np.ascontiguousarray(r, dtype=float), *self.arguments(), *tensor)


@compiled()
def _layer_sweep(r, nodes, rows_indptr, rows_indices, rows_data, order, lower_indptr, lower_rows, lower_data,
                 pivots, scale, excluded, factor_x, factor_y):
    """:meth:`BoundaryLayer.sweep`: layer - tensor - layer, in one compiled call (CG's loop
    calls it every iteration, and from Python its seven steps' calls and temporaries took
    as long as its triangular solves)."""
    n, k = r.shape
    n_layer = len(nodes)
    z = np.zeros((n, k))
    _solve(r, z, order, lower_indptr, lower_rows, lower_data, pivots)  # the layer's rows of r in and out
    on_layer = np.empty((n_layer, k))
    for i in range(n_layer):
        for c in range(k):
            on_layer[i, c] = z[nodes[i], c]
    # M z from the layer's rows alone: z lives on the layer, and M[:, nodes] = M[nodes, :]^T
    rest = _transpose_times_dense(rows_indptr, rows_indices, rows_data, on_layer, n)
    for i in range(n):
        for c in range(k):
            rest[i, c] = r[i, c] - rest[i, c]
    tensor = np.empty((n, k))
    _apply_tensor(rest, tensor, scale, excluded, factor_x, factor_y)
    for i in range(n):
        for c in range(k):
            z[i, c] = z[i, c] + tensor[i, c]
    layer_rows = np.empty((n_layer, k))
    _csr_times_dense_dot(rows_indptr, rows_indices, rows_data, z, layer_rows, np.zeros(k))
    residual = np.zeros((n, k))
    for i in range(n_layer):
        for c in range(k):
            residual[nodes[i], c] = r[nodes[i], c] - layer_rows[i, c]
    correction = np.zeros((n, k))
    _solve(residual, correction, order, lower_indptr, lower_rows, lower_data, pivots)
    for i in range(n):
        for c in range(k):
            z[i, c] = z[i, c] + correction[i, c]
    return z


def tensor_preconditioner(grid) -> TensorPreconditioner | None:
    """For grids whose basis declares ``tensor_gram`` (cubic B-splines, nodes numbered
    ``i * n_y + j``), else None (Jacobi)."""
    from scipy.linalg import cholesky_banded

    if not grid.definition.tensor_gram:
        return None
    stencil = np.array([2416.0, 1191.0, 120.0, 1.0]) / 5040.0
    factors = []
    for n_cells in grid.discretization.n_elements:
        n = n_cells + 3
        banded = np.zeros((4, n))
        for offset in range(4):
            banded[3 - offset, offset:] = stencil[offset]
        factors.append(np.ascontiguousarray(cholesky_banded(banded, lower=False)))
    if factors[0].shape[1] * factors[1].shape[1] != grid.n_nodes:  # pragma: no cover
        return None
    return TensorPreconditioner(factors[0], factors[1], stencil[0] ** 2)


def _near_empty_nodes(lattice: np.ndarray, empty: np.ndarray, width: int) -> np.ndarray:
    """(n_nodes,) bool: the nodes within ``width`` lattice steps (along x and y, and
    diagonally) of an ``empty`` one or of the grid's edge (a body there fills its
    elements partly too); ``lattice`` (n_nodes, 2) gives each node's indices.  CG's
    singularity check near the edges and its boundary layer (:class:`BoundaryLayer`)."""
    from scipy.ndimage import maximum_filter

    image = np.zeros(tuple(lattice.max(axis=0) + 1), dtype=bool)
    image[lattice[:, 0], lattice[:, 1]] = empty
    return maximum_filter(image, size=2 * width + 1, mode="constant", cval=True)[lattice[:, 0], lattice[:, 1]]


@compiled()
def _banded_sweeps(factor, values, count, n_lines):
    """Solve ``U^T U z = values`` in place on ``n_lines`` independent lattice lines
    at once (U upper banded, bandwidth 3, ``factor[3 + i - j, j] = U[i, j]``):
    entry ``j`` of line ``l`` is ``values[j * n_lines + l]``, so the inner loop
    runs over contiguous, independent lines.  The diagonal is inverted once (a
    product per entry instead of a division)."""
    inverse = 1.0 / factor[3]
    for j in range(count):
        row = j * n_lines
        for line in range(n_lines):
            total = values[row + line]
            if j >= 3:
                total = fused(-factor[0, j], values[row - 3 * n_lines + line], total)
            if j >= 2:
                total = fused(-factor[1, j], values[row - 2 * n_lines + line], total)
            if j >= 1:
                total = fused(-factor[2, j], values[row - n_lines + line], total)
            values[row + line] = total * inverse[j]
    for i in range(count - 1, -1, -1):
        row = i * n_lines
        for line in range(n_lines):
            total = values[row + line]
            if i + 1 < count:
                total = fused(-factor[2, i + 1], values[row + n_lines + line], total)
            if i + 2 < count:
                total = fused(-factor[1, i + 2], values[row + 2 * n_lines + line], total)
            if i + 3 < count:
                total = fused(-factor[0, i + 3], values[row + 3 * n_lines + line], total)
            values[row + line] = total * inverse[i]


@compiled()
def _apply_tensor(r, out, scale, excluded, factor_x, factor_y):
    """``out = S^-1 (K_x ⊗ K_y)^-1 S^-1 r`` on kept nodes, ``r`` on excluded ones
    (node ``ix * n_y + iy``)."""
    n_x, n_y = factor_x.shape[1], factor_y.shape[1]
    line = np.empty(n_x * n_y)
    transposed = np.empty(n_x * n_y)
    for c in range(r.shape[1]):
        for ix in range(n_x):
            for iy in range(n_y):
                transposed[iy * n_x + ix] = scale[ix * n_y + iy] * r[ix * n_y + iy, c]
        _banded_sweeps(factor_y, transposed, n_y, n_x)  # along y, the lines (ix) contiguous
        for ix in range(n_x):
            for iy in range(n_y):
                line[ix * n_y + iy] = transposed[iy * n_x + ix]
        _banded_sweeps(factor_x, line, n_x, n_y)  # along x, the lines (iy) contiguous
        for i in range(n_x * n_y):
            out[i, c] = r[i, c] if excluded[i] else scale[i] * line[i]
    return out
