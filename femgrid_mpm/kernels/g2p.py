"""G2P, the last pass of a step: the points' velocity, position and density from the grid (Eqs. 19-21).

``v_p += dt N @ a``, ``x_p += dt (N @ v_rel + v_ref)``, ``rho_p *= exp(-dt div v)``.
``N @ v_rel`` and ``div v`` (of the grid velocity at the step's start) are
interpolated in the force pass, whose gathers of ``v_rel`` already hold the
inner sums, and handed over per point in ``start_motion`` (n, 3)
(:mod:`.force`): G2P gathers the acceleration only.  With ``hrz`` the HRZ
weights ``W = N^2 / sum N^2`` carry the velocity increment (see
:mod:`.p2g`); positions keep ``N``.
"""

from __future__ import annotations

import math

from .arithmetic import fused
from .compiled import compiled
from .shape import function_slots, located_weights, point_weights, point_work, squares, tensor_constants


#: below this ``|a|`` :func:`density_factor` sums the series (the next term, a^7 / 7!, is 3.5e-19 of 1)
SERIES_BOUND = 2.0**-7


@compiled(forceinline=True)
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


@compiled(forceinline=True)
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


# -- any basis, function by function: the flat and folded forms (see :mod:`.families`) ---------------------


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


# -- tensor-product bases: sum factorization over the n1 x n1 nodes (see :mod:`.families`) -----------------


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
