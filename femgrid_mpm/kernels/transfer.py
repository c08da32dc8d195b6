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
``fastmath=False`` and is cached on disk (``cache=True``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .basis import evaluate_point, folded_weights, normalized_squares, scratch, tensor_constants, tensor_weights

OUTSIDE = -1


@numba.njit(cache=True, inline="always")
def _relative_velocity(velocity, v_ref, relative):
    """``v_I - v_ref``: the grid velocity in the step's frame (after the constraints)."""
    for i in range(velocity.shape[0]):
        relative[i, 0] = velocity[i, 0] - v_ref[0]
        relative[i, 1] = velocity[i, 1] - v_ref[1]


@numba.njit(cache=True, inline="always")
def _linear_elastic_point(p, dt, dvx_dx, dvy_dx, dvx_dy, dvy_dy, lame, body, strain, stress, start_motion):
    """Paper Eqs. 18 and 6 for point ``p``: strain increment from its velocity
    gradient, the incremental linear elastic stress, ``div v`` for Eq. 21.
    Returns the new stress (xx, yy, xy)."""
    e_xx = dt * dvx_dx
    e_yy = dt * dvy_dy
    e_xy = dt * (0.5 * (dvx_dy + dvy_dx))
    strain[p, 0] += e_xx
    strain[p, 1] += e_yy
    strain[p, 2] += e_xy
    lam = lame[body[p], 0]
    two_mu = lame[body[p], 1]
    volumetric = e_xx + e_yy
    s_xx = stress[p, 0] + (lam * volumetric + two_mu * e_xx)
    s_yy = stress[p, 1] + (lam * volumetric + two_mu * e_yy)
    s_xy = stress[p, 2] + two_mu * e_xy
    stress[p, 0] = s_xx
    stress[p, 1] = s_yy
    stress[p, 2] = s_xy
    start_motion[p, 0] = dvx_dx + dvy_dy
    return s_xx, s_yy, s_xy


@numba.njit(cache=True)
def flat_p2g(x, v, mass_p, density_p, v_ref, signed, want_volume, assemble, hrz,
        marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, terms, term_weights, connectivity,
        grid_mass, grid_absolute, grid_volume, momentum, indptr, rank, complete, slots, matrix):
    """Scatter mass, relative momentum (and the mass matrix, into the fixed
    pattern of :mod:`.pattern`) to the grid.

    Returns the first point outside the grid, or -1.
    """
    n_local = connectivity.shape[1]
    fx, dfx, fy, dfy, w, wx, wy = scratch(factors_x, factors_y, n_local)
    grid_mass[:] = 0.0
    momentum[:] = 0.0
    if signed or hrz:
        grid_absolute[:] = 0.0
    if want_volume:
        grid_volume[:] = 0.0
    if assemble:
        matrix[:] = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        element = evaluate_point(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y,
                                 terms, term_weights, fx, dfx, fy, dfy, w, wx, wy)
        if element < 0:
            return p
        m = mass_p[p]
        px = m * (v[p, 0] - v_ref[0])
        py = m * (v[p, 1] - v_ref[1])
        volume = m / density_p[p]
        if hrz:  # W = N^2 / sum N^2 carries the momentum; its column sums are the diagonal mass
            squares = 0.0
            for k in range(n_local):
                squares += w[k] * w[k]
            for k in range(n_local):
                node = connectivity[element, k]
                weight = w[k] * w[k] / squares
                grid_mass[node] += w[k] * m
                grid_absolute[node] += weight * m
                momentum[node, 0] += weight * px
                momentum[node, 1] += weight * py
            continue
        for k in range(n_local):
            node = connectivity[element, k]
            grid_mass[node] += w[k] * m
            momentum[node, 0] += w[k] * px
            momentum[node, 1] += w[k] * py
            if signed:
                grid_absolute[node] += abs(w[k]) * m
            if want_volume:
                grid_volume[node] += w[k] * volume
            if assemble:
                weighted = w[k] * m
                start = indptr[node]
                full = complete[node]
                for j in range(n_local):
                    slot = slots[k, j]
                    matrix[start + (slot if full else rank[node, slot])] += weighted * w[j]
    return -1


@numba.njit(cache=True, inline="always")
def _record_gradient(p, dt, dvx_dx, dvy_dx, dvx_dy, dvy_dy, strain, strain_increment, gradient_increment, start_motion):
    """Eq. 18 for any material: point p's strain increment (added to its strain),
    ``dt L`` and ``div v``."""
    strain_increment[p, 0] = dt * dvx_dx
    strain_increment[p, 1] = dt * dvy_dy
    strain_increment[p, 2] = dt * (0.5 * (dvx_dy + dvy_dx))
    for c in range(3):
        strain[p, c] += strain_increment[p, c]
    gradient_increment[p, 0] = dt * dvx_dx
    gradient_increment[p, 1] = dt * dvx_dy
    gradient_increment[p, 2] = dt * dvy_dx
    gradient_increment[p, 3] = dt * dvy_dy
    start_motion[p, 0] = dvx_dx + dvy_dy


@numba.njit(cache=True, inline="always")
def _move_point(p, dt, ax, ay, v_ref, v, x, density_p, start_motion):
    """Eqs. 19-21 for point p from its interpolated acceleration (ax, ay) and what
    the force pass interpolated (``start_motion[p]``: ``div v`` and the relative
    grid velocity ``N @ v_rel``).  Returns ``v_x + v_y + x + y``."""
    v[p, 0] += dt * ax
    v[p, 1] += dt * ay
    x[p, 0] += dt * (start_motion[p, 1] + v_ref[0])
    x[p, 1] += dt * (start_motion[p, 2] + v_ref[1])
    density_p[p] *= math.exp(-dt * start_motion[p, 0])
    return v[p, 0] + v[p, 1] + x[p, 0] + x[p, 1]


@numba.njit(cache=True, inline="always")
def _flat_gradient(element, n_local, connectivity, relative, w, wx, wy):
    """``dNdx @ v_rel``, ``dNdy @ v_rel`` and ``N @ v_rel`` at one point:
    (d vx/dx, d vy/dx, d vx/dy, d vy/dy, vx, vy)."""
    dvx_dx = 0.0
    dvy_dx = 0.0
    dvx_dy = 0.0
    dvy_dy = 0.0
    ux = 0.0
    uy = 0.0
    for k in range(n_local):
        node = connectivity[element, k]
        rx = relative[node, 0]
        ry = relative[node, 1]
        dvx_dx += wx[k] * rx
        dvy_dx += wx[k] * ry
        dvx_dy += wy[k] * rx
        dvy_dy += wy[k] * ry
        ux += w[k] * rx
        uy += w[k] * ry
    return dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy


@numba.njit(cache=True, inline="always")
def _flat_force(element, n_local, connectivity, wx, wy, w_xx, w_yy, w_xy, force):
    """One point's share of Eq. 11, ``-V sigma grad N``, scattered to its nodes."""
    for k in range(n_local):
        node = connectivity[element, k]
        force[node, 0] -= wx[k] * w_xx + wy[k] * w_xy
        force[node, 1] -= wx[k] * w_xy + wy[k] * w_yy


@numba.njit(cache=True)
def flat_linear_elastic_stress_and_force(x, velocity, v_ref, relative, dt, mass_p, density_p, body, lame,
                                    marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform,
                                    terms, term_weights, connectivity, strain, stress, force, start_motion):
    """Eqs. 18, 6 and 11 in one pass, for bodies of :class:`LinearElastic` material.

    ``lame[b] = (lambda, 2 mu)`` of body b.  Returns the sum of the new
    stresses (for the finiteness check).
    """
    _relative_velocity(velocity, v_ref, relative)
    n_local = connectivity.shape[1]
    fx, dfx, fy, dfy, w, wx, wy = scratch(factors_x, factors_y, n_local)
    force[:] = 0.0
    total = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        element = evaluate_point(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y,
                                 terms, term_weights, fx, dfx, fy, dfy, w, wx, wy)
        dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy = _flat_gradient(element, n_local, connectivity, relative, w, wx, wy)
        start_motion[p, 1] = ux  # N @ v_rel: G2P moves the point with it
        start_motion[p, 2] = uy
        s_xx, s_yy, s_xy = _linear_elastic_point(p, dt, dvx_dx, dvy_dx, dvx_dy, dvy_dy, lame, body, strain, stress, start_motion)
        total += s_xx + s_yy + s_xy
        volume = mass_p[p] / density_p[p]
        w_xx = volume * s_xx
        w_yy = volume * s_yy
        w_xy = volume * s_xy
        _flat_force(element, n_local, connectivity, wx, wy, w_xx, w_yy, w_xy, force)
    return total


@numba.njit(cache=True)
def flat_velocity_gradient(x, velocity, v_ref, relative, dt,
                      marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, terms, term_weights,
                      connectivity, strain, strain_increment, gradient_increment, start_motion):
    """Eq. 18 for any material: the strain increment (added to ``strain``) and ``dt L``."""
    _relative_velocity(velocity, v_ref, relative)
    n_local = connectivity.shape[1]
    fx, dfx, fy, dfy, w, wx, wy = scratch(factors_x, factors_y, n_local)
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        element = evaluate_point(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y,
                                 terms, term_weights, fx, dfx, fy, dfy, w, wx, wy)
        dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy = _flat_gradient(element, n_local, connectivity, relative, w, wx, wy)
        start_motion[p, 1] = ux  # N @ v_rel: G2P moves the point with it
        start_motion[p, 2] = uy
        _record_gradient(p, dt, dvx_dx, dvy_dx, dvx_dy, dvy_dy, strain, strain_increment, gradient_increment, start_motion)


@numba.njit(cache=True)
def flat_internal_force(x, mass_p, density_p, stress,
                   marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, terms, term_weights,
                   connectivity, force):
    """Eq. 11: ``f_I = -sum_p V_p sigma_p grad N_I`` with the volumes of time t."""
    n_local = connectivity.shape[1]
    fx, dfx, fy, dfy, w, wx, wy = scratch(factors_x, factors_y, n_local)
    force[:] = 0.0
    total = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        element = evaluate_point(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y,
                                 terms, term_weights, fx, dfx, fy, dfy, w, wx, wy)
        volume = mass_p[p] / density_p[p]
        w_xx = volume * stress[p, 0]
        w_yy = volume * stress[p, 1]
        w_xy = volume * stress[p, 2]
        total += stress[p, 0] + stress[p, 1] + stress[p, 2]
        _flat_force(element, n_local, connectivity, wx, wy, w_xx, w_yy, w_xy, force)
    return total


@numba.njit(cache=True)
def flat_g2p(x, v, density_p, acceleration, v_ref, dt, start_motion, hrz,
        marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, terms, term_weights, connectivity):
    """Eqs. 19-21: point velocity from the grid acceleration, position from the
    grid velocity of the step's start and density from its divergence (both
    interpolated in the force pass: ``start_motion``).  Returns ``sum(v) + sum(x)``."""
    n_local = connectivity.shape[1]
    fx, dfx, fy, dfy, w, wx, wy = scratch(factors_x, factors_y, n_local)
    total = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        element = evaluate_point(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y,
                                 terms, term_weights, fx, dfx, fy, dfy, w, wx, wy)
        ax = 0.0
        ay = 0.0
        squares = 0.0
        if hrz:
            for k in range(n_local):
                squares += w[k] * w[k]
        for k in range(n_local):
            node = connectivity[element, k]
            weight = w[k] * w[k] / squares if hrz else w[k]  # what carries the velocity increment
            ax += weight * acceleration[node, 0]
            ay += weight * acceleration[node, 1]
        total += _move_point(p, dt, ax, ay, v_ref, v, x, density_p, start_motion)
    return total


@numba.njit(cache=True)
def lumped_grid_velocity(grid_mass, grid_absolute, signed, reference_mass, momentum, v_ref,
                         inverse, active, velocity, full_momentum):
    """Lumped grid update (Eqs. 15-17): which nodes can be divided by, ``1 / m_I``,
    ``v_I = p_rel / m_I + v_ref`` and the momentum in the fixed frame.

    A node is active when its mass is not empty and (signed bases) not
    cancellation-dominated: ``|m_I| > 1e-6 sum m_p |N_Ip|``.  Returns the
    smallest mass.
    """
    smallest = np.inf
    for i in range(grid_mass.shape[0]):
        m = grid_mass[i]
        absolute = grid_absolute[i] if signed else m
        smallest = min(smallest, m)
        is_active = abs(m) > 1e-6 * absolute and absolute > 1e-12 * reference_mass
        active[i] = is_active
        inverse[i] = 1.0 / m if is_active else 0.0
        for c in range(2):
            velocity[i, c] = momentum[i, c] * inverse[i] + v_ref[c]
            full_momentum[i, c] = momentum[i, c] + m * v_ref[c]
    return smallest


# -- tensor-product bases: sum factorization over the n1 x n1 nodes ----------------------------------------
#
# With phi_(i,j) = U_i(xi) W_j(eta), a gather sum_ij phi_ij g_ij is
# sum_i U_i (sum_j W_j g_ij) and its x-derivative reuses the inner sums;
# a scatter multiplies per-i factors by W_j.  ``len(marker)`` (n1) is a
# compile-time constant, so every loop over nodes is unrolled.


@numba.njit(cache=True)
def tensor_p2g(x, v, mass_p, density_p, v_ref, signed, want_volume, assemble, hrz,
               marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, connectivity,
               grid_mass, grid_absolute, grid_volume, momentum, indptr, rank, complete, slots, matrix):
    """:func:`flat_p2g` for tensor-product bases (``slots`` in tensor order)."""
    n1 = len(marker)
    grid_mass[:] = 0.0
    momentum[:] = 0.0
    if signed or hrz:
        grid_absolute[:] = 0.0
    if want_volume:
        grid_volume[:] = 0.0
    if assemble:
        matrix[:] = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        element, fx, dfx, fy, dfy = tensor_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y)
        if element < 0:
            return p
        m = mass_p[p]
        px = m * (v[p, 0] - v_ref[0])
        py = m * (v[p, 1] - v_ref[1])
        volume = m / density_p[p]
        if hrz:  # W_ij = gx_i gy_j carries the momentum; its column sums are the diagonal mass
            gx = normalized_squares(fx)
            gy = normalized_squares(fy)
            for i in range(n1):
                m_i = fx[i] * m
                d_i = gx[i] * m
                px_i = gx[i] * px
                py_i = gx[i] * py
                for j in range(n1):
                    node = connectivity[element, i * n1 + j]
                    grid_mass[node] += m_i * fy[j]
                    grid_absolute[node] += d_i * gy[j]
                    momentum[node, 0] += px_i * gy[j]
                    momentum[node, 1] += py_i * gy[j]
        elif signed:  # also |N|.T @ m_p
            for i in range(n1):
                m_i = fx[i] * m
                a_i = abs(fx[i]) * m
                px_i = fx[i] * px
                py_i = fx[i] * py
                for j in range(n1):
                    node = connectivity[element, i * n1 + j]
                    grid_mass[node] += m_i * fy[j]
                    grid_absolute[node] += a_i * abs(fy[j])
                    momentum[node, 0] += px_i * fy[j]
                    momentum[node, 1] += py_i * fy[j]
        else:
            for i in range(n1):
                m_i = fx[i] * m
                px_i = fx[i] * px
                py_i = fx[i] * py
                for j in range(n1):
                    node = connectivity[element, i * n1 + j]
                    grid_mass[node] += m_i * fy[j]
                    momentum[node, 0] += px_i * fy[j]
                    momentum[node, 1] += py_i * fy[j]
        if want_volume:
            for i in range(n1):
                v_i = fx[i] * volume
                for j in range(n1):
                    grid_volume[connectivity[element, i * n1 + j]] += v_i * fy[j]
        if assemble:
            for i in range(n1):
                for j in range(n1):
                    a = i * n1 + j
                    node = connectivity[element, a]
                    start = indptr[node]
                    full = complete[node]
                    m_a = fx[i] * fy[j] * m
                    for k in range(n1):
                        m_ak = m_a * fx[k]
                        for l in range(n1):
                            slot = slots[a, k * n1 + l]
                            matrix[start + (slot if full else rank[node, slot])] += m_ak * fy[l]
    return -1


