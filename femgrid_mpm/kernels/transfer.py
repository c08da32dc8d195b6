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
    (Eqs. 19-21).

Every kernel is serial (``parallel`` variants are separate functions), uses
``fastmath=False`` and is cached on disk (``cache=True``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .basis import evaluate_point, scratch

OUTSIDE = -1


@numba.njit(cache=True)
def p2g(x, v, mass_p, density_p, v_ref, signed, want_volume, assemble,
        geometry, n_elements, factors_x, table_x, factors_y, table_y, terms, term_weights, connectivity,
        grid_mass, grid_absolute, grid_volume, momentum, slots, matrix):
    """Scatter mass, relative momentum (and the mass matrix) to the grid.

    Returns the first point outside the grid, or -1.
    """
    n_local = connectivity.shape[1]
    fx, dfx, fy, dfy, w, wx, wy = scratch(factors_x, factors_y, n_local)
    grid_mass[:] = 0.0
    momentum[:] = 0.0
    if signed:
        grid_absolute[:] = 0.0
    if want_volume:
        grid_volume[:] = 0.0
    if assemble:
        matrix[:] = 0.0
    for p in range(x.shape[0]):
        element = evaluate_point(x[p, 0], x[p, 1], geometry, n_elements, factors_x, table_x, factors_y, table_y,
                                 terms, term_weights, fx, dfx, fy, dfy, w, wx, wy)
        if element < 0:
            return p
        m = mass_p[p]
        px = m * (v[p, 0] - v_ref[0])
        py = m * (v[p, 1] - v_ref[1])
        volume = m / density_p[p]
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
                for j in range(n_local):
                    matrix[node, slots[k, j]] += weighted * w[j]
    return -1


@numba.njit(cache=True)
def linear_elastic_stress_and_force(x, velocity, v_ref, dt, mass_p, density_p, body, lame,
                                    geometry, n_elements, factors_x, table_x, factors_y, table_y, terms,
                                    term_weights, connectivity, strain, stress, force, divergence):
    """Eqs. 18, 6 and 11 in one pass, for bodies of :class:`LinearElastic` material.

    ``lame[b] = (lambda, 2 mu)`` of body b.  Returns the sum of the new
    stresses (for the finiteness check).
    """
    n_local = connectivity.shape[1]
    fx, dfx, fy, dfy, w, wx, wy = scratch(factors_x, factors_y, n_local)
    force[:] = 0.0
    total = 0.0
    for p in range(x.shape[0]):
        element = evaluate_point(x[p, 0], x[p, 1], geometry, n_elements, factors_x, table_x, factors_y, table_y,
                                 terms, term_weights, fx, dfx, fy, dfy, w, wx, wy)
        # dv_dx = dNdx @ v_rel: (d vx/dx, d vy/dx); dv_dy likewise
        dvx_dx = 0.0
        dvy_dx = 0.0
        dvx_dy = 0.0
        dvy_dy = 0.0
        for k in range(n_local):
            node = connectivity[element, k]
            rx = velocity[node, 0] - v_ref[0]
            ry = velocity[node, 1] - v_ref[1]
            dvx_dx += wx[k] * rx
            dvy_dx += wx[k] * ry
            dvx_dy += wy[k] * rx
            dvy_dy += wy[k] * ry
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
        total += s_xx + s_yy + s_xy
        divergence[p] = dvx_dx + dvy_dy
        volume = mass_p[p] / density_p[p]
        w_xx = volume * s_xx
        w_yy = volume * s_yy
        w_xy = volume * s_xy
        for k in range(n_local):
            node = connectivity[element, k]
            force[node, 0] -= wx[k] * w_xx + wy[k] * w_xy
            force[node, 1] -= wx[k] * w_xy + wy[k] * w_yy
    return total


@numba.njit(cache=True)
def velocity_gradient(x, velocity, v_ref, dt,
                      geometry, n_elements, factors_x, table_x, factors_y, table_y, terms, term_weights,
                      connectivity, strain, strain_increment, gradient_increment, divergence):
    """Eq. 18 for any material: the strain increment (added to ``strain``) and ``dt L``."""
    n_local = connectivity.shape[1]
    fx, dfx, fy, dfy, w, wx, wy = scratch(factors_x, factors_y, n_local)
    for p in range(x.shape[0]):
        element = evaluate_point(x[p, 0], x[p, 1], geometry, n_elements, factors_x, table_x, factors_y, table_y,
                                 terms, term_weights, fx, dfx, fy, dfy, w, wx, wy)
        dvx_dx = 0.0
        dvy_dx = 0.0
        dvx_dy = 0.0
        dvy_dy = 0.0
        for k in range(n_local):
            node = connectivity[element, k]
            rx = velocity[node, 0] - v_ref[0]
            ry = velocity[node, 1] - v_ref[1]
            dvx_dx += wx[k] * rx
            dvy_dx += wx[k] * ry
            dvx_dy += wy[k] * rx
            dvy_dy += wy[k] * ry
        strain_increment[p, 0] = dt * dvx_dx
        strain_increment[p, 1] = dt * dvy_dy
        strain_increment[p, 2] = dt * (0.5 * (dvx_dy + dvy_dx))
        for c in range(3):
            strain[p, c] += strain_increment[p, c]
        gradient_increment[p, 0] = dt * dvx_dx
        gradient_increment[p, 1] = dt * dvx_dy
        gradient_increment[p, 2] = dt * dvy_dx
        gradient_increment[p, 3] = dt * dvy_dy
        divergence[p] = dvx_dx + dvy_dy


@numba.njit(cache=True)
def internal_force(x, mass_p, density_p, stress,
                   geometry, n_elements, factors_x, table_x, factors_y, table_y, terms, term_weights,
                   connectivity, force):
    """Eq. 11: ``f_I = -sum_p V_p sigma_p grad N_I`` with the volumes of time t."""
    n_local = connectivity.shape[1]
    fx, dfx, fy, dfy, w, wx, wy = scratch(factors_x, factors_y, n_local)
    force[:] = 0.0
    total = 0.0
    for p in range(x.shape[0]):
        element = evaluate_point(x[p, 0], x[p, 1], geometry, n_elements, factors_x, table_x, factors_y, table_y,
                                 terms, term_weights, fx, dfx, fy, dfy, w, wx, wy)
        volume = mass_p[p] / density_p[p]
        w_xx = volume * stress[p, 0]
        w_yy = volume * stress[p, 1]
        w_xy = volume * stress[p, 2]
        total += stress[p, 0] + stress[p, 1] + stress[p, 2]
        for k in range(n_local):
            node = connectivity[element, k]
            force[node, 0] -= wx[k] * w_xx + wy[k] * w_xy
            force[node, 1] -= wx[k] * w_xy + wy[k] * w_yy
    return total


@numba.njit(cache=True)
def g2p(x, v, density_p, acceleration, velocity, v_ref, dt, divergence,
        geometry, n_elements, factors_x, table_x, factors_y, table_y, terms, term_weights, connectivity):
    """Eqs. 19-21: point velocity from the grid acceleration, position from the
    grid velocity of the step's start, density.  Returns ``sum(v) + sum(x)``."""
    n_local = connectivity.shape[1]
    fx, dfx, fy, dfy, w, wx, wy = scratch(factors_x, factors_y, n_local)
    total = 0.0
    for p in range(x.shape[0]):
        element = evaluate_point(x[p, 0], x[p, 1], geometry, n_elements, factors_x, table_x, factors_y, table_y,
                                 terms, term_weights, fx, dfx, fy, dfy, w, wx, wy)
        ax = 0.0
        ay = 0.0
        ux = 0.0
        uy = 0.0
        for k in range(n_local):
            node = connectivity[element, k]
            ax += w[k] * acceleration[node, 0]
            ay += w[k] * acceleration[node, 1]
            ux += w[k] * (velocity[node, 0] - v_ref[0])
            uy += w[k] * (velocity[node, 1] - v_ref[1])
        v[p, 0] += dt * ax
        v[p, 1] += dt * ay
        x[p, 0] += dt * (ux + v_ref[0])
        x[p, 1] += dt * (uy + v_ref[1])
        density_p[p] *= math.exp(-dt * divergence[p])
        total += v[p, 0] + v[p, 1] + x[p, 0] + x[p, 1]
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
