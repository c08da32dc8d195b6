"""P2G, the first pass of a step: mass and momentum (and the consistent mass matrix) onto the grid.

``m_I = N.T @ m_p``, ``|N|.T @ m_p`` (signed bases), ``N.T @ V_p``
(consistent mass), ``N.T @ (m_p (v_p - v_ref))`` and, for consistent mass,
``M = N.T diag(m_p) N`` into a stencil matrix (the fixed pattern of
:mod:`.pattern`); ``*_p2g_sums`` without the matrix.

With ``hrz`` (``mass = "hrz"``, :class:`femgrid_mpm.mass.HrzMass`) the
point's HRZ weights ``W = N^2 / sum N^2`` carry the momentum (as they carry
the velocity increment in :mod:`.g2p`), and P2G sums the HRZ diagonal
``W.T @ m_p`` into ``grid_absolute`` (the row sums ``N.T @ m_p`` still go to
``grid_mass``).  For a tensor basis the weights are themselves products,
``W_ij = (U_i^2 / sum U^2) (W_j^2 / sum W^2)``.

P2G tests every point against the grid and stops at the first one outside
(its index is returned, -1 if none): the later passes of the step locate
the points with no test.
"""

from __future__ import annotations

import numpy as np

from .arithmetic import fused, quotient
from .compiled import compiled
from .shape import function_slots, inside_grid, located_weights, point_weights, point_work, squares, tensor_constants


@compiled(forceinline=True)
def _clear_sums(absolute, want_volume, assemble, grid_mass, momentum, grid_absolute, grid_volume, matrix):
    """Zero what a P2G pass sums into: mass, momentum and what it is asked for."""
    grid_mass[:] = 0.0
    momentum[:] = 0.0
    if absolute:
        grid_absolute[:] = 0.0
    if want_volume:
        grid_volume[:] = 0.0
    if assemble:
        matrix[:] = 0.0


@compiled(forceinline=True)
def _mirror(matrix, mirror_target, mirror_source):
    """The assembled mass matrix's lower half (stencil order) from its upper half."""
    for t in range(mirror_target.shape[0]):
        matrix[mirror_target[t]] = matrix[mirror_source[t]]


@compiled(forceinline=True)
def _no_pattern():
    """Stand-ins for the mass pattern's arrays when no matrix is assembled (never read, so
    left uninitialized: numba's ``np.zeros`` compiles in twice the time of ``np.empty``,
    0.8 against 0.4 CPU s of a first run's 6-7, ``benchmarks/compile_time.py --kernels``)."""
    return np.empty(2, np.int32), np.empty((1, 1), np.int32), np.empty(1, np.bool_), np.empty(0, np.int32), np.empty(1)


# -- any basis, function by function: the flat and folded forms (see :mod:`.families`) ---------------------