@numba.njit(cache=True, inline="always")
def _tensor_gradient(element, fx, dfx, fy, dfy, n1, connectivity, relative):
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
            node = connectivity[element, i * n1 + j]
            rx = relative[node, 0]
            ry = relative[node, 1]
            ax += fy[j] * rx
            ay += fy[j] * ry
            bx += dfy[j] * rx
            by += dfy[j] * ry
        dvx_dx += dfx[i] * ax
        dvy_dx += dfx[i] * ay
        dvx_dy += fx[i] * bx
        dvy_dy += fx[i] * by
        ux += fx[i] * ax
        uy += fx[i] * ay
    return dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy


@numba.njit(cache=True, inline="always")
def _tensor_force(element, fx, dfx, fy, dfy, n1, connectivity, w_xx, w_yy, w_xy, force):
    """Scatter ``-(dNdx (V s_xx, V s_xy) + dNdy (V s_xy, V s_yy))`` of one point."""
    for i in range(n1):
        c_xx = dfx[i] * w_xx
        c_xy = fx[i] * w_xy
        d_xy = dfx[i] * w_xy
        d_yy = fx[i] * w_yy
        for j in range(n1):
            node = connectivity[element, i * n1 + j]
            force[node, 0] -= fy[j] * c_xx + dfy[j] * c_xy
            force[node, 1] -= fy[j] * d_xy + dfy[j] * d_yy


