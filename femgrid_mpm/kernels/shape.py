"""A point's shape functions inside the kernels, from the tables of :mod:`.tables`.

Everything here is inlined into the passes (:mod:`.p2g`, :mod:`.force`,
:mod:`.g2p`): numba overloads, written out for the number ``n1`` of 1D
factors per direction (``len(marker)``, a compile-time constant, so every
loop over the ``n1 x n1`` slots is unrolled), inlined in numba's IR
(``inline="always"``), and helpers compiled once for their types and inlined
by LLVM (``forceinline=True``: numba's IR inlining types a helper again at
every call; a cold serendipity bar with lumped mass compiled in 17.5-18.5
CPU s that way, in 9.1-10.6 s this way, docs/performance.md).

A point is located exactly as :meth:`femgrid_mpm.Grid.locate` does (same
arithmetic, so the same element and cell coordinates bit for bit).
:func:`located_weights` gives its nodes (:func:`cell_nodes`) and its 1D
factors along x and y, which the tensor kernels combine by sum
factorization; :func:`point_weights` the values and gradients of its local
functions one by one, for the flat and folded forms (the ``local_*``
kernels).
"""

from __future__ import annotations

import numba
from numba.extending import overload
import numpy as np

from .arithmetic import fused
from .compiled import compiled


# -- a point's cell, its 1D factors and its nodes: loops over n1 x n1 slots unrolled at compile time ---------


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
    n1 = len(c)  # the numba tuple type: its number of elements
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
    table in ``first..last``, its own table elsewhere; for :data:`.tables.LINEAR` factors,
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


def cell_nodes(topology, ix, iy, n_y, marker):  # pragma: no cover - replaced by the overload in numba
    """The nodes of cell ``(ix, iy)``, indexable by slot: computed from the affine
    numbering (:func:`.tables.lattice_numbering`, a tuple) as a tuple, or read as the row of
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


@compiled(forceinline=True)
def tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform):
    """What every point of a tensor kernel needs, loaded once before the loop over points
    (locals stay in registers; array reads would be repeated per point, as the
    grid stores might alias them): geometry, cell counts, uniform runs and their tables."""
    return (geometry[0], geometry[1], geometry[2], geometry[3], geometry[4], n_elements[0], n_elements[1],
            uniform[0], uniform[1], uniform[2], uniform[3],
            load_table(factors_x, table_x[uniform[0]], marker), load_table(factors_y, table_y[uniform[2]], marker))


@compiled(forceinline=True)
def inside_grid(px, py, constants):
    """Whether a point lies in the grid (False for NaN): the test of every point, before
    its weights, in P2G and the shape-function matrices (a test first and a return was
    ~1 ns per point faster than weights at a safe cell and a select)."""
    return px >= constants[0] and px <= constants[2] and py >= constants[1] and py <= constants[3]


@compiled(forceinline=True)
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


# -- function by function: the flat (tables) and folded (serendipity) forms -------------------------------


@compiled(forceinline=True)
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


def folded_weights(fx, dfx, fy, dfy, fold):  # pragma: no cover - replaced by the overload in numba
    """``(w, wx, wy)``: the ``n1 x n1`` values and gradients of :class:`.tables.FoldedTables`' slots, as tuples."""
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
    (:class:`.tables.BasisTables`: into the scratch arrays ``work``) or a fold
    (:class:`.tables.FoldedTables`: register tuples in slot order)."""
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