@compiled()
def local_p2g(x, v, mass_p, density_p, v_ref, signed, want_volume, assemble, hrz,
              marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, form, topology,
              grid_mass, grid_absolute, grid_volume, momentum, indptr, rank, complete, slots, centre,
              ordered, mirror_target, mirror_source, matrix):
    """Scatter mass, relative momentum (and the mass matrix, into the fixed
    pattern of :mod:`.pattern`: the products of slot >= ``centre``, then the
    rest copied from their transposes) to the grid.

    Returns the first point outside the grid, or -1.
    """
    count, skip = function_slots(form, marker, topology)
    work = point_work(form, factors_x, factors_y, topology)
    _clear_sums(signed or hrz, want_volume, assemble, grid_mass, momentum, grid_absolute, grid_volume, matrix)
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        if not inside_grid(x[p, 0], x[p, 1], constants):
            return p
        nodes, w, wx, wy = point_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y,
                                         table_y, topology, form, work)
        m = mass_p[p]
        px = m * (v[p, 0] - v_ref[0])
        py = m * (v[p, 1] - v_ref[1])
        # one loop per kind of sum (the branches outside the unrolled loops)
        if hrz:  # W = N^2 / sum N^2 carries the momentum; its column sums are the diagonal mass
            squares = 0.0
            for k in range(count):
                if k != skip:
                    squares += w[k] * w[k]
            inverse = 1.0 / squares  # into the point's mass and momentum: one product a point, not a node
            m_w = m * inverse
            px_w = px * inverse
            py_w = py * inverse
            for k in range(count):
                if k != skip:
                    node = nodes[k]
                    square = w[k] * w[k]
                    grid_mass[node] = fused(w[k], m, grid_mass[node])
                    grid_absolute[node] = fused(square, m_w, grid_absolute[node])
                    momentum[node, 0] = fused(square, px_w, momentum[node, 0])
                    momentum[node, 1] = fused(square, py_w, momentum[node, 1])
        elif signed:  # also |N|.T @ m_p
            for k in range(count):
                if k != skip:
                    node = nodes[k]
                    grid_mass[node] = fused(w[k], m, grid_mass[node])
                    grid_absolute[node] = fused(abs(w[k]), m, grid_absolute[node])
                    momentum[node, 0] = fused(w[k], px, momentum[node, 0])
                    momentum[node, 1] = fused(w[k], py, momentum[node, 1])
        else:
            for k in range(count):
                if k != skip:
                    node = nodes[k]
                    grid_mass[node] = fused(w[k], m, grid_mass[node])
                    momentum[node, 0] = fused(w[k], px, momentum[node, 0])
                    momentum[node, 1] = fused(w[k], py, momentum[node, 1])
        if want_volume:
            volume = quotient(m, density_p[p])
            for k in range(count):
                if k != skip:
                    node = nodes[k]
                    grid_volume[node] = fused(w[k], volume, grid_volume[node])
        if assemble:  # the upper half in stencil order; the rest is mirrored after the pass
            for k in range(count):
                if k != skip:
                    node = nodes[k]
                    weighted = w[k] * m
                    start = indptr[node]
                    full = complete[node]
                    for j in range(count):
                        slot = slots[k, j]
                        if j != skip and slot >= centre:
                            entry = np.uint64(start + (slot if full else rank[node, slot]))  # unsigned: no wraparound test
                            matrix[entry] = fused(weighted, w[j], matrix[entry])
    if assemble:
        _mirror(matrix, mirror_target, mirror_source)
    return -1


@compiled()
def local_p2g_sums(x, v, mass_p, density_p, v_ref, signed, want_volume, hrz,
                   marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, form, topology,
                   grid_mass, grid_absolute, grid_volume, momentum):
    """:func:`local_p2g` with no mass matrix (see :func:`tensor_p2g_sums`)."""
    index, table, flags, mirror, matrix = _no_pattern()
    return local_p2g(x, v, mass_p, density_p, v_ref, signed, want_volume, False, hrz, marker, geometry, n_elements,
                     factors_x, table_x, factors_y, table_y, uniform, form, topology, grid_mass, grid_absolute,
                     grid_volume, momentum, index, table, flags, table, 0, False, mirror, mirror, matrix)


# -- tensor-product bases: sum factorization over the n1 x n1 nodes (see :mod:`.families`) -----------------