@numba.njit(cache=True)
def tensor_linear_elastic_stress_and_force(x, velocity, v_ref, relative, dt, mass_p, density_p, body, lame,
                                           marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform,
                                           connectivity, strain, stress, force, start_motion):
    """:func:`flat_linear_elastic_stress_and_force` for tensor-product bases."""
    _relative_velocity(velocity, v_ref, relative)
    n1 = len(marker)
    force[:] = 0.0
    total = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        element, fx, dfx, fy, dfy = tensor_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y)
        dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy = _tensor_gradient(element, fx, dfx, fy, dfy, n1, connectivity, relative)
        start_motion[p, 1] = ux  # N @ v_rel: G2P moves the point with it
        start_motion[p, 2] = uy
        s_xx, s_yy, s_xy = _linear_elastic_point(p, dt, dvx_dx, dvy_dx, dvx_dy, dvy_dy, lame, body, strain, stress, start_motion)
        total += s_xx + s_yy + s_xy
        volume = mass_p[p] / density_p[p]
        _tensor_force(element, fx, dfx, fy, dfy, n1, connectivity, volume * s_xx, volume * s_yy, volume * s_xy,
                      force)
    return total


@numba.njit(cache=True)
def tensor_velocity_gradient(x, velocity, v_ref, relative, dt,
                             marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, connectivity,
                             strain, strain_increment, gradient_increment, start_motion):
    """:func:`flat_velocity_gradient` for tensor-product bases."""
    _relative_velocity(velocity, v_ref, relative)
    n1 = len(marker)
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        element, fx, dfx, fy, dfy = tensor_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y)
        dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy = _tensor_gradient(element, fx, dfx, fy, dfy, n1, connectivity, relative)
        start_motion[p, 1] = ux  # N @ v_rel: G2P moves the point with it
        start_motion[p, 2] = uy
        _record_gradient(p, dt, dvx_dx, dvy_dx, dvx_dy, dvy_dy, strain, strain_increment, gradient_increment, start_motion)


