"""Compiled particle <-> grid transfers: the three passes over the points of one step.

Each kernel evaluates the shape functions of a point afresh (see
:mod:`.basis`) instead of reading stored matrices: at 1e5 points the
matrices of cubic B-splines are ~45 MB, and streaming them through memory
three times a step costs more than recomputing them.  The kernels mirror the
scipy expressions of :class:`~femgrid_mpm.kernels.engines.ScipyTransfer`
term by term (same frame of reference, same order of operations where it
matters), so the two engines agree to rounding.

``p2g``
    ``m_I = N.T @ m_p``, ``|N|.T @ m_p`` (signed bases), ``N.T @ V_p``
    (consistent mass), ``N.T @ (m_p (v_p - v_ref))`` and, for consistent
    mass, ``M = N.T diag(m_p) N`` into a stencil matrix.
``velocity_gradient`` / ``internal_force`` / ``linear_elastic_stress_and_force``
    ``dt L_p = dt sum_I v_I (grad N_I)^T`` (Eq. 18), the strain increment and
    ``f_I = -sum_p V_p sigma_p grad N_I`` (Eq. 11); the last one fused with
    the linear elastic stress update (Eq. 6) in one pass.
``g2p``
    ``v_p += dt N @ a``, ``x_p += dt (N @ v_rel + v_ref)``, ``rho_p *= exp(-dt div v)``
    (Eqs. 19-21).  ``N @ v_rel`` and ``div v`` (of the grid velocity at the
    step's start) are interpolated in the force pass, whose gathers of
    ``v_rel`` already hold the inner sums, and handed over per point in
    ``start_motion`` (n, 3): G2P gathers the acceleration only.

With ``hrz`` (``mass = "hrz"``, :class:`femgrid_mpm.mass.HrzMass`) the
point's HRZ weights ``W = N^2 / sum N^2`` carry the momentum in P2G and the
velocity increment in G2P, and P2G sums the HRZ diagonal ``W.T @ m_p`` into
``grid_absolute`` (the row sums ``N.T @ m_p`` still go to ``grid_mass``).
For a tensor basis the weights are themselves products,
``W_ij = (U_i^2 / sum U^2) (W_j^2 / sum W^2)``.

Every kernel is serial (``parallel`` variants are separate functions), uses
``fastmath=False``, its accumulations fused multiply-adds by name
(:func:`.arithmetic.fused`), and is cached on disk (:func:`.compiled.compiled`).
The point volumes ``m / rho`` are :func:`.arithmetic.quotient` (IEEE 754, no
Python test for a zero divisor: a zero density stops the run by the step's
finiteness check instead of a ZeroDivisionError out of a kernel).
"""

from __future__ import annotations

import math

import numpy as np

from .arithmetic import fused, quotient
from .compiled import compiled
from .basis import (function_slots, inside_grid, located_weights, point_weights, point_work, squares,
                    tensor_constants)


@compiled(inline="always")
def _relative_velocity(velocity, v_ref, relative):
    """``v_I - v_ref``: the grid velocity in the step's frame (after the constraints)."""
    for i in range(velocity.shape[0]):
        relative[i, 0] = velocity[i, 0] - v_ref[0]
        relative[i, 1] = velocity[i, 1] - v_ref[1]


@compiled(inline="always")
def _hand_over(p, divergence, ux, uy, start_motion):
    """What the force pass knows of point p's motion at the step's start and G2P
    needs (:func:`_move_point`): ``div v`` and ``N @ v_rel``, whose inner sums
    the gradient's gather already holds."""
    start_motion[p, 0] = divergence
    start_motion[p, 1] = ux
    start_motion[p, 2] = uy


