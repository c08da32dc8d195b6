"""The compiled forms of a grid's shape functions: every basis as a short sum of separated terms.

Each local function of every basis here is a polynomial of degree at most
``d`` in each cell coordinate, and in fact a short sum of products of 1D
polynomials, ``phi_k(xi, eta) = sum_t U_i(t)(xi) W_j(t)(eta)``: one term for
the tensor-product bases (q1, q2, cubic B-splines), two for the corner
functions of serendipity.  :func:`separated_tables` derives that form once per
grid from the basis's own definition (the monomial coefficients that
:class:`~femgrid_mpm.bases.LocalPolynomials` fits to scikit-fem's ``lbasis``,
or the per-cell tables of :class:`~femgrid_mpm.bases.TensorPieces`) by exact
skeleton (cross) decomposition, and checks it reproduces them.  Evaluating a
point (:mod:`.shape`, inside the kernels) is then a few 1D Horner evaluations
and ``3 x n_terms`` products, the same numbers as
:meth:`femgrid_mpm.Grid.shape_functions` to rounding (tested to 1e-12 for
every registered basis).

Beside the separated (flat) form, which serves any basis, the faster forms a
basis has are found here: tensor products (:class:`TensorTables`) and tensor
products plus a share of the centre one (:class:`FoldedTables`), with the
grid's nodes as an affine function of the cell (:func:`lattice_numbering`).
Everything here is Python that runs once per grid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..bases import LocalPolynomials, TensorPieces


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
        :func:`.shape.cell_nodes` reads (the numbering along the lattice, or the connectivity)."""
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
    :mod:`.p2g`, :mod:`.force` and :mod:`.g2p`, shared with the flat
    form).  ``connectivity`` is in slot order (the centre slot holds a
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
#: increasing power), which :func:`.shape.cell_factors` computes without the tables
LINEAR = (True, True)
LINEAR_FACTORS = np.array([[1.0, -1.0], [0.0, 1.0]])


def separated_tables(grid) -> BasisTables:
    """The separated form of ``grid``'s basis (see the module docstring)."""
    d = grid.discretization
    local = d.local_basis
    geometry = np.array([*grid.lower, *grid.upper, 1.0 / d.element_width])
    n_elements = np.array(d.n_elements, dtype=np.int64)
    connectivity = np.ascontiguousarray(d.connectivity, dtype=np.int32)
    if isinstance(local, TensorPieces):
        # per-cell tables (cell, power, function); function k = n1 a + b is X_a(xi) Y_b(eta)
        n1 = local.n1
        factors_x = np.ascontiguousarray(np.swapaxes(local.tables[0], 1, 2))
        factors_y = np.ascontiguousarray(np.swapaxes(local.tables[1], 1, 2))
        table_x = np.arange(d.n_elements[0], dtype=np.int32)
        table_y = np.arange(d.n_elements[1], dtype=np.int32)
        terms = np.array([(n1 * a + b, a, b) for a in range(n1) for b in range(n1)], dtype=np.int32)
        weights = np.ones(len(terms))
        # flat form: the tensor products themselves
        flat = (factors_x, factors_y, np.arange(n1 * n1, dtype=np.int32)[:, None], np.ones((n1 * n1, 1)))
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
        numbering = lattice_numbering(tensor_connectivity, d.n_elements, fx.shape[1])
        # nodes that are no affine function of the cell (pieces finer than the node lattice,
        # as GIMP's): the flat form, which reads them
        tensor = None if numbering is None else TensorTables(
            LINEAR if linear else (0,) * fx.shape[1], geometry, n_elements, fx, table_x, fy, table_y,
            _uniform_runs(fx, table_x, fy, table_y), connectivity=tensor_connectivity, order=order,
            numbering=numbering)
    factors_x, factors_y, terms, weights = flat
    uniform = _uniform_runs(factors_x, table_x, factors_y, table_y)
    folded = None if tensor is not None else _folded_form(factors_x, factors_y, terms, weights, connectivity)
    if folded is not None:
        fold, folded_connectivity, order = folded
        n1 = factors_x.shape[1]
        numbering = lattice_numbering(folded_connectivity, d.n_elements, n1, skip=(n1 * n1) // 2,
                                      per_column=True)
        folded = None if numbering is None else FoldedTables(
            (0,) * n1, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, fold=fold,
            connectivity=folded_connectivity, order=order, numbering=numbering)
    return BasisTables((0,) * factors_x.shape[1], geometry, n_elements, factors_x, table_x, factors_y, table_y,
                       uniform, terms=terms, term_weights=weights, connectivity=connectivity, tensor=tensor,
                       folded=folded)


def lattice_numbering(connectivity: np.ndarray, n_elements, n1: int, skip: int = -1,
                      per_column: bool = False) -> tuple | None:
    """The node of slot ``s = i n1 + j`` of element ``(ix, iy)`` as an affine function,
    ``ix * step_x + iy * steps_y[i] + offsets[s]``: the flat tuple
    ``(step_x, *steps_y, *offsets)``, ``steps_y`` a single step if every column
    has the same (so the tuple's length tells which); None if the nodes are no
    affine function of the element (elements finer than the node lattice).

    The grid numbers its nodes along the lattice (x index, then y index), so
    moving one element along x adds the same number to every node, and
    moving along y adds the same number to the nodes of one column of slots
    (serendipity's middle column has half as many nodes as the others).  The
    kernels compute a point's nodes from its cell instead of reading them:
    ~5-8% of a step (q1 2.4 of 12.4 ns per point in P2G, cubic splines 3.5
    of 62 in the force pass).  ``skip``: a slot that is no function (the
    folded centre), left out of the check.  ``per_column``: the columns' steps differ on
    every grid more than one element tall (serendipity's folded slots), so they are kept
    per column on a grid one element tall too, where all are 0: the kernels specialise on
    the tuple's length, and the paper's one-element bar compiled serendipity's passes a
    second time (~20 CPU s).

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
        return None
    # one step for all columns when they share it (every basis but serendipity): one product per point
    steps = steps_y[:1] if len(set(steps_y)) == 1 and not per_column else steps_y
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