@numba.njit(cache=True)
def tensor_internal_force(x, mass_p, density_p, stress,
                          marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, connectivity,
                          force):
    """:func:`flat_internal_force` for tensor-product bases."""
    n1 = len(marker)
    force[:] = 0.0
    total = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        element, fx, dfx, fy, dfy = tensor_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y)
        volume = mass_p[p] / density_p[p]
        total += stress[p, 0] + stress[p, 1] + stress[p, 2]
        _tensor_force(element, fx, dfx, fy, dfy, n1, connectivity, volume * stress[p, 0], volume * stress[p, 1],
                      volume * stress[p, 2], force)
    return total


@numba.njit(cache=True)
def tensor_g2p(x, v, density_p, acceleration, v_ref, dt, start_motion, hrz,
               marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, connectivity):
    """:func:`flat_g2p` for tensor-product bases."""
    n1 = len(marker)
    total = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        element, fx, dfx, fy, dfy = tensor_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y)
        ax = 0.0
        ay = 0.0
        # what carries the velocity increment: N, or the HRZ weights
        gx = normalized_squares(fx) if hrz else fx
        gy = normalized_squares(fy) if hrz else fy
        for i in range(n1):
            sax = 0.0
            say = 0.0
            for j in range(n1):
                node = connectivity[element, i * n1 + j]
                sax += gy[j] * acceleration[node, 0]
                say += gy[j] * acceleration[node, 1]
            ax += gx[i] * sax
            ay += gx[i] * say
        total += _move_point(p, dt, ax, ay, v_ref, v, x, density_p, start_motion)
    return total


