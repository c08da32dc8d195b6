"""Compiled shape functions: every basis as a short sum of separated terms.

Each local function of every basis here is a polynomial of degree at most
``d`` in each cell coordinate, and in fact a short sum of products of 1D
polynomials, ``phi_k(xi, eta) = sum_t U_i(t)(xi) W_j(t)(eta)``: one term for
the tensor-product bases (q1, q2, cubic B-splines), two for the corner
functions of serendipity.  :func:`separated_tables` derives that form once per
grid from the basis's own definition (the monomial coefficients that
:class:`~femgrid_mpm.bases.LocalPolynomials` fits to scikit-fem's ``lbasis``,
or the per-cell tables of :class:`~femgrid_mpm.bases.TensorSplines`) by exact
skeleton (cross) decomposition, and checks it reproduces them.  Evaluating a
point is then a few 1D Horner evaluations and ``3 x n_terms`` products, the
same numbers as :meth:`femgrid_mpm.Grid.shape_functions` to rounding (tested
to 1e-12 for every registered basis).

A point is located exactly as :meth:`femgrid_mpm.Grid.locate` does (same
arithmetic, so the same element and cell coordinates bit for bit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
from numba.extending import overload
import numpy as np

from ..bases import LocalPolynomials, TensorSplines
from .arithmetic import fused
from .compiled import compiled


@dataclass(frozen=True)
class _Factors:
    """A basis as 1D factors on the lattice, the arrays every kernel takes.

    Attributes
    ----------
    marker : tuple
        ``n1`` zeros, ``n1`` the number of 1D factors per direction: its
        length is a compile-time constant for numba, so each kind of basis
        gets kernels with fully unrolled loops over its ``n1 x n1`` slots.
        :data:`LINEAR` (two ``True``) for q1, whose factors are exactly
        ``(1 - s, s)`` along both axes: the kernels compute them so (q1's
        three passes ~1.5 ns per point faster each, bit for bit the same).
    geometry : ndarray, shape (5,)
        ``lower_x, lower_y, upper_x, upper_y, 1 / element_width``.
    n_elements : ndarray of int64, shape (2,)
    factors_x, factors_y : ndarray, shape (n_tables, n1, n1)
        Coefficients (increasing powers) of the 1D factors along x and y
        (Lagrange polynomials, or the splines' own pieces); one table per
        cell column (row) for bases whose pieces differ from cell to cell
        (open-knot splines), else a single table.
    table_x, table_y : ndarray of int32, shape (n_elements_x,), (n_elements_y,)
        Which table each cell column (row) uses.
    uniform : ndarray of int64, shape (4,)
        ``(first_x, last_x, first_y, last_y)``: the cell columns
        ``first_x..last_x`` (rows ``first_y..last_y``) all use the table of
        ``first_x`` (``first_y``), which the kernels load once into registers
        (every cell for Lagrange bases and ghost-node splines, the interior
        for open-knot splines); a per-point table lookup made the transfers
        ~1.7x slower.
    """

    marker: tuple
    geometry: np.ndarray
    n_elements: np.ndarray
    factors_x: np.ndarray
    table_x: np.ndarray
    factors_y: np.ndarray
    table_y: np.ndarray
    uniform: np.ndarray

    def arrays(self) -> tuple:
        """The kernels' arguments, in their order; the last is the topology that
        :func:`cell_nodes` reads (the numbering along the lattice, or the connectivity)."""
        return (self.marker, self.geometry, self.n_elements, self.factors_x, self.table_x, self.factors_y,
                self.table_y, self.uniform, *self._extra(), self._topology())

    def _extra(self) -> tuple:
        return ()

    def _topology(self):
        return self.numbering


@dataclass(frozen=True)
class BasisTables(_Factors):
    """A grid's basis in separated form (any basis: the flat form), with its
    faster forms where it has them.

    Attributes
    ----------
    terms, term_weights : ndarray of int32 and of float, shape (n_local, width)
        Local function k is ``sum_t term_weights[k, t] * q_(terms[k, t])``
        with ``q_(i n1 + j) = U_i(xi) W_j(eta)``.
    connectivity : ndarray of int32, shape (n_elements, n_local)
        Global node of each local function, element ``ix * n_elements_y + iy``.
    tensor, folded : TensorTables or FoldedTables or None
        The basis as tensor products, or as tensor products plus a share of
        the centre one (serendipity).
    """

    terms: np.ndarray = None
    term_weights: np.ndarray = None
    connectivity: np.ndarray = None
    tensor: "TensorTables | None" = None
    folded: "FoldedTables | None" = None

    @property
    def n_local(self) -> int:
        return self.connectivity.shape[1]

    def _extra(self) -> tuple:
        return ((self.terms, self.term_weights),)

    def _topology(self):
        return self.connectivity  # any basis: its nodes are read per point


@dataclass(frozen=True)
class TensorTables(_Factors):
    """A tensor-product basis, ``phi_(i n1 + j) = U_i(xi) W_j(eta)``, for the fast kernels
    (sum factorization).  ``order[s]`` is the grid's local index of tensor
    slot ``s``; ``connectivity`` is the grid's, permuted to tensor order, and
    ``numbering`` its affine form (:func:`lattice_numbering`), which the kernels use."""

    connectivity: np.ndarray = None
    order: np.ndarray = None
    numbering: tuple = None


@dataclass(frozen=True)
class FoldedTables(_Factors):
    """Tensor-product functions plus a share of the centre one (serendipity), for the folded kernels.

    Local function k is ``q_(s_k) + fold[s_k] q_c`` with
    ``q_(i n1 + j) = U_i(xi) W_j(eta)`` and ``c = (n1 n1) // 2`` the centre
    slot, which is no function of its own: serendipity's corner functions
    are their Q2 functions minus a quarter of the centre bubble, the
    mid-side ones plus half of it.  The kernels evaluate the ``n1 x n1``
    products in registers and fold the centre in (no scratch arrays), so
    serendipity runs at about q2's speed (the ``local_*`` kernels of
    :mod:`.transfer`, shared with the flat form).  ``connectivity`` is in slot order (the centre slot holds a
    node of the element that is never touched), ``order[s]`` the grid's
    local index of slot s (-1 for the centre); ``numbering`` as for :class:`TensorTables`.
    """

    fold: tuple = ()
    connectivity: np.ndarray = None
    order: np.ndarray = None
    numbering: tuple = None

    def _extra(self) -> tuple:
        return (self.fold,)


def _folded_form(factors_x, factors_y, terms, weights, connectivity):
    """``(fold, connectivity, order)`` if every function is one product with
    weight 1 plus a multiple of the centre product (odd ``n1``), else None."""
    n1 = factors_x.shape[1]
    centre = (n1 * n1) // 2
    if n1 % 2 == 0 or factors_y.shape[1] != n1:
        return None
    fold = np.zeros(n1 * n1)
    order = np.full(n1 * n1, -1, dtype=np.int64)
    for k in range(len(terms)):
        own = [s for s, c in zip(terms[k], weights[k]) if c == 1.0 and s != centre]
        others = [(s, c) for s, c in zip(terms[k], weights[k]) if c != 0.0 and s != (own[0] if own else -1)]
        if len(own) != 1 or order[own[0]] >= 0 or any(s != centre for s, _ in others):
            return None
        order[own[0]] = k
        fold[own[0]] = sum(c for _, c in others)
    if np.count_nonzero(order >= 0) != n1 * n1 - 1:
        return None
    fold[centre] = -1.0  # q_c - q_c: the centre slot's weight is exactly zero
    slots = np.where(order >= 0, order, 0)
    return tuple(float(c) for c in fold), np.ascontiguousarray(connectivity[:, slots]), order


#: the marker of factors that are exactly ``(1 - s, s)`` (coefficients ``LINEAR_FACTORS``, by
#: increasing power), which :func:`cell_factors` computes without the tables
LINEAR = (True, True)
LINEAR_FACTORS = np.array([[1.0, -1.0], [0.0, 1.0]])


def separated_tables(grid) -> BasisTables:
    """The separated form of ``grid``'s basis (see the module docstring)."""
    d = grid.discretization
    local = d.local_basis
    geometry = np.array([*grid.lower, *grid.upper, 1.0 / d.element_width])
    n_elements = np.array(d.n_elements, dtype=np.int64)
    connectivity = np.ascontiguousarray(d.connectivity, dtype=np.int32)
    if isinstance(local, TensorSplines):
        # per-cell tables (cell, power, function); function k = 4 a + b is X_a(xi) Y_b(eta)
        factors_x = np.ascontiguousarray(np.swapaxes(local.tables[0], 1, 2))
        factors_y = np.ascontiguousarray(np.swapaxes(local.tables[1], 1, 2))
        table_x = np.arange(d.n_elements[0], dtype=np.int32)
        table_y = np.arange(d.n_elements[1], dtype=np.int32)
        terms = np.array([(4 * a + b, a, b) for a in range(4) for b in range(4)], dtype=np.int32)
        weights = np.ones(len(terms))
        # flat form: the tensor products themselves
        flat = (factors_x, factors_y, np.arange(16, dtype=np.int32)[:, None], np.ones((16, 1)))
    elif isinstance(local, LocalPolynomials):
        us, ws, separated = _skeleton_terms(local)
        factors_x, factors_y = np.array(us)[None], np.array(ws)[None]
        table_x = np.zeros(d.n_elements[0], dtype=np.int32)
        table_y = np.zeros(d.n_elements[1], dtype=np.int32)
        terms = np.array([term[:3] for term in separated], dtype=np.int32)
        weights = np.array([term[3] for term in separated])
        flat = _lagrange_expansion(local)
    else:  # pragma: no cover - a new kind of local basis needs its separated form here
        raise TypeError(f"no separated form for {type(local).__name__}")
    tensor = _tensor_form(factors_x, factors_y, terms, weights)
    if tensor is not None:
        fx, fy, order = tensor
        tensor_connectivity = np.ascontiguousarray(connectivity[:, order])
        linear = all(f.shape[1:] == LINEAR_FACTORS.shape and np.all(f == LINEAR_FACTORS) for f in (fx, fy))
        tensor = TensorTables(LINEAR if linear else (0,) * fx.shape[1], geometry, n_elements, fx, table_x, fy, table_y,
                              _uniform_runs(fx, table_x, fy, table_y), connectivity=tensor_connectivity, order=order,
                              numbering=lattice_numbering(tensor_connectivity, d.n_elements, fx.shape[1]))
    factors_x, factors_y, terms, weights = flat
    uniform = _uniform_runs(factors_x, table_x, factors_y, table_y)
    folded = None if tensor is not None else _folded_form(factors_x, factors_y, terms, weights, connectivity)
    if folded is not None:
        fold, folded_connectivity, order = folded
        n1 = factors_x.shape[1]
        folded = FoldedTables((0,) * n1, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform,
                              fold=fold, connectivity=folded_connectivity, order=order,
                              numbering=lattice_numbering(folded_connectivity, d.n_elements, n1, skip=(n1 * n1) // 2))
    return BasisTables((0,) * factors_x.shape[1], geometry, n_elements, factors_x, table_x, factors_y, table_y,
                       uniform, terms=terms, term_weights=weights, connectivity=connectivity, tensor=tensor,
                       folded=folded)


def lattice_numbering(connectivity: np.ndarray, n_elements, n1: int, skip: int = -1) -> tuple:
    """The node of slot ``s = i n1 + j`` of element ``(ix, iy)`` as an affine function,
    ``ix * step_x + iy * steps_y[i] + offsets[s]``: the flat tuple
    ``(step_x, *steps_y, *offsets)``, ``steps_y`` a single step if every column
    has the same (so the tuple's length tells which).

    The grid numbers its nodes along the lattice (x index, then y index), so
    moving one element along x adds the same number to every node, and
    moving along y adds the same number to the nodes of one column of slots
    (serendipity's middle column has half as many nodes as the others).  The
    kernels compute a point's nodes from its cell instead of reading them:
    ~5-8% of a step (q1 2.4 of 12.4 ns per point in P2G, cubic splines 3.5
    of 62 in the force pass).  ``skip``: a slot that is no function (the
    folded centre), left out of the check.

    >>> connectivity = np.array([[0, 1, 3, 4], [1, 2, 4, 5], [3, 4, 6, 7], [4, 5, 7, 8]])  # q1, 2 x 2 cells
    >>> lattice_numbering(connectivity, (2, 2), 2)
    (3, 1, 0, 1, 3, 4)
    """
    n_x, n_y = int(n_elements[0]), int(n_elements[1])
    nodes = connectivity.astype(np.int64).reshape(n_x, n_y, n1, n1)
    step_x = int(nodes[1, 0, 0, 0] - nodes[0, 0, 0, 0]) if n_x > 1 else 0
    steps_y = tuple(int(nodes[0, 1, i, 0] - nodes[0, 0, i, 0]) if n_y > 1 else 0 for i in range(n1))
    offsets = nodes[0, 0].reshape(-1).copy()
    ix, iy = np.meshgrid(np.arange(n_x), np.arange(n_y), indexing="ij")
    affine = ix[:, :, None, None] * step_x + iy[:, :, None, None] * np.array(steps_y)[:, None] + offsets.reshape(n1, n1)
    used = np.ones(n1 * n1, dtype=bool)
    if skip >= 0:
        used[skip] = False  # its node (one of the element's) is never read
    if not np.array_equal(affine.reshape(n_x, n_y, -1)[..., used], nodes.reshape(n_x, n_y, -1)[..., used]):
        raise AssertionError("the grid's nodes are not numbered along the lattice")
    # one step for all columns when they share it (every basis but serendipity): one product per point
    steps = steps_y[:1] if len(set(steps_y)) == 1 else steps_y
    return (step_x, *steps, *(int(o) for o in offsets))  # flat: numba passes no nested tuple into a prange body


def _lagrange_expansion(local: LocalPolynomials):
    """Any basis of degree d per coordinate in the tensor Lagrange basis of Q_d:
    ``phi_k = sum_s T[s, k] L_a(xi) L_b(eta)`` (s = a (d + 1) + b) with
    ``T[s, k] = phi_k`` at the lattice point ``(a / d, b / d)``, exact since
    tensor interpolation reproduces Q_d.  Serendipity: each function is its own
    Q2 function plus ``-1/4`` (corners) or ``1/2`` (mid-sides) of the centre one.

    Returns ``(factors_x, factors_y, slots, weights)`` with the nonzero
    ``T[s, k]`` as rows ``slots[k], weights[k]`` (padded with zero weights).
    """
    n1 = local.degree + 1
    points = np.linspace(0.0, 1.0, n1)
    lagrange = np.linalg.inv(np.vander(points, n1, increasing=True)).T  # row a: coefficients of L_a
    xi, eta = (a.ravel() for a in np.meshgrid(points, points, indexing="ij"))
    expansion, _, _ = local.evaluate(np.column_stack([xi, eta]))  # (n1 * n1, n_local)
    expansion[np.abs(expansion) < 1e-13] = 0.0
    width = max(1, int((expansion != 0).sum(axis=0).max()))
    slots = np.zeros((local.n_local, width), dtype=np.int32)
    weights = np.zeros((local.n_local, width))
    for k in range(local.n_local):
        nonzero = np.flatnonzero(expansion[:, k])
        slots[k, : len(nonzero)] = nonzero
        weights[k, : len(nonzero)] = expansion[nonzero, k]
    return lagrange[None].copy(), lagrange[None].copy(), slots, weights


def _uniform_runs(factors_x, table_x, factors_y, table_y) -> np.ndarray:
    """``uniform`` of :class:`_Factors`: the longest run of equal tables along x, then y."""
    return np.array([*_uniform_run(factors_x, table_x), *_uniform_run(factors_y, table_y)], dtype=np.int64)


def _uniform_run(factors, table):
    """``(first, last)``: the longest run of consecutive cells whose tables are equal."""
    tables = factors[table]
    same = np.all(tables[1:] == tables[:-1], axis=(1, 2))
    best, start = (0, 0), 0
    for cell in range(1, len(table) + 1):
        if cell == len(table) or not same[cell - 1]:
            if cell - 1 - start > best[1] - best[0]:
                best = (start, cell - 1)
            start = cell
    return best


def _tensor_form(factors_x, factors_y, terms, weights):
    """``(factors_x, factors_y, order)`` if every function is one product ``U_i W_j``
    over a full ``n1 x n1`` set with ``n1 - 1`` the degree (q1, q2, cubic
    splines), the weights folded into the factors; else None (serendipity)."""
    n1 = factors_x.shape[2]
    if not (factors_x.shape[1] == factors_y.shape[1] == n1 and len(terms) == n1 * n1 and n1 in (2, 3, 4)):
        return None
    if len(set(terms[:, 0].tolist())) != len(terms) or len(set(map(tuple, terms[:, 1:].tolist()))) != len(terms):
        return None
    weight = np.zeros((n1, n1))
    order = np.zeros(n1 * n1, dtype=np.int64)
    for (k, i, j), c in zip(terms, weights):
        weight[i, j] = c
        order[i * n1 + j] = k
    # weight = alpha_i beta_j: fold alpha into U_i and beta into W_j
    beta = weight[0, :]
    alpha = weight[:, 0] / beta[0]
    if np.abs(np.outer(alpha, beta) - weight).max() > 1e-12 * np.abs(weight).max():
        return None
    fx = factors_x * alpha[None, :, None]
    fy = factors_y * beta[None, :, None]
    return np.ascontiguousarray(fx), np.ascontiguousarray(fy), order


def _skeleton_terms(local: LocalPolynomials):
    """Exact skeleton decomposition of each local function's coefficient matrix.

    ``C_k[a, b]`` (the coefficient of ``xi**a eta**b``) is peeled into
    ``c * outer(u, w)`` terms, pivoting on its largest remaining entry
    (complete pivoting); ``u`` and ``w`` are the pivot column and row, each
    scaled to a largest coefficient of +1, so that 1D factors common to
    several functions are found and evaluated once.
    """
    n_1d = local.degree + 1
    us: list[np.ndarray] = []
    ws: list[np.ndarray] = []
    terms = []

    def normalized(vector):
        # the first of the largest entries (ties within rounding: (1 - s)^3 has -3 and 3)
        magnitude = np.abs(vector)
        pivot = vector[np.flatnonzero(magnitude >= (1 - 1e-9) * magnitude.max())[0]]
        return vector / pivot, pivot

    def index_of(factors, vector):
        for index, known in enumerate(factors):
            if np.allclose(known, vector, rtol=0, atol=1e-12):
                return index
        factors.append(vector)
        return len(factors) - 1

    for k in range(local.n_local):
        coefficients = local.values[:, k].reshape(n_1d, n_1d)
        remainder = coefficients.copy()
        scale = np.abs(coefficients).max()
        while np.abs(remainder).max() > 1e-12 * scale:  # the fitted coefficients carry ~1e-14
            a, b = np.unravel_index(np.argmax(np.abs(remainder)), remainder.shape)
            u, u_scale = normalized(remainder[:, b] / remainder[a, b])
            w, w_scale = normalized(remainder[a, :].copy())
            i, j = index_of(us, u), index_of(ws, w)
            terms.append((k, i, j, u_scale * w_scale))
            remainder = remainder - u_scale * w_scale * np.outer(us[i], ws[j])
        rebuilt = sum(c * np.outer(us[i], ws[j]) for kk, i, j, c in terms if kk == k)
        if np.abs(rebuilt - coefficients).max() > 1e-12 * scale:  # pragma: no cover
            raise AssertionError(f"separated form of local function {k} does not reproduce it")
    return us, ws, terms


# -- kernels -------------------------------------------------------------------------------------------


@compiled(inline="always")
def evaluate_point(px, py, constants, marker, factors_x, table_x, factors_y, table_y, connectivity, terms,
                   term_weights, q, qx, qy, unused, w, wx, wy):
    """Shape functions of a point in the grid (see :func:`located_weights`) into ``w, wx,
    wy`` (n_local); returns its nodes (``connectivity``'s row)."""
    nodes, fx, dfx, fy, dfy = located_weights(px, py, constants, marker, factors_x, table_x, factors_y, table_y,
                                              connectivity)
    n1 = len(marker)
    for i in range(n1):
        for j in range(n1):
            q[i * n1 + j] = fx[i] * fy[j]
            qx[i * n1 + j] = dfx[i] * fy[j]
            qy[i * n1 + j] = fx[i] * dfy[j]
    for k in range(w.shape[0]):
        value = 0.0
        slope_x = 0.0
        slope_y = 0.0
        for t in range(terms.shape[1]):
            s = terms[k, t]
            c = term_weights[k, t]
            value += c * q[s]
            slope_x += c * qx[s]
            slope_y += c * qy[s]
        w[k] = value
        wx[k] = slope_x
        wy[k] = slope_y
    return nodes


@compiled()
def scratch(factors_x, factors_y, n_local):
    """Per-point work arrays for :func:`evaluate_point`."""
    n = factors_x.shape[1] * factors_y.shape[1]
    return (np.empty(n), np.empty(n), np.empty(n), np.empty(1), np.empty(n_local), np.empty(n_local),
            np.empty(n_local))


@compiled()
def shape_function_data(x, marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, form,
                        connectivity, values, d_x, d_y, nodes):
    """``N, dNdx, dNdy`` of every point as fixed-width rows (n, n_local), and their nodes.

    Returns the first point outside the grid, or -1.
    """
    n_local = connectivity.shape[1]
    terms, term_weights = form
    fx, dfx, fy, dfy, w, wx, wy = scratch(factors_x, factors_y, n_local)
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        if not inside_grid(x[p, 0], x[p, 1], constants):
            return p
        local = evaluate_point(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y,
                               connectivity, terms, term_weights, fx, dfx, fy, dfy, w, wx, wy)
        for k in range(n_local):
            values[p, k] = w[k]
            d_x[p, k] = wx[k]
            d_y[p, k] = wy[k]
            nodes[p, k] = local[k]
    return -1


# -- tensor-product kernels: loops over n1 x n1 nodes unrolled at compile time ---------------------------


def load_table(factors, table, marker):  # pragma: no cover - replaced by the overload in numba
    """The coefficients ``factors[table]`` as a nested tuple (``len(marker)`` factors)."""
    raise NotImplementedError("only callable from compiled code")


@overload(load_table, inline="always")
def _load_table(factors, table, marker):
    n1 = len(marker.types)
    if n1 == 2:
        def linear(factors, table, marker):
            c = factors
            t = table
            return ((c[t, 0, 0], c[t, 0, 1]), (c[t, 1, 0], c[t, 1, 1]))
        return linear
    if n1 == 3:
        def quadratic(factors, table, marker):
            c = factors
            t = table
            return ((c[t, 0, 0], c[t, 0, 1], c[t, 0, 2]), (c[t, 1, 0], c[t, 1, 1], c[t, 1, 2]),
                    (c[t, 2, 0], c[t, 2, 1], c[t, 2, 2]))
        return quadratic
    if n1 == 4:
        def cubic(factors, table, marker):
            c = factors
            t = table
            return ((c[t, 0, 0], c[t, 0, 1], c[t, 0, 2], c[t, 0, 3]), (c[t, 1, 0], c[t, 1, 1], c[t, 1, 2], c[t, 1, 3]),
                    (c[t, 2, 0], c[t, 2, 1], c[t, 2, 2], c[t, 2, 3]), (c[t, 3, 0], c[t, 3, 1], c[t, 3, 2], c[t, 3, 3]))
        return cubic
    return None


def factors_1d(s, c, scale):  # pragma: no cover - replaced by the overload in numba
    """Values and slopes (times ``scale``) of the 1D factors with coefficients ``c`` at s, as tuples."""
    raise NotImplementedError("only callable from compiled code")


@overload(factors_1d, inline="always")
def _factors_1d(s, c, scale):
    # Horner's scheme, each step one fused multiply-add (:mod:`.arithmetic`)
    n1 = len(c.types) if hasattr(c, "types") else c.count
    if n1 == 2:
        def linear(s, c, scale):
            return ((fused(c[0][1], s, c[0][0]), fused(c[1][1], s, c[1][0])),
                    (c[0][1] * scale, c[1][1] * scale))
        return linear
    if n1 == 3:
        def quadratic(s, c, scale):
            return ((fused(fused(c[0][2], s, c[0][1]), s, c[0][0]),
                     fused(fused(c[1][2], s, c[1][1]), s, c[1][0]),
                     fused(fused(c[2][2], s, c[2][1]), s, c[2][0])),
                    (fused(2.0 * c[0][2], s, c[0][1]) * scale,
                     fused(2.0 * c[1][2], s, c[1][1]) * scale,
                     fused(2.0 * c[2][2], s, c[2][1]) * scale))
        return quadratic
    if n1 == 4:
        def cubic(s, c, scale):
            return ((fused(fused(fused(c[0][3], s, c[0][2]), s, c[0][1]), s, c[0][0]),
                     fused(fused(fused(c[1][3], s, c[1][2]), s, c[1][1]), s, c[1][0]),
                     fused(fused(fused(c[2][3], s, c[2][2]), s, c[2][1]), s, c[2][0]),
                     fused(fused(fused(c[3][3], s, c[3][2]), s, c[3][1]), s, c[3][0])),
                    (fused(fused(3.0 * c[0][3], s, 2.0 * c[0][2]), s, c[0][1]) * scale,
                     fused(fused(3.0 * c[1][3], s, 2.0 * c[1][2]), s, c[1][1]) * scale,
                     fused(fused(3.0 * c[2][3], s, 2.0 * c[2][2]), s, c[2][1]) * scale,
                     fused(fused(3.0 * c[3][3], s, 2.0 * c[3][2]), s, c[3][1]) * scale))
        return cubic
    return None


def cell_factors(s, cell, first, last, uniform, factors, table, marker, scale):  # pragma: no cover
    """:func:`factors_1d` at ``s`` in ``cell`` along one axis: with the run's ``uniform``
    table in ``first..last``, its own table elsewhere; for :data:`LINEAR` factors,
    ``(1 - s, s)`` and ``(-scale, scale)`` outright."""
    raise NotImplementedError("only callable from compiled code")


@overload(cell_factors, inline="always")
def _cell_factors(s, cell, first, last, uniform, factors, table, marker, scale):
    if isinstance(marker.types[0], numba.types.Boolean):
        # the tables' Horner form c01 s + c00 with c = (1, -1), (0, 1) is 1 - s and s exactly
        # (bit for bit), in one subtraction instead of two products and additions
        def linear(s, cell, first, last, uniform, factors, table, marker, scale):
            return (1.0 - s, s), (-scale, scale)
        return linear

    def tables(s, cell, first, last, uniform, factors, table, marker, scale):
        if first <= cell <= last:  # (two returns: a conditional expression of inlined overloads upsets numba's SSA)
            return factors_1d(s, uniform, scale)
        return factors_1d(s, load_table(factors, table[cell], marker), scale)
    return tables


def squares(f):  # pragma: no cover - replaced by the overload in numba
    """``(f_i^2, sum_i f_i^2)`` of a tuple: one direction's part of the HRZ weights of a
    tensor basis, ``W_ij = U_i^2 W_j^2 / (sum U^2 sum W^2)`` (one division per point,
    for both directions: ~1 ns per pass for q2)."""
    raise NotImplementedError("only callable from compiled code")


@overload(squares, inline="always")
def _squares(f):
    n1 = f.count
    if n1 == 2:
        def linear(f):
            a, b = f[0] * f[0], f[1] * f[1]
            return (a, b), a + b
        return linear
    if n1 == 3:
        def quadratic(f):
            a, b, c = f[0] * f[0], f[1] * f[1], f[2] * f[2]
            return (a, b, c), a + b + c
        return quadratic
    if n1 == 4:
        def cubic(f):
            a, b, c, d = f[0] * f[0], f[1] * f[1], f[2] * f[2], f[3] * f[3]
            return (a, b, c, d), a + b + c + d
        return cubic
    return None


def folded_weights(fx, dfx, fy, dfy, fold):  # pragma: no cover - replaced by the overload in numba
    """``(w, wx, wy)``: the ``n1 x n1`` values and gradients of :class:`FoldedTables`' slots, as tuples."""
    raise NotImplementedError("only callable from compiled code")


def _folded_source(n1: int) -> str:
    """Source of :func:`folded_weights` for ``n1`` factors: every slot written out."""
    c = n1 // 2
    lines = ["def folded(fx, dfx, fy, dfy, fold):",
             f"    q = fx[{c}] * fy[{c}]", f"    qx = dfx[{c}] * fy[{c}]", f"    qy = fx[{c}] * dfy[{c}]"]
    slots = [(i, j) for i in range(n1) for j in range(n1)]
    for name, a, b, centre in (("w", "fx", "fy", "q"), ("wx", "dfx", "fy", "qx"), ("wy", "fx", "dfy", "qy")):
        terms = ", ".join(f"fused(fold[{i * n1 + j}], {centre}, {a}[{i}] * {b}[{j}])" for i, j in slots)
        lines.append(f"    {name} = ({terms})")
    lines.append("    return w, wx, wy")
    return "\n".join(lines)


@overload(folded_weights, inline="always")
def _folded_weights(fx, dfx, fy, dfy, fold):
    namespace: dict = {"fused": fused}
    exec(_folded_source(fx.count), namespace)  # noqa: S102 - generated from integers only
    return namespace["folded"]


def point_weights(px, py, constants, marker, factors_x, table_x, factors_y, table_y, topology, form,
                  work):  # pragma: no cover
    """``(nodes, w, wx, wy)`` of a point in the grid (see :func:`located_weights`; P2G tests
    :func:`inside_grid` first): its nodes (:func:`cell_nodes`) and the values and
    gradients of its local functions, for ``form`` = ``(terms, term_weights)``
    (:class:`BasisTables`: into the scratch arrays ``work``) or a fold
    (:class:`FoldedTables`: register tuples in slot order)."""
    raise NotImplementedError("only callable from compiled code")


@overload(point_weights, inline="always")
def _point_weights(px, py, constants, marker, factors_x, table_x, factors_y, table_y, topology, form, work):
    if isinstance(form, numba.types.UniTuple) and isinstance(form.dtype, numba.types.Float):
        def folded(px, py, constants, marker, factors_x, table_x, factors_y, table_y, topology, form, work):
            nodes, fx, dfx, fy, dfy = located_weights(px, py, constants, marker, factors_x, table_x, factors_y,
                                                      table_y, topology)
            w, wx, wy = folded_weights(fx, dfx, fy, dfy, form)
            return nodes, w, wx, wy
        return folded

    def flat(px, py, constants, marker, factors_x, table_x, factors_y, table_y, topology, form, work):
        q, qx, qy, unused, w, wx, wy = work
        nodes = evaluate_point(px, py, constants, marker, factors_x, table_x, factors_y, table_y, topology,
                               form[0], form[1], q, qx, qy, unused, w, wx, wy)
        return nodes, w, wx, wy
    return flat


def point_work(form, factors_x, factors_y, topology):  # pragma: no cover - replaced by the overload in numba
    """The scratch arrays :func:`point_weights` needs for ``form`` (none for a fold)."""
    raise NotImplementedError("only callable from compiled code")


@overload(point_work, inline="always")
def _point_work(form, factors_x, factors_y, topology):
    if isinstance(form, numba.types.UniTuple) and isinstance(form.dtype, numba.types.Float):
        def folded(form, factors_x, factors_y, topology):
            return ()
        return folded

    def flat(form, factors_x, factors_y, topology):
        return scratch(factors_x, factors_y, topology.shape[1])
    return flat


def function_slots(form, marker, topology):  # pragma: no cover - replaced by the overload in numba
    """``(count, skip)``: how many local slots :func:`point_weights` gives and
    which one is no function (the folded centre; -1 for none)."""
    raise NotImplementedError("only callable from compiled code")


@overload(function_slots, inline="always")
def _function_slots(form, marker, topology):
    if isinstance(form, numba.types.UniTuple) and isinstance(form.dtype, numba.types.Float):
        count = len(marker.types) ** 2  # compile-time constants: the loops over slots unroll
        skip = count // 2

        def folded(form, marker, topology):
            return count, skip
        return folded

    def flat(form, marker, topology):
        return topology.shape[1], -1
    return flat


def cell_nodes(topology, ix, iy, n_y, marker):  # pragma: no cover - replaced by the overload in numba
    """The nodes of cell ``(ix, iy)``, indexable by slot: computed from the affine
    numbering (:func:`lattice_numbering`, a tuple) as a tuple, or read as the row of
    a connectivity array (the flat form, any basis)."""
    raise NotImplementedError("only callable from compiled code")


def _numbering_source(n1: int, shared_step: bool) -> str:
    """Source of :func:`cell_nodes` for a numbering of ``n1 x n1`` slots: the cell's
    first node (one per column of slots if their steps along y differ), then one
    addition per slot.  In unsigned arithmetic: numba tests every signed index for
    Python's negative wraparound (a shift, a mask and an addition per node and
    access), and unsigned nodes made the lumped and HRZ steps 5-8% faster at 1e5
    points (q1 41 -> 37.5 ns, q2 HRZ 80-84 -> 74-77, serendipity HRZ 84-88 -> 79.5-82,
    interleaved; bit-identical)."""
    lines = ["def computed(topology, ix, iy, n_y, marker):", "    along_x = np.uint64(ix) * np.uint64(topology[0])",
             "    row = np.uint64(iy)"]
    if shared_step:
        lines.append("    first = along_x + row * np.uint64(topology[1])")
        lines += [f"    column_{i} = first" for i in range(n1)]
    else:
        lines += [f"    column_{i} = along_x + row * np.uint64(topology[{1 + i}])" for i in range(n1)]
    offsets = 2 if shared_step else 1 + n1
    slots = ", ".join(f"column_{s // n1} + np.uint64(topology[{offsets + s}])" for s in range(n1 * n1))
    lines.append(f"    return ({slots},)")
    return "\n".join(lines)


@overload(cell_nodes, inline="always")
def _cell_nodes(topology, ix, iy, n_y, marker):
    if isinstance(topology, numba.types.Array):
        def read(topology, ix, iy, n_y, marker):
            return topology[ix * np.int64(n_y) + iy]
        return read
    namespace: dict = {"np": np}
    n1 = len(marker.types)
    shared_step = len(topology) == 2 + n1 * n1
    exec(_numbering_source(n1, shared_step), namespace)  # noqa: S102 - generated from integers only
    return namespace["computed"]


@compiled(inline="always")
def tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform):
    """What every point of a tensor kernel needs, loaded once before the loop over points
    (locals stay in registers; array reads would be repeated per point, as the
    grid stores might alias them): geometry, cell counts, uniform runs and their tables."""
    return (geometry[0], geometry[1], geometry[2], geometry[3], geometry[4], n_elements[0], n_elements[1],
            uniform[0], uniform[1], uniform[2], uniform[3],
            load_table(factors_x, table_x[uniform[0]], marker), load_table(factors_y, table_y[uniform[2]], marker))


@compiled(inline="always")
def inside_grid(px, py, constants):
    """Whether a point lies in the grid (False for NaN): the test of every point, before
    its weights, in P2G and the shape-function matrices (a test first and a return was
    ~1 ns per point faster than weights at a safe cell and a select)."""
    return px >= constants[0] and px <= constants[2] and py >= constants[1] and py <= constants[3]


@compiled(inline="always")
def located_weights(px, py, constants, marker, factors_x, table_x, factors_y, table_y, topology):
    """Nodes (:func:`cell_nodes`) and the 1D factors ``(fx, dfx, fy, dfy)`` of a point in the grid.

    Located as :meth:`Grid.locate` does (same arithmetic, so the same cell and
    cell coordinates bit for bit).  Every pass calls it directly: P2G after
    :func:`inside_grid` (it stops at the first point outside), the force pass
    and G2P with no test, as P2G has located every point of the step (without
    the test and its selects they are ~1-2 ns per point faster).
    """
    lower_x, lower_y, upper_x, upper_y, scale, n_x, n_y, first_x, last_x, first_y, last_y, uniform_x, uniform_y = constants
    sx = (px - lower_x) * scale
    sy = (py - lower_y) * scale
    ix = min(np.int32(sx), np.int32(n_x - 1))
    iy = min(np.int32(sy), np.int32(n_y - 1))
    fx, dfx = cell_factors(sx - ix, ix, first_x, last_x, uniform_x, factors_x, table_x, marker, scale)
    fy, dfy = cell_factors(sy - iy, iy, first_y, last_y, uniform_y, factors_y, table_y, marker, scale)
    return cell_nodes(topology, ix, iy, n_y, marker), fx, dfx, fy, dfy


@compiled()
def tensor_shape_function_data(x, marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform,
                               numbering, order, values, d_x, d_y, nodes):
    """:func:`shape_function_data` for tensor bases, in the grid's local order."""
    n1 = len(marker)
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        if not inside_grid(x[p, 0], x[p, 1], constants):
            return p
        local, fx, dfx, fy, dfy = located_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x,
                                                  factors_y, table_y, numbering)
        for i in range(n1):
            for j in range(n1):
                k = order[i * n1 + j]
                values[p, k] = fx[i] * fy[j]
                d_x[p, k] = dfx[i] * fy[j]
                d_y[p, k] = fx[i] * dfy[j]
                nodes[p, k] = local[i * n1 + j]
    return -1


def evaluate_shape_functions(tables: BasisTables, x: np.ndarray, values, d_x, d_y, nodes) -> int:
    """Fill ``(n, n_local)`` arrays with ``N, dNdx, dNdy`` and node indices in the
    grid's local order, by the tensor kernel where the basis allows; returns
    the first point outside the grid, or -1."""
    if tables.tensor is not None:
        return tensor_shape_function_data(x, *tables.tensor.arrays(), tables.tensor.order, values, d_x, d_y, nodes)
    return shape_function_data(x, *tables.arrays(), values, d_x, d_y, nodes)
