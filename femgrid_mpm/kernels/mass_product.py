"""The consistent mass's product with a nodal field, without the matrix: ``N.T diag(m_p) N f``.

Each point gathers ``f`` at itself (as G2P gathers the acceleration) and scatters it back
weighed by its mass (as P2G scatters momentum), from its weights and nodes recorded once a step
(:func:`tensor_point_weights`, :func:`local_point_weights`; evaluating them is most of a pass):
``2 s`` products a point and component for ``s`` functions against the ``s^2 / 2`` of
assembling its share of the matrix (cubic splines: 32 against 136), which the iterated mass
(:mod:`femgrid_mpm.mass.iterated`) needs only ``2k`` times a step.  The points are where P2G left
them: the products of one step are all taken before G2P moves them.
"""

from __future__ import annotations

import numpy as np

from .arithmetic import fused
from .compiled import compiled
from .shape import function_slots, located_weights, point_weights, point_work, tensor_constants


@compiled()
def tensor_point_weights(x, marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform,
                         topology, weights, nodes):
    """Each point's ``n1 x n1`` values ``phi_ij = U_i W_j`` and nodes into ``weights``, ``nodes`` (n, n1^2)."""
    n1 = len(marker)
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        found, fx, dfx, fy, dfy = located_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y,
                                                  table_y, topology)
        for i in range(n1):
            for j in range(n1):
                weights[p, i * n1 + j] = fx[i] * fy[j]
                nodes[p, i * n1 + j] = found[i * n1 + j]


@compiled()
def local_point_weights(x, marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, form,
                        topology, weights, nodes):
    """The same function by function; a slot that is no function (the folded form's centre) weighs 0."""
    count, skip = function_slots(form, marker, topology)
    work = point_work(form, factors_x, factors_y, topology)
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        found, w, wx, wy = point_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y,
                                         table_y, topology, form, work)
        for k in range(count):
            weights[p, k] = 0.0 if k == skip else w[k]
            nodes[p, k] = found[0] if k == skip else found[k]


@compiled()
def weighted_mass_product(mass_p, weights, nodes, field, out):
    """``out = N.T diag(mass_p) N field`` (field, out (n_nodes, 2)) from the recorded weights."""
    out[:] = 0.0
    slots = weights.shape[1]
    for p in range(weights.shape[0]):
        gx = 0.0
        gy = 0.0
        for k in range(slots):
            node = np.uint64(nodes[p, k])  # unsigned: no wraparound test
            gx = fused(weights[p, k], field[node, 0], gx)
            gy = fused(weights[p, k], field[node, 1], gy)
        gx *= mass_p[p]
        gy *= mass_p[p]
        for k in range(slots):
            node = np.uint64(nodes[p, k])
            out[node, 0] = fused(gx, weights[p, k], out[node, 0])
            out[node, 1] = fused(gy, weights[p, k], out[node, 1])