# -- folded bases (serendipity): n1 x n1 tensor slots in registers, the centre folded in ---------------------
#
# ``folded_weights`` returns every slot's value and gradient as tuples
# (see :class:`~femgrid_mpm.kernels.basis.FoldedTables`); the loops over the
# slots have a compile-time length and are unrolled, and the centre slot,
# which is no node, is skipped.  Same arithmetic per function as the flat
# kernels (``q_own + c q_centre``), so the weights agree bit for bit.


@numba.njit(cache=True)
def folded_p2g(x, v, mass_p, density_p, v_ref, signed, want_volume, assemble, hrz,
               marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, fold, connectivity,
               grid_mass, grid_absolute, grid_volume, momentum, indptr, rank, complete, slots, matrix):
    """:func:`flat_p2g` for folded bases (``slots`` in slot order)."""
    n1 = len(marker)
    n_slots = n1 * n1
    centre = n_slots // 2
    grid_mass[:] = 0.0
    momentum[:] = 0.0
    if signed or hrz:
        grid_absolute[:] = 0.0
    if want_volume:
        grid_volume[:] = 0.0
    if assemble:
        matrix[:] = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        element, fx, dfx, fy, dfy = tensor_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y)
        if element < 0:
            return p
        w, wx, wy = folded_weights(fx, dfx, fy, dfy, fold)
        m = mass_p[p]
        px = m * (v[p, 0] - v_ref[0])
        py = m * (v[p, 1] - v_ref[1])
        volume = m / density_p[p]
        squares = 0.0
        if hrz:
            for s in range(n_slots):
                squares += w[s] * w[s]  # the centre's weight is exactly zero
        for s in range(n_slots):
            if s == centre:
                continue
            node = connectivity[element, s]
            grid_mass[node] += w[s] * m
            if hrz:  # W = N^2 / sum N^2 carries the momentum; its column sums are the diagonal mass
                weight = w[s] * w[s] / squares
                grid_absolute[node] += weight * m
                momentum[node, 0] += weight * px
                momentum[node, 1] += weight * py
            else:
                momentum[node, 0] += w[s] * px
                momentum[node, 1] += w[s] * py
                if signed:
                    grid_absolute[node] += abs(w[s]) * m
            if want_volume:
                grid_volume[node] += w[s] * volume
            if assemble:
                weighted = w[s] * m
                start = indptr[node]
                full = complete[node]
                for b in range(n_slots):
                    if b != centre:
                        slot = slots[s, b]
                        matrix[start + (slot if full else rank[node, slot])] += weighted * w[b]
    return -1