@compiled(inline="always")
def _linear_elastic_point(p, dt, dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy, lame, body, strain, stress, start_motion):
    """Paper Eqs. 18 and 6 for point ``p``: strain increment from its velocity
    gradient, the incremental linear elastic stress; ``div v`` and the
    interpolated relative velocity ``(ux, uy)`` for G2P (:func:`_hand_over`).
    Returns the new stress (xx, yy, xy)."""
    e_xx = dt * dvx_dx
    e_yy = dt * dvy_dy
    e_xy = dt * (0.5 * (dvx_dy + dvy_dx))
    strain[p, 0] += e_xx
    strain[p, 1] += e_yy
    strain[p, 2] += e_xy
    material = np.uint64(body[p])  # unsigned: no wraparound test
    lam = lame[material, 0]
    two_mu = lame[material, 1]
    volumetric = e_xx + e_yy
    s_xx = stress[p, 0] + (lam * volumetric + two_mu * e_xx)
    s_yy = stress[p, 1] + (lam * volumetric + two_mu * e_yy)
    s_xy = stress[p, 2] + two_mu * e_xy
    stress[p, 0] = s_xx
    stress[p, 1] = s_yy
    stress[p, 2] = s_xy
    _hand_over(p, dvx_dx + dvy_dy, ux, uy, start_motion)
    return s_xx, s_yy, s_xy


@compiled(inline="always")
def _mirror(matrix, mirror_target, mirror_source):
    """The assembled mass matrix's lower half (stencil order) from its upper half."""
    for t in range(mirror_target.shape[0]):
        matrix[mirror_target[t]] = matrix[mirror_source[t]]


@compiled(inline="always")
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


@compiled(inline="always")
def _record_gradient(p, dt, dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy, strain, strain_increment, gradient_increment,
                     start_motion):
    """Eq. 18 for any material: point p's strain increment (added to its strain)
    and ``dt L``; ``div v`` and ``(ux, uy)`` for G2P (:func:`_hand_over`)."""
    strain_increment[p, 0] = dt * dvx_dx
    strain_increment[p, 1] = dt * dvy_dy
    strain_increment[p, 2] = dt * (0.5 * (dvx_dy + dvy_dx))
    for c in range(3):
        strain[p, c] += strain_increment[p, c]
    gradient_increment[p, 0] = dt * dvx_dx
    gradient_increment[p, 1] = dt * dvx_dy
    gradient_increment[p, 2] = dt * dvy_dx
    gradient_increment[p, 3] = dt * dvy_dy
    _hand_over(p, dvx_dx + dvy_dy, ux, uy, start_motion)


#: below this ``|a|`` :func:`density_factor` sums the series (the next term, a^7 / 7!, is 3.5e-19 of 1)
SERIES_BOUND = 2.0**-7


@compiled(inline="always")
def density_factor(a):
    """``exp(a)`` for Eq. 21's ``a = -dt div v``, within 1 ulp of ``math.exp``.

    ``|a|`` is almost always far below 1e-2 (a volumetric strain increment), where
    the Taylor series to a^6 is exact to rounding: six products and additions
    inline, against a call to libm's ``exp`` (~5 ns per point, most of it the
    call itself; 2.2 ns of q1's G2P at 1e5 points).  Larger, infinite or NaN
    arguments go to ``math.exp``.  Compared with ``math.exp`` on 2e6 arguments
    per magnitude (``tests/test_kernels.py``): equal below 1e-8, at most 1 ulp
    apart (0.2% of them) up to the bound.
    """
    if abs(a) <= SERIES_BOUND:
        return 1.0 + a * (1.0 + a * (0.5 + a * (1.0 / 6.0 + a * (1.0 / 24.0 + a * (1.0 / 120.0 + a * (1.0 / 720.0))))))
    return math.exp(a)


@compiled(inline="always")
def _move_point(p, dt, ax, ay, v_ref, v, x, density_p, start_motion):
    """Eqs. 19-21 for point p from its interpolated acceleration (ax, ay) and what
    the force pass interpolated (``start_motion[p]``: ``div v`` and the relative
    grid velocity ``N @ v_rel``).  Returns ``v_x + v_y + x + y``."""
    v[p, 0] = fused(dt, ax, v[p, 0])
    v[p, 1] = fused(dt, ay, v[p, 1])
    x[p, 0] = fused(dt, start_motion[p, 1] + v_ref[0], x[p, 0])
    x[p, 1] = fused(dt, start_motion[p, 2] + v_ref[1], x[p, 1])
    density_p[p] *= density_factor(-dt * start_motion[p, 0])
    return v[p, 0] + v[p, 1] + x[p, 0] + x[p, 1]


# -- any basis, function by function: the flat (tables) and folded (serendipity) forms -----------------
#
# ``point_weights`` gives a point's nodes and the values and gradients of
# its local functions (scratch arrays for the flat form, register tuples for
# the folded one); ``function_slots`` their count and the slot that is no
# function (the folded form's centre; -1 for none).  Each kernel is compiled
# once per form.


