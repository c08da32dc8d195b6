"""The machine's yardstick: the library's q1 lumped step written as plainly as compiled code gets.

Absolute costs per particle-step depend on the machine (the same commit
measured 63-81 ns for q1 on one machine of this kind and 90-98 ns on
another).  This module is the same explicit step (paper section 3.2, USF,
lumped mass, linear elastic, ``fastmath=False``, the library's arithmetic:
explicit fused multiply-adds in the accumulations and Eq. 21's exponential
by its series) with none of the library's
generality: one uniform bilinear grid whose node ``(i, j)`` is numbered
``i * (n_y + 1) + j``, no tables, no frame of reference, no effect stages,
no guards, no negative-mass checks, no output.  `benchmarks/step.py` times
it beside the library, so the table says how far the library is from the
simplest code of the same algorithm on the machine at hand;
`tests/test_performance_paths.py` checks that it computes the library's
step (to 1e-12 of each field's scale).

>>> import numpy as np
>>> state = block(side=4)
>>> before = state["x"].copy()
>>> run(state, steps=3, dt=1e-3)
>>> bool(np.all(np.isfinite(state["x"]))) and bool(np.any(state["x"] != before))
True
"""

from __future__ import annotations

import numpy as np

from femgrid_mpm.kernels.arithmetic import fused, quotient
from femgrid_mpm.kernels.compiled import compiled  # cached by fingerprint: it inlines the library's helpers
from femgrid_mpm.kernels.g2p import density_factor


@compiled(inline="always")
def _cell(x, p, lower, inverse_spacing, stride):
    """Point p's cell: its lower-left node and the coordinates (0..1) within it."""
    sx = (x[p, 0] - lower[0]) * inverse_spacing
    sy = (x[p, 1] - lower[1]) * inverse_spacing
    i = int(sx)
    j = int(sy)
    return i * stride + j, sx - i, sy - j


@compiled()
def minimal_step(x, v, mass, density, stress, strain, lame_lambda, two_mu, dt, lower, inverse_spacing, n_y,
                 grid_mass, momentum, velocity, force, start):
    """One step for every point: P2G, grid velocity, stress and force, grid acceleration, G2P.

    ``x, v`` (n, 2), ``mass, density`` (n,), ``stress, strain`` (n, 3) are
    updated in place; ``grid_mass`` (n_nodes,), ``momentum, velocity,
    force`` (n_nodes, 2) and ``start`` (n, 3) are work arrays.  ``n_y`` is
    the number of cells along y.
    """
    stride = n_y + 1
    grid_mass[:] = 0.0
    momentum[:] = 0.0
    for p in range(x.shape[0]):  # P2G: m_I = N.T @ m_p, p_I = N.T @ (m_p v_p)
        node, fx, fy = _cell(x, p, lower, inverse_spacing, stride)
        m = mass[p]
        for di, wx in ((0, 1.0 - fx), (1, fx)):
            for dj, wy in ((0, 1.0 - fy), (1, fy)):
                w = wx * wy
                n = node + di * stride + dj
                grid_mass[n] = fused(w, m, grid_mass[n])
                momentum[n, 0] = fused(w * m, v[p, 0], momentum[n, 0])
                momentum[n, 1] = fused(w * m, v[p, 1], momentum[n, 1])
    for n in range(grid_mass.shape[0]):  # Eq. 17
        inverse = 1.0 / grid_mass[n] if grid_mass[n] > 0.0 else 0.0
        velocity[n, 0] = momentum[n, 0] * inverse
        velocity[n, 1] = momentum[n, 1] * inverse
    force[:] = 0.0
    for p in range(x.shape[0]):  # Eqs. 18, 6, 11: strain increment, stress, internal force
        node, fx, fy = _cell(x, p, lower, inverse_spacing, stride)
        dvx_dx = dvx_dy = dvy_dx = dvy_dy = ux = uy = 0.0
        for di, wx, gx in ((0, 1.0 - fx, -inverse_spacing), (1, fx, inverse_spacing)):
            for dj, wy, gy in ((0, 1.0 - fy, -inverse_spacing), (1, fy, inverse_spacing)):
                n = node + di * stride + dj
                dvx_dx = fused(gx * wy, velocity[n, 0], dvx_dx)
                dvy_dx = fused(gx * wy, velocity[n, 1], dvy_dx)
                dvx_dy = fused(wx * gy, velocity[n, 0], dvx_dy)
                dvy_dy = fused(wx * gy, velocity[n, 1], dvy_dy)
                ux = fused(wx * wy, velocity[n, 0], ux)
                uy = fused(wx * wy, velocity[n, 1], uy)
        e_xx = dt * dvx_dx
        e_yy = dt * dvy_dy
        e_xy = dt * 0.5 * (dvx_dy + dvy_dx)
        strain[p, 0] += e_xx
        strain[p, 1] += e_yy
        strain[p, 2] += e_xy
        stress[p, 0] += lame_lambda * (e_xx + e_yy) + two_mu * e_xx
        stress[p, 1] += lame_lambda * (e_xx + e_yy) + two_mu * e_yy
        stress[p, 2] += two_mu * e_xy
        start[p, 0] = dvx_dx + dvy_dy
        start[p, 1] = ux
        start[p, 2] = uy
        volume = quotient(mass[p], density[p])
        for di, wx, gx in ((0, 1.0 - fx, -inverse_spacing), (1, fx, inverse_spacing)):
            for dj, wy, gy in ((0, 1.0 - fy, -inverse_spacing), (1, fy, inverse_spacing)):
                n = node + di * stride + dj
                force[n, 0] = fused(-volume, fused(gx * wy, stress[p, 0], wx * gy * stress[p, 2]), force[n, 0])
                force[n, 1] = fused(-volume, fused(gx * wy, stress[p, 2], wx * gy * stress[p, 1]), force[n, 1])
    for n in range(grid_mass.shape[0]):  # a = f / m, in place
        inverse = 1.0 / grid_mass[n] if grid_mass[n] > 0.0 else 0.0
        force[n, 0] *= inverse
        force[n, 1] *= inverse
    for p in range(x.shape[0]):  # G2P, Eqs. 19-21
        node, fx, fy = _cell(x, p, lower, inverse_spacing, stride)
        ax = ay = 0.0
        for di, wx in ((0, 1.0 - fx), (1, fx)):
            for dj, wy in ((0, 1.0 - fy), (1, fy)):
                n = node + di * stride + dj
                ax = fused(wx * wy, force[n, 0], ax)
                ay = fused(wx * wy, force[n, 1], ay)
        v[p, 0] = fused(dt, ax, v[p, 0])
        v[p, 1] = fused(dt, ay, v[p, 1])
        x[p, 0] = fused(dt, start[p, 1], x[p, 0])
        x[p, 1] = fused(dt, start[p, 2], x[p, 1])
        density[p] *= density_factor(-dt * start[p, 0])