@numba.njit(cache=True, inline="always")
def _folded_gradient(element, w, wx, wy, n_slots, centre, connectivity, relative):
    """``dNdx @ v_rel``, ``dNdy @ v_rel`` and ``N @ v_rel`` of one point:
    (dvx/dx, dvy/dx, dvx/dy, dvy/dy, vx, vy)."""
    dvx_dx = 0.0
    dvy_dx = 0.0
    dvx_dy = 0.0
    dvy_dy = 0.0
    ux = 0.0
    uy = 0.0
    for s in range(n_slots):
        if s == centre:
            continue
        node = connectivity[element, s]
        rx = relative[node, 0]
        ry = relative[node, 1]
        dvx_dx += wx[s] * rx
        dvy_dx += wx[s] * ry
        dvx_dy += wy[s] * rx
        dvy_dy += wy[s] * ry
        ux += w[s] * rx
        uy += w[s] * ry
    return dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy


@numba.njit(cache=True, inline="always")
def _folded_force(element, wx, wy, n_slots, centre, connectivity, w_xx, w_yy, w_xy, force):
    """One point's share of Eq. 11, ``-V sigma grad N``, scattered to its nodes."""
    for s in range(n_slots):
        if s == centre:
            continue
        node = connectivity[element, s]
        force[node, 0] -= wx[s] * w_xx + wy[s] * w_xy
        force[node, 1] -= wx[s] * w_xy + wy[s] * w_yy


