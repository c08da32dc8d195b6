"""The force pass of a step: velocity gradient and strain increment (Eq. 18), internal force (Eq. 11).

``velocity_gradient`` / ``internal_force`` / ``linear_elastic_stress_and_force``
    ``dt L_p = dt sum_I v_I (grad N_I)^T`` (Eq. 18), the strain increment and
    ``f_I = -sum_p V_p sigma_p grad N_I`` (Eq. 11); the last one fused with
    the linear elastic stress update (Eq. 6) in one pass.  Other materials
    update their stress between the first two.

The gradient's gathers of the relative grid velocity ``v_rel`` already hold
the inner sums of ``N @ v_rel``: the pass interpolates it and ``div v`` (of
the grid velocity at the step's start) and hands both over per point in
``start_motion`` (n, 3) to G2P (:mod:`.g2p`), which gathers the
acceleration only.
"""

from __future__ import annotations

import numpy as np

from .arithmetic import fused, quotient
from .compiled import compiled
from .shape import function_slots, located_weights, point_weights, point_work, tensor_constants


@compiled(forceinline=True)
def _relative_velocity(velocity, v_ref, relative):
    """``v_I - v_ref``: the grid velocity in the step's frame (after the constraints)."""
    for i in range(velocity.shape[0]):
        relative[i, 0] = velocity[i, 0] - v_ref[0]
        relative[i, 1] = velocity[i, 1] - v_ref[1]


@compiled(forceinline=True)
def _hand_over(p, divergence, ux, uy, start_motion):
    """What the force pass knows of point p's motion at the step's start and G2P
    needs (:func:`.g2p._move_point`): ``div v`` and ``N @ v_rel``, whose inner sums
    the gradient's gather already holds."""
    start_motion[p, 0] = divergence
    start_motion[p, 1] = ux
    start_motion[p, 2] = uy


@compiled(forceinline=True)
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


@compiled(forceinline=True)
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


# -- any basis, function by function: the flat and folded forms (see :mod:`.families`) ---------------------


@compiled(forceinline=True)
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


@compiled(forceinline=True)
def _local_force(nodes, count, skip, wx, wy, w_xx, w_yy, w_xy, force):
    """One point's share of Eq. 11, ``-V sigma grad N``, scattered to its nodes."""
    for k in range(count):
        if k == skip:
            continue
        node = nodes[k]
        force[node, 0] = fused(-wx[k], w_xx, fused(-wy[k], w_xy, force[node, 0]))
        force[node, 1] = fused(-wx[k], w_xy, fused(-wy[k], w_yy, force[node, 1]))


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


# -- tensor-product bases: sum factorization over the n1 x n1 nodes (see :mod:`.families`) -----------------


@compiled(forceinline=True)
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


@compiled(forceinline=True)
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