@compiled(inline="always")
def _local_gradient(nodes, count, skip, relative, w, wx, wy):
    """``dNdx @ v_rel``, ``dNdy @ v_rel`` and ``N @ v_rel`` at one point:
    (d vx/dx, d vy/dx, d vx/dy, d vy/dy, vx, vy)."""
    dvx_dx = 0.0
    dvy_dx = 0.0
    dvx_dy = 0.0
    dvy_dy = 0.0
    ux = 0.0
    uy = 0.0
    for k in range(count):
        if k == skip:
            continue
        node = nodes[k]
        rx = relative[node, 0]
        ry = relative[node, 1]
        dvx_dx = fused(wx[k], rx, dvx_dx)
        dvy_dx = fused(wx[k], ry, dvy_dx)
        dvx_dy = fused(wy[k], rx, dvx_dy)
        dvy_dy = fused(wy[k], ry, dvy_dy)
        ux = fused(w[k], rx, ux)
        uy = fused(w[k], ry, uy)
    return dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy


@compiled(inline="always")
def _local_force(nodes, count, skip, wx, wy, w_xx, w_yy, w_xy, force):
    """One point's share of Eq. 11, ``-V sigma grad N``, scattered to its nodes."""
    for k in range(count):
        if k == skip:
            continue
        node = nodes[k]
        force[node, 0] = fused(-wx[k], w_xx, fused(-wy[k], w_xy, force[node, 0]))
        force[node, 1] = fused(-wx[k], w_xy, fused(-wy[k], w_yy, force[node, 1]))


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
def local_linear_elastic_stress_and_force(x, velocity, v_ref, relative, dt, mass_p, density_p, body, lame,
                                          marker, geometry, n_elements, factors_x, table_x, factors_y, table_y,
                                          uniform, form, topology, strain, stress, force, start_motion):
    """Eqs. 18, 6 and 11 in one pass, for bodies of :class:`LinearElastic` material.

    ``lame[b] = (lambda, 2 mu)`` of body b.  Returns the sum of the new
    stresses (for the finiteness check).
    """
    _relative_velocity(velocity, v_ref, relative)
    count, skip = function_slots(form, marker, topology)
    work = point_work(form, factors_x, factors_y, topology)
    force[:] = 0.0
    total = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        nodes, w, wx, wy = point_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y,
                                         table_y, topology, form, work)
        dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy = _local_gradient(nodes, count, skip, relative, w, wx, wy)
        s_xx, s_yy, s_xy = _linear_elastic_point(p, dt, dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy, lame, body, strain, stress,
                                                 start_motion)
        total += s_xx + s_yy + s_xy
        volume = quotient(mass_p[p], density_p[p])
        _local_force(nodes, count, skip, wx, wy, volume * s_xx, volume * s_yy, volume * s_xy, force)
    return total


@compiled()
def local_velocity_gradient(x, velocity, v_ref, relative, dt,
                            marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, form,
                            topology, strain, strain_increment, gradient_increment, start_motion):
    """Eq. 18 for any material: the strain increment (added to ``strain``) and ``dt L``."""
    _relative_velocity(velocity, v_ref, relative)
    count, skip = function_slots(form, marker, topology)
    work = point_work(form, factors_x, factors_y, topology)
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        nodes, w, wx, wy = point_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y,
                                         table_y, topology, form, work)
        dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy = _local_gradient(nodes, count, skip, relative, w, wx, wy)
        _record_gradient(p, dt, dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy, strain, strain_increment, gradient_increment, start_motion)


@compiled()
def local_internal_force(x, mass_p, density_p, stress,
                         marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, form,
                         topology, force):
    """Eq. 11: ``f_I = -sum_p V_p sigma_p grad N_I`` with the volumes of time t."""
    count, skip = function_slots(form, marker, topology)
    work = point_work(form, factors_x, factors_y, topology)
    force[:] = 0.0
    total = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        nodes, w, wx, wy = point_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y,
                                         table_y, topology, form, work)
        volume = quotient(mass_p[p], density_p[p])
        total += stress[p, 0] + stress[p, 1] + stress[p, 2]
        _local_force(nodes, count, skip, wx, wy, volume * stress[p, 0], volume * stress[p, 1],
                     volume * stress[p, 2], force)
    return total