def block(side: int, E: float = 1e4, nu: float = 0.3, density: float = 1e3) -> dict:
    """The state of `benchmarks/step.py`'s block: ``side x side`` cells of 2 x 2 points
    (spacing 1 m) two cells inside a grid of ``side + 4`` cells, plane strain,
    velocity ``0.01 cos(pi (x - 2) / side)``."""
    offsets = 2.0 + (np.arange(2 * side) + 0.5) / 2.0
    X, Y = np.meshgrid(offsets, offsets, indexing="ij")
    x = np.column_stack([X.ravel(), Y.ravel()])
    n, cells = len(x), side + 4
    v = np.zeros((n, 2))
    v[:, 0] = 0.01 * np.cos(np.pi * (x[:, 0] - 2.0) / side)
    n_nodes = (cells + 1) ** 2
    return {
        "x": x, "v": v, "mass": np.full(n, density * 0.25), "density": np.full(n, density),
        "stress": np.zeros((n, 3)), "strain": np.zeros((n, 3)),
        "lame_lambda": E * nu / ((1 + nu) * (1 - 2 * nu)), "two_mu": E / (1 + nu),
        "lower": np.zeros(2), "inverse_spacing": 1.0, "n_y": cells,
        "grid_mass": np.zeros(n_nodes), "momentum": np.zeros((n_nodes, 2)), "velocity": np.zeros((n_nodes, 2)),
        "force": np.zeros((n_nodes, 2)), "start": np.zeros((n, 3)),
    }


def run(state: dict, steps: int, dt: float) -> None:
    """``steps`` steps of :func:`minimal_step` on a :func:`block` state."""
    s = state
    for _ in range(steps):
        minimal_step(s["x"], s["v"], s["mass"], s["density"], s["stress"], s["strain"], s["lame_lambda"],
                     s["two_mu"], dt, s["lower"], s["inverse_spacing"], s["n_y"], s["grid_mass"], s["momentum"],
                     s["velocity"], s["force"], s["start"])