@compiled()
def tensor_p2g(x, v, mass_p, density_p, v_ref, signed, want_volume, assemble, hrz,
               marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, topology,
               grid_mass, grid_absolute, grid_volume, momentum, indptr, rank, complete, slots, centre,
               ordered, mirror_target, mirror_source, matrix):
    """:func:`local_p2g` for tensor-product bases (``slots`` in tensor order).

    ``ordered``: the 1D factors are in the order of their nodes along the
    axis (q1, cubic splines; not q2, whose middle node comes last), checked
    by the engine.  Then the slot of ``b = (k, l)`` seen from ``a = (i, j)``
    is at least ``centre`` exactly when ``(k, l) >= (i, j)``
    lexicographically (a test on the indices of fully unrolled loops, so
    decided at compile time: a loop from ``k = i`` instead was 25% slower),
    and in a complete row the slots of ``l = 0 .. n1 - 1`` are consecutive.
    """
    n1 = len(marker)
    _clear_sums(signed or hrz, want_volume, assemble, grid_mass, momentum, grid_absolute, grid_volume, matrix)
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        if not inside_grid(x[p, 0], x[p, 1], constants):
            return p
        nodes, fx, dfx, fy, dfy = located_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y,
                                                  table_y, topology)
        m = mass_p[p]
        px = m * (v[p, 0] - v_ref[0])
        py = m * (v[p, 1] - v_ref[1])
        if hrz:  # W_ij = U_i^2 W_j^2 / (sum U^2 sum W^2) carries the momentum; its column sums are the diagonal mass
            gx, sum_x = squares(fx)
            gy, sum_y = squares(fy)
            inverse = 1.0 / (sum_x * sum_y)  # one division a point, into the point's factors
            m_w = m * inverse
            px_w = px * inverse
            py_w = py * inverse
            for i in range(n1):
                m_i = fx[i] * m
                d_i = gx[i] * m_w
                px_i = gx[i] * px_w
                py_i = gx[i] * py_w
                for j in range(n1):
                    node = nodes[i * n1 + j]
                    grid_mass[node] = fused(m_i, fy[j], grid_mass[node])
                    grid_absolute[node] = fused(d_i, gy[j], grid_absolute[node])
                    momentum[node, 0] = fused(px_i, gy[j], momentum[node, 0])
                    momentum[node, 1] = fused(py_i, gy[j], momentum[node, 1])
        elif signed:  # also |N|.T @ m_p
            for i in range(n1):
                m_i = fx[i] * m
                a_i = abs(fx[i]) * m
                px_i = fx[i] * px
                py_i = fx[i] * py
                for j in range(n1):
                    node = nodes[i * n1 + j]
                    grid_mass[node] = fused(m_i, fy[j], grid_mass[node])
                    grid_absolute[node] = fused(a_i, abs(fy[j]), grid_absolute[node])
                    momentum[node, 0] = fused(px_i, fy[j], momentum[node, 0])
                    momentum[node, 1] = fused(py_i, fy[j], momentum[node, 1])
        else:
            for i in range(n1):
                m_i = fx[i] * m
                px_i = fx[i] * px
                py_i = fx[i] * py
                for j in range(n1):
                    node = nodes[i * n1 + j]
                    grid_mass[node] = fused(m_i, fy[j], grid_mass[node])
                    momentum[node, 0] = fused(px_i, fy[j], momentum[node, 0])
                    momentum[node, 1] = fused(py_i, fy[j], momentum[node, 1])
        if want_volume:
            volume = quotient(m, density_p[p])
            for i in range(n1):
                v_i = fx[i] * volume
                for j in range(n1):
                    node = nodes[i * n1 + j]
                    grid_volume[node] = fused(v_i, fy[j], grid_volume[node])
        if assemble:  # the upper half, (k, l) >= (i, j); the rest is mirrored after the pass
            for i in range(n1):
                for j in range(n1):
                    a = i * n1 + j
                    node = nodes[a]
                    start = indptr[node]
                    m_a = fx[i] * fy[j] * m
                    full = complete[node]
                    if ordered and full:
                        for k in range(n1):
                            m_ak = m_a * fx[k]
                            first = np.uint64(start + slots[a, k * n1])
                            for l in range(n1):
                                if k > i or (k == i and l >= j):
                                    matrix[first + np.uint64(l)] = fused(m_ak, fy[l], matrix[first + np.uint64(l)])
                    else:
                        for k in range(n1):
                            m_ak = m_a * fx[k]
                            for l in range(n1):
                                slot = slots[a, k * n1 + l]
                                if slot >= centre:
                                    entry = np.uint64(start + (slot if full else rank[node, slot]))  # unsigned: no wraparound test
                                    matrix[entry] = fused(m_ak, fy[l], matrix[entry])
    if assemble:
        _mirror(matrix, mirror_target, mirror_source)
    return -1


@compiled()
def tensor_p2g_sums(x, v, mass_p, density_p, v_ref, signed, want_volume, hrz,
                    marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, topology,
                    grid_mass, grid_absolute, grid_volume, momentum):
    """:func:`tensor_p2g` with no mass matrix (lumped and HRZ mass): the pattern's nine
    arguments are not passed from Python, where unboxing them cost ~0.7 us a step."""
    index, table, flags, mirror, matrix = _no_pattern()
    return tensor_p2g(x, v, mass_p, density_p, v_ref, signed, want_volume, False, hrz, marker, geometry, n_elements,
                      factors_x, table_x, factors_y, table_y, uniform, topology, grid_mass, grid_absolute,
                      grid_volume, momentum, index, table, flags, table, 0, False, mirror, mirror, matrix)