@numba.njit(cache=True)
def folded_linear_elastic_stress_and_force(x, velocity, v_ref, relative, dt, mass_p, density_p, body, lame,
                                           marker, geometry, n_elements, factors_x, table_x, factors_y, table_y,
                                           uniform, fold, connectivity, strain, stress, force, start_motion):
    """:func:`flat_linear_elastic_stress_and_force` for folded bases."""
    _relative_velocity(velocity, v_ref, relative)
    n1 = len(marker)
    n_slots = n1 * n1
    centre = n_slots // 2
    force[:] = 0.0
    total = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        element, fx, dfx, fy, dfy = tensor_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y)
        w, wx, wy = folded_weights(fx, dfx, fy, dfy, fold)
        dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy = _folded_gradient(element, w, wx, wy, n_slots, centre, connectivity, relative)
        start_motion[p, 1] = ux  # N @ v_rel: G2P moves the point with it
        start_motion[p, 2] = uy
        s_xx, s_yy, s_xy = _linear_elastic_point(p, dt, dvx_dx, dvy_dx, dvx_dy, dvy_dy, lame, body, strain, stress, start_motion)
        total += s_xx + s_yy + s_xy
        volume = mass_p[p] / density_p[p]
        _folded_force(element, wx, wy, n_slots, centre, connectivity, volume * s_xx, volume * s_yy, volume * s_xy,
                      force)
    return total


@numba.njit(cache=True)
def folded_velocity_gradient(x, velocity, v_ref, relative, dt,
                             marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, fold,
                             connectivity, strain, strain_increment, gradient_increment, start_motion):
    """:func:`flat_velocity_gradient` for folded bases."""
    _relative_velocity(velocity, v_ref, relative)
    n1 = len(marker)
    n_slots = n1 * n1
    centre = n_slots // 2
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        element, fx, dfx, fy, dfy = tensor_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y)
        w, wx, wy = folded_weights(fx, dfx, fy, dfy, fold)
        dvx_dx, dvy_dx, dvx_dy, dvy_dy, ux, uy = _folded_gradient(element, w, wx, wy, n_slots, centre, connectivity, relative)
        start_motion[p, 1] = ux  # N @ v_rel: G2P moves the point with it
        start_motion[p, 2] = uy
        _record_gradient(p, dt, dvx_dx, dvy_dx, dvx_dy, dvy_dy, strain, strain_increment, gradient_increment, start_motion)


@numba.njit(cache=True)
def folded_internal_force(x, mass_p, density_p, stress,
                          marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, fold,
                          connectivity, force):
    """:func:`flat_internal_force` for folded bases."""
    n1 = len(marker)
    n_slots = n1 * n1
    centre = n_slots // 2
    force[:] = 0.0
    total = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        element, fx, dfx, fy, dfy = tensor_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y)
        w, wx, wy = folded_weights(fx, dfx, fy, dfy, fold)
        volume = mass_p[p] / density_p[p]
        total += stress[p, 0] + stress[p, 1] + stress[p, 2]
        _folded_force(element, wx, wy, n_slots, centre, connectivity, volume * stress[p, 0], volume * stress[p, 1],
                      volume * stress[p, 2], force)
    return total


@numba.njit(cache=True)
def folded_g2p(x, v, density_p, acceleration, v_ref, dt, start_motion, hrz,
               marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, fold, connectivity):
    """:func:`flat_g2p` for folded bases."""
    n1 = len(marker)
    n_slots = n1 * n1
    centre = n_slots // 2
    total = 0.0
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        element, fx, dfx, fy, dfy = tensor_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y)
        w, wx, wy = folded_weights(fx, dfx, fy, dfy, fold)
        squares = 0.0
        if hrz:
            for s in range(n_slots):
                squares += w[s] * w[s]
        ax = 0.0
        ay = 0.0
        for s in range(n_slots):
            if s == centre:
                continue
            node = connectivity[element, s]
            weight = w[s] * w[s] / squares if hrz else w[s]  # what carries the velocity increment
            ax += weight * acceleration[node, 0]
            ay += weight * acceleration[node, 1]
        total += _move_point(p, dt, ax, ay, v_ref, v, x, density_p, start_motion)
    return total