@compiled()
def local_g2p(x, v, density_p, acceleration, v_ref, dt, start_motion, hrz,
              marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, form, topology):
    """Eqs. 19-21: point velocity from the grid acceleration, position from the
    grid velocity of the step's start and density from its divergence (both
    interpolated in the force pass: ``start_motion``).  Returns ``sum(v) + sum(x)``."""
    count, skip = function_slots(form, marker, topology)
    work = point_work(form, factors_x, factors_y, topology)
    total = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        nodes, w, wx, wy = point_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y,
                                         table_y, topology, form, work)
        ax = 0.0
        ay = 0.0
        if hrz:  # the HRZ weights carry the velocity increment
            squares = 0.0
            for k in range(count):
                if k != skip:
                    squares += w[k] * w[k]
            for k in range(count):
                if k != skip:
                    node = nodes[k]
                    square = w[k] * w[k]
                    ax = fused(square, acceleration[node, 0], ax)
                    ay = fused(square, acceleration[node, 1], ay)
            inverse = 1.0 / squares  # after the sums: one product a point, not a node
            ax *= inverse
            ay *= inverse
        else:
            for k in range(count):
                if k != skip:
                    node = nodes[k]
                    ax = fused(w[k], acceleration[node, 0], ax)
                    ay = fused(w[k], acceleration[node, 1], ay)
        total += _move_point(p, dt, ax, ay, v_ref, v, x, density_p, start_motion)
    return total


# -- tensor-product bases: sum factorization over the n1 x n1 nodes ----------------------------------------
#
# With phi_(i,j) = U_i(xi) W_j(eta), a gather sum_ij phi_ij g_ij is
# sum_i U_i (sum_j W_j g_ij) and its x-derivative reuses the inner sums;
# a scatter multiplies per-i factors by W_j.  ``len(marker)`` (n1) is a
# compile-time constant, so every loop over nodes is unrolled.  A point's
# nodes are computed from its cell (``topology`` is the grid's numbering
# along the lattice, see :func:`.basis.lattice_numbering`), not read.


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


@compiled(inline="always")
def _no_pattern():
    """Stand-ins for the mass pattern's arrays when no matrix is assembled (never read)."""
    return np.zeros(2, np.int32), np.zeros((1, 1), np.int32), np.zeros(1, np.bool_), np.zeros(0, np.int32), np.zeros(1)


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


@compiled()
def local_p2g_sums(x, v, mass_p, density_p, v_ref, signed, want_volume, hrz,
                   marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, form, topology,
                   grid_mass, grid_absolute, grid_volume, momentum):
    """:func:`local_p2g` with no mass matrix (see :func:`tensor_p2g_sums`)."""
    index, table, flags, mirror, matrix = _no_pattern()
    return local_p2g(x, v, mass_p, density_p, v_ref, signed, want_volume, False, hrz, marker, geometry, n_elements,
                     factors_x, table_x, factors_y, table_y, uniform, form, topology, grid_mass, grid_absolute,
                     grid_volume, momentum, index, table, flags, table, 0, False, mirror, mirror, matrix)


@compiled(inline="always")
def _tensor_gradient(nodes, fx, dfx, fy, dfy, n1, relative):
    """``dNdx @ v_rel``, ``dNdy @ v_rel`` and ``N @ v_rel`` of one point:
    (dvx/dx, dvy/dx, dvx/dy, dvy/dy, vx, vy); the last two reuse the inner sums."""
    dvx_dx = 0.0
    dvy_dx = 0.0
    dvx_dy = 0.0
    dvy_dy = 0.0
    ux = 0.0
    uy = 0.0
    for i in range(n1):
        ax = 0.0
        ay = 0.0
        bx = 0.0
        by = 0.0
        for j in range(n1):
            node = nodes[i * n1 + j]
            rx = relative[node, 0]
            ry = relative[node, 1]
            ax = fused(fy[j], rx, ax)
            ay = fused(fy[j], ry, ay)
            bx = fused(dfy[j], rx, bx)
            by = fused(dfy[j], ry, by)
        dvx_dx = fused(dfx[i], ax, dvx_dx)
        dvy_dx = fused(dfx[i], ay, dvy_dx)
        dvx_dy = fused(fx[i], bx, dvx_dy)
        dvy_dy = fused(fx[i], by, dvy_dy)
        ux = fused(fx[i], ax, ux)
        uy = fused(fx[i], ay, uy)
    return dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy


