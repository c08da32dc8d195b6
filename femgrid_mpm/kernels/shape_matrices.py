"""``N, dNdx, dNdy`` at many points as fixed-width rows: the data of
:class:`~.engines.ShapeFunctionMatrices` (effects, and mass models that need
``N`` itself, read the matrices), and what ``tests/test_kernels.py`` checks
against :meth:`femgrid_mpm.Grid.shape_functions`.

The kernels here evaluate each point as the passes do (:mod:`.shape`) and
write the values out in the grid's local order.
"""

from __future__ import annotations

import numpy as np

from .compiled import compiled
from .shape import evaluate_point, inside_grid, located_weights, scratch, tensor_constants
from .tables import BasisTables


@compiled()
def shape_function_data(x, marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, form,
                        connectivity, values, d_x, d_y, nodes):
    """``N, dNdx, dNdy`` of every point as fixed-width rows (n, n_local), and their nodes.

    Returns the first point outside the grid, or -1.
    """
    n_local = connectivity.shape[1]
    terms, term_weights = form
    fx, dfx, fy, dfy, w, wx, wy = scratch(factors_x, factors_y, n_local)
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        if not inside_grid(x[p, 0], x[p, 1], constants):
            return p
        local = evaluate_point(x[p, 0], x[p, 1], constants, marker, factors_x, table_x, factors_y, table_y,
                               connectivity, terms, term_weights, fx, dfx, fy, dfy, w, wx, wy)
        for k in range(n_local):
            values[p, k] = w[k]
            d_x[p, k] = wx[k]
            d_y[p, k] = wy[k]
            nodes[p, k] = local[k]
    return -1


@compiled()
def tensor_shape_function_data(x, marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform,
                               numbering, order, values, d_x, d_y, nodes):
    """:func:`shape_function_data` for tensor bases, in the grid's local order."""
    n1 = len(marker)
    constants = tensor_constants(marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform)
    for p in range(x.shape[0]):
        if not inside_grid(x[p, 0], x[p, 1], constants):
            return p
        local, fx, dfx, fy, dfy = located_weights(x[p, 0], x[p, 1], constants, marker, factors_x, table_x,
                                                  factors_y, table_y, numbering)
        for i in range(n1):
            for j in range(n1):
                k = order[i * n1 + j]
                values[p, k] = fx[i] * fy[j]
                d_x[p, k] = dfx[i] * fy[j]
                d_y[p, k] = fx[i] * dfy[j]
                nodes[p, k] = local[i * n1 + j]
    return -1


def evaluate_shape_functions(tables: BasisTables, x: np.ndarray, values, d_x, d_y, nodes) -> int:
    """Fill ``(n, n_local)`` arrays with ``N, dNdx, dNdy`` and node indices in the
    grid's local order, by the tensor kernel where the basis allows; returns
    the first point outside the grid, or -1."""
    if tables.tensor is not None:
        return tensor_shape_function_data(x, *tables.tensor.arrays(), tables.tensor.order, values, d_x, d_y, nodes)
    return shape_function_data(x, *tables.arrays(), values, d_x, d_y, nodes)