@compiled(inline="always")
def _tensor_force(nodes, fx, dfx, fy, dfy, n1, w_xx, w_yy, w_xy, force):
    """Scatter ``-(dNdx (V s_xx, V s_xy) + dNdy (V s_xy, V s_yy))`` of one point."""
    for i in range(n1):
        c_xx = -dfx[i] * w_xx
        c_xy = -fx[i] * w_xy
        d_xy = -dfx[i] * w_xy
        d_yy = -fx[i] * w_yy
        for j in range(n1):
            node = nodes[i * n1 + j]
            force[node, 0] = fused(fy[j], c_xx, fused(dfy[j], c_xy, force[node, 0]))
            force[node, 1] = fused(fy[j], d_xy, fused(dfy[j], d_yy, force[node, 1]))


@compiled()
def tensor_linear_elastic_stress_and_force(x, velocity, v_ref, relative, dt, mass_p, density_p, body, lame,
                                           marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform,
                                           topology, strain, stress, force, start_motion):
    """:func:`local_linear_elastic_stress_and_force` for tensor-product bases."""
    _relative_velocity(velocity, v_ref, relative)
    n1 = len(marker)
    force[:] = 0.0
    total = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        nodes, fx, dfx, fy, dfy = located_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y,
                                                  table_y, topology)
        dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy = _tensor_gradient(nodes, fx, dfx, fy, dfy, n1, relative)
        s_xx, s_yy, s_xy = _linear_elastic_point(p, dt, dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy, lame, body, strain, stress, start_motion)
        total += s_xx + s_yy + s_xy
        volume = quotient(mass_p[p], density_p[p])
        _tensor_force(nodes, fx, dfx, fy, dfy, n1, volume * s_xx, volume * s_yy, volume * s_xy,
                      force)
    return total


@compiled()
def tensor_velocity_gradient(x, velocity, v_ref, relative, dt,
                             marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, topology,
                             strain, strain_increment, gradient_increment, start_motion):
    """:func:`local_velocity_gradient` for tensor-product bases."""
    _relative_velocity(velocity, v_ref, relative)
    n1 = len(marker)
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        nodes, fx, dfx, fy, dfy = located_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y,
                                                  table_y, topology)
        dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy = _tensor_gradient(nodes, fx, dfx, fy, dfy, n1, relative)
        _record_gradient(p, dt, dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy, strain, strain_increment, gradient_increment, start_motion)


@compiled()
def tensor_internal_force(x, mass_p, density_p, stress,
                          marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, topology,
                          force):
    """:func:`local_internal_force` for tensor-product bases."""
    n1 = len(marker)
    force[:] = 0.0
    total = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        nodes, fx, dfx, fy, dfy = located_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y,
                                                  table_y, topology)
        volume = quotient(mass_p[p], density_p[p])
        total += stress[p, 0] + stress[p, 1] + stress[p, 2]
        _tensor_force(nodes, fx, dfx, fy, dfy, n1, volume * stress[p, 0], volume * stress[p, 1],
                      volume * stress[p, 2], force)
    return total


@compiled()
def tensor_g2p(x, v, density_p, acceleration, v_ref, dt, start_motion, hrz,
               marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, topology):
    """:func:`local_g2p` for tensor-product bases."""
    n1 = len(marker)
    total = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        nodes, fx, dfx, fy, dfy = located_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y,
                                                  table_y, topology)
        ax = 0.0
        ay = 0.0
        # what carries the velocity increment: N, or the HRZ weights (their normalization after the sums)
        gx, sum_x = squares(fx) if hrz else (fx, 1.0)
        gy, sum_y = squares(fy) if hrz else (fy, 1.0)
        for i in range(n1):
            sax = 0.0
            say = 0.0
            for j in range(n1):
                node = nodes[i * n1 + j]
                sax = fused(gy[j], acceleration[node, 0], sax)
                say = fused(gy[j], acceleration[node, 1], say)
            ax = fused(gx[i], sax, ax)
            ay = fused(gx[i], say, ay)
        if hrz:
            inverse = 1.0 / (sum_x * sum_y)
            ax *= inverse
            ay *= inverse
        total += _move_point(p, dt, ax, ay, v_ref, v, x, density_p, start_motion)
    return total
