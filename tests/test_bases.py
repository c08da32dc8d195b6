"""Property tests looped over every basis in the registry.

Tolerances: 1e-12 for identities that hold exactly in exact arithmetic (the
shape functions are evaluated from exact monomial coefficients, so only
rounding of O(10) operations enters); 1e-6 relative for central finite
differences with step 1e-6 of a cell (truncation error ~ step^2 * f''').
"""

import numpy as np
import pytest
import skfem

from femgrid_mpm import Grid
from femgrid_mpm.bases import BASES, cubic_spline

BASIS_NAMES = list(BASES)
LOWER, UPPER, SPACING = (-1.0, 0.5), (3.0, 2.5), 0.25


def make_grid(basis):
    return Grid(basis, lower=LOWER, upper=UPPER, spacing=SPACING)


def random_points(n=500, seed=0):
    rng = np.random.default_rng(seed)
    return np.asarray(LOWER) + rng.random((n, 2)) * (np.asarray(UPPER) - np.asarray(LOWER))


def lattice_points():
    """Points exactly on cell edges and corners, domain boundary included."""
    x = LOWER[0] + SPACING * np.arange(int(round((UPPER[0] - LOWER[0]) / SPACING)) + 1)
    y = LOWER[1] + SPACING * np.arange(int(round((UPPER[1] - LOWER[1]) / SPACING)) + 1)
    corners = np.column_stack([a.ravel() for a in np.meshgrid(x, y)])
    rng = np.random.default_rng(1)
    on_vertical = np.column_stack([rng.choice(x, 50), rng.uniform(LOWER[1], UPPER[1], 50)])
    on_horizontal = np.column_stack([rng.uniform(LOWER[0], UPPER[0], 50), rng.choice(y, 50)])
    return np.vstack([corners, on_vertical, on_horizontal])


POINT_SETS = {"random": random_points(), "edges and corners": lattice_points()}


@pytest.mark.parametrize("points_kind", list(POINT_SETS))
@pytest.mark.parametrize("basis", BASIS_NAMES)
def test_partition_of_unity(basis, points_kind):
    N, dNdx, dNdy = make_grid(basis).shape_functions(POINT_SETS[points_kind])
    np.testing.assert_allclose(N.sum(axis=1), 1.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(dNdx.sum(axis=1), 0.0, rtol=0, atol=1e-10)
    np.testing.assert_allclose(dNdy.sum(axis=1), 0.0, rtol=0, atol=1e-10)


@pytest.mark.parametrize("points_kind", list(POINT_SETS))
@pytest.mark.parametrize("basis", BASIS_NAMES)
def test_linear_completeness(basis, points_kind):
    grid = make_grid(basis)
    points = POINT_SETS[points_kind]
    N, dNdx, dNdy = grid.shape_functions(points)
    np.testing.assert_allclose(N @ grid.nodes, points, rtol=0, atol=1e-12)
    np.testing.assert_allclose(dNdx @ grid.nodes[:, 0], 1.0, rtol=0, atol=1e-10)
    np.testing.assert_allclose(dNdy @ grid.nodes[:, 0], 0.0, rtol=0, atol=1e-10)
    np.testing.assert_allclose(dNdx @ grid.nodes[:, 1], 0.0, rtol=0, atol=1e-10)
    np.testing.assert_allclose(dNdy @ grid.nodes[:, 1], 1.0, rtol=0, atol=1e-10)


QUADRATICS = {
    "x^2": lambda x, y: x**2,
    "xy": lambda x, y: x * y,
    "y^2": lambda x, y: y**2,
    "x^2 y^2": lambda x, y: x**2 * y**2,
}
REPRODUCED = {"q2": ["x^2", "xy", "y^2", "x^2 y^2"], "serendipity": ["x^2", "xy", "y^2"]}


@pytest.mark.parametrize(
    "basis,monomial", [(b, m) for b, ms in REPRODUCED.items() for m in ms]
)
def test_quadratic_completeness(basis, monomial):
    grid = make_grid(basis)
    points = np.vstack(list(POINT_SETS.values()))
    f = QUADRATICS[monomial]
    N, _, _ = grid.shape_functions(points)
    np.testing.assert_allclose(N @ f(*grid.nodes.T), f(*points.T), rtol=0, atol=1e-12)


def test_serendipity_does_not_reproduce_x2y2():
    """The check above could fail: serendipity lacks the x^2 y^2 term."""
    grid = make_grid("serendipity")
    points = random_points(50)
    N, _, _ = grid.shape_functions(points)
    f = QUADRATICS["x^2 y^2"]
    assert np.max(np.abs(N @ f(*grid.nodes.T) - f(*points.T))) > 1e-4


def test_bspline2_quadratic_offset():
    """Quadratic B-splines on nodes reproduce x^2 + h^2/4 (the spline's variance), exactly."""
    grid = make_grid("bspline2")
    points = np.vstack(list(POINT_SETS.values()))
    N, _, _ = grid.shape_functions(points)
    np.testing.assert_allclose(N @ grid.nodes[:, 0] ** 2, points[:, 0] ** 2 + SPACING**2 / 4, rtol=0, atol=1e-12)


def test_bspline2_matches_the_quadratic_spline():
    """The nine functions of a point: the products of S2 at its distances from the nodes."""
    from femgrid_mpm.bases.bspline2 import quadratic_spline

    grid = make_grid("bspline2")
    points = random_points(60, seed=6)
    N, _, _ = grid.shape_functions(points)
    r = (points[:, None, :] - grid.nodes[None, :, :]) / SPACING
    expected = quadratic_spline(r[..., 0]) * quadratic_spline(r[..., 1])
    np.testing.assert_allclose(N.toarray(), expected, rtol=0, atol=1e-14)


def test_open_knot_quadratic_splines_interpolate_at_the_boundary():
    """On the domain's edge only the edge node's function is non-zero, and it is 1: fixing the
    nodes on x <= 0 holds the wall exactly; the edge nodes lie on the edge, the next ones half a
    spacing in (their Greville abscissae)."""
    grid = Grid("bspline2_open", (0.0, 0.0), (3.0, 2.0), 0.5)
    rng = np.random.default_rng(7)
    wall = np.column_stack([np.zeros(20), rng.uniform(0.0, 2.0, 20)])
    N, _, _ = grid.shape_functions(wall)
    on_wall = grid.nodes_where("x <= 0")
    np.testing.assert_array_equal(N[:, on_wall].sum(axis=1), 1.0)
    assert sorted(set(grid.nodes[:, 0])) == [0.0, 0.25, 0.75, 1.25, 1.75, 2.25, 2.75, 3.0]


def test_bspline3_quadratic_offset():
    """Cubic B-splines on nodes reproduce x^2 + h^2/3 (Schoenberg), an exact identity."""
    grid = make_grid("bspline3")
    points = np.vstack(list(POINT_SETS.values()))
    N, _, _ = grid.shape_functions(points)
    np.testing.assert_allclose(N @ grid.nodes[:, 0] ** 2, points[:, 0] ** 2 + SPACING**2 / 3, rtol=0, atol=1e-12)


@pytest.mark.parametrize("basis", BASIS_NAMES)
def test_gradients_by_finite_differences(basis):
    grid = make_grid(basis)
    width = grid.discretization.element_width
    rng = np.random.default_rng(2)
    # keep points inside one element so the functions are smooth across the stencil
    element_corner = grid.lower + width * rng.integers(0, grid.discretization.n_elements, size=(200, 2))
    points = element_corner + width * rng.uniform(0.05, 0.95, size=(200, 2))
    step = 1e-6 * width
    N, dNdx, dNdy = grid.shape_functions(points)
    for derivative, shift in ((dNdx, [step, 0.0]), (dNdy, [0.0, step])):
        plus, _, _ = grid.shape_functions(points + shift)
        minus, _, _ = grid.shape_functions(points - shift)
        difference = ((plus - minus) / (2 * step)).toarray()
        scale = np.max(np.abs(derivative.toarray()))
        np.testing.assert_allclose(derivative.toarray(), difference, rtol=0, atol=1e-6 * scale)


SKFEM_ELEMENTS = {"q1": skfem.ElementQuad1, "q2": skfem.ElementQuad2, "serendipity": skfem.ElementQuadS2}


@pytest.mark.parametrize("basis", list(SKFEM_ELEMENTS))
def test_values_agree_with_scikit_fem_probes(basis):
    grid = make_grid(basis)
    points = np.vstack([random_points(20, seed=3), [[0.1, 0.6], [2.9, 2.4], [1.0, 1.5]]])
    reference = skfem.Basis(grid.mesh, SKFEM_ELEMENTS[basis]()).probes(points.T).toarray()
    reference = reference[:, grid.discretization.dofs]  # the grid numbers its nodes along the lattice
    N, _, _ = grid.shape_functions(points)
    np.testing.assert_allclose(N.toarray(), reference, rtol=0, atol=1e-12)


def test_bspline3_matches_paper_formulas():
    """The 16 functions of the paper's section 3.4, typed out independently."""
    grid = make_grid("bspline3")
    rng = np.random.default_rng(4)
    cell = np.array([5, 3])
    local = rng.random((30, 2))
    points = grid.lower + (cell + local) * SPACING
    xi, eta = local.T
    one_d = [
        lambda s: (1 - s) ** 3 / 6,
        lambda s: 2 / 3 - s**2 + s**3 / 2,
        lambda s: 1 / 6 + s / 2 + s**2 / 2 - s**3 / 2,
        lambda s: s**3 / 6,
    ]
    N, _, _ = grid.shape_functions(points)
    N = N.toarray()
    for a in range(4):
        for b in range(4):
            node = np.flatnonzero(
                np.all(np.isclose(grid.nodes, grid.lower + (cell + [a - 1, b - 1]) * SPACING), axis=1)
            )
            np.testing.assert_allclose(N[:, node[0]], one_d[a](xi) * one_d[b](eta), rtol=0, atol=1e-14)


@pytest.mark.parametrize("basis", BASIS_NAMES)
def test_sign_of_shape_functions(basis):
    N, _, _ = make_grid(basis).shape_functions(np.vstack(list(POINT_SETS.values())))
    if basis in ("q2", "serendipity"):
        assert N.data.min() < -0.1  # both take clearly negative values inside elements
    else:
        assert N.data.min() >= -1e-15  # never negative beyond rounding


def test_cubic_spline_kernel():
    """Eq. 23 values at a few distances, and continuity of the slope at |r| = 1."""
    value, slope = cubic_spline(np.array([0.0, 0.5, 1.0, 1.5, 2.0, 2.5]))
    np.testing.assert_allclose(value, [2 / 3, 2 / 3 - 0.25 + 0.0625, 1 / 6, 1 / 48, 0, 0], atol=1e-15)
    left, right = cubic_spline(np.array([1 - 1e-12, 1 + 1e-12]))[1]
    assert abs(left - right) < 1e-9


@pytest.mark.parametrize(
    "basis,expected", [("q1", 45), ("q2", 45), ("serendipity", 38), ("bspline3", 85)]
)
def test_paper_bar_grid_node_counts(basis, expected):
    """7 x 1 domain, spacing 0.5: 15 x 3 lattice nodes (paper: 45)."""
    assert Grid(basis, (0, 0), (7, 1), 0.5).n_nodes == expected


def test_extent_rounded_up_to_whole_elements():
    grid = Grid("q2", (0, 0), (1.5, 1.0), 0.5)  # 3 spacings: not a whole q2 element
    np.testing.assert_allclose(grid.upper, [2.0, 1.0])
    assert Grid("q1", (0, 0), (1.5, 1.0), 0.5).upper.tolist() == [1.5, 1.0]


@pytest.mark.parametrize("basis", BASIS_NAMES)
def test_points_outside_are_named(basis):
    grid = make_grid(basis)
    points = np.array([[0.0, 1.0], [3.5, 1.0], [0.0, 3.0], [np.nan, 1.0]])
    with pytest.raises(ValueError, match=r"3 of 4 points lie outside the grid .* the first is point 1 at \(3.5, 1\)"):
        grid.shape_functions(points)


def test_nodes_where():
    grid = Grid("bspline3", (0, 0), (2, 1), 0.5)
    left = grid.nodes_where("x <= 0")
    assert set(grid.nodes[left, 0]) == {-0.5, 0.0}  # boundary column and the extra one beyond
    assert len(left) == 2 * 5
    np.testing.assert_array_equal(grid.nodes_where(lambda x, y: x <= 0), left)
    both = grid.nodes_where("(x <= 0) or (x >= 2)")
    assert len(both) == 4 * 5
    with pytest.raises(ValueError, match="not allowed"):
        grid.nodes_where("x.__class__")


@pytest.mark.parametrize("kwargs,message", [
    (dict(basis="q3"), "unknown basis 'q3'"),
    (dict(spacing=0.0), "spacing must be a positive"),
    (dict(spacing=float("nan")), "spacing must be a positive"),
    (dict(upper=(0.0, 1.0)), "must exceed lower"),
    (dict(spacing=1e-5), "more than the limit"),
    (dict(spacing=True), "spacing must be a positive"),
    # node counts and areas must stay finite floats (these raised OverflowError)
    (dict(spacing=1e-300), "outside the supported range"),
    (dict(spacing=1e300), "outside the supported range"),
    (dict(lower=(-1e308, 0.0)), "lower .* outside the supported range"),
    # gimp divided by it: ZeroDivisionError, an IndexError later, or functions that did not sum to 1
    (dict(basis="gimp", points_per_cell=0), "points_per_cell must be a whole number, at least 1, got 0"),
    (dict(basis="gimp", points_per_cell=-1), "points_per_cell must be a whole number"),
    (dict(basis="gimp", points_per_cell=0.5), "points_per_cell must be a whole number"),
    (dict(basis="gimp", points_per_cell="2"), "points_per_cell must be a whole number"),
    (dict(basis="q1", points_per_cell=True), "points_per_cell must be a whole number"),
    (dict(lower=(0.0, 1j)), "lower must be two finite numbers"),  # its imaginary part was dropped
])
def test_bad_grid_arguments(kwargs, message):
    arguments = dict(basis="q1", lower=(0.0, 0.0), upper=(1.0, 1.0), spacing=0.5) | kwargs
    with pytest.raises(ValueError, match=message):
        Grid(**arguments)


def test_complex_points_are_refused():
    """Their imaginary part was dropped with a ComplexWarning only, as the corners' once was."""
    grid = Grid("q1", (0.0, 0.0), (1.0, 1.0), 0.5)
    with pytest.raises(ValueError, match="points must be real numbers, got complex128"):
        grid.shape_functions(np.array([[0.25 + 0.5j, 0.25]]))


@pytest.mark.parametrize("basis", BASIS_NAMES)
def test_matrices_survive_scipy_operations_on_each_other(basis):
    """scipy sorts indices in place (e.g. in abs()); no matrix may share index
    arrays with another (this once scrambled dNdx through abs(N))."""
    points = random_points(100)
    grid = make_grid(basis)
    N, dNdx, dNdy = grid.shape_functions(points)
    reference = [m.toarray() for m in (N, dNdx, dNdy)]
    for matrix in (N, dNdx, dNdy):
        abs(matrix)
        matrix.sort_indices()
    for matrix, expected in zip((N, dNdx, dNdy), reference):
        np.testing.assert_array_equal(matrix.toarray(), expected)


def test_open_knot_splines_interpolate_at_the_boundary():
    """On the domain's edge only the edge node's function is non-zero, and it is 1:
    fixing the nodes on x <= 0 holds the wall exactly (the paper's ghost column does not)."""
    grid = Grid("bspline3_open", (0.0, 0.0), (3.0, 2.0), 0.5)
    rng = np.random.default_rng(5)
    wall = np.column_stack([np.zeros(20), rng.uniform(0.0, 2.0, 20)])
    N, _, _ = grid.shape_functions(wall)
    on_wall = grid.nodes_where("x <= 0")
    np.testing.assert_allclose(N[:, on_wall].sum(axis=1), 1.0, atol=1e-13)
    off_wall = np.setdiff1d(np.arange(grid.n_nodes), on_wall)
    assert np.abs(N[:, off_wall]).max() < 1e-13
    ghost = Grid("bspline3", (0.0, 0.0), (3.0, 2.0), 0.5)
    N_ghost, _, _ = ghost.shape_functions(wall)
    assert N_ghost[:, ghost.nodes_where("x <= 0")].sum(axis=1).max() < 0.9  # 1/6 left to the next column


def test_open_knot_splines_equal_uniform_ones_in_the_interior():
    """Three or more cells from every boundary both variants are Eq. 23."""
    open_grid = Grid("bspline3_open", (0.0, 0.0), (5.0, 4.0), 0.5)
    ghost_grid = Grid("bspline3", (0.0, 0.0), (5.0, 4.0), 0.5)
    rng = np.random.default_rng(6)
    points = np.array([1.5, 1.5]) + rng.random((50, 2)) * [2.0, 1.0]
    for a, b in zip(open_grid.shape_functions(points), ghost_grid.shape_functions(points)):
        np.testing.assert_allclose(a.toarray(), b.toarray(), atol=1e-13)
    interior = "(x > 1) and (x < 4) and (y > 1) and (y < 3)"
    np.testing.assert_array_equal(open_grid.nodes[open_grid.nodes_where(interior)],
                                  ghost_grid.nodes[ghost_grid.nodes_where(interior)])


@pytest.mark.parametrize("basis", BASIS_NAMES)
def test_nodes_are_numbered_along_the_lattice(basis):
    """By x index, then y index (what the compiled kernels' arithmetic numbering assumes;
    scikit-fem numbers vertices, then edges by facet, then centres); for the scikit-fem
    bases ``dofs`` maps back to scikit-fem's numbering."""
    grid = make_grid(basis)
    x, y = grid.nodes[:, 0], grid.nodes[:, 1]
    np.testing.assert_array_equal(np.lexsort((y, x)), np.arange(grid.n_nodes))
    dofs = grid.discretization.dofs
    if basis in SKFEM_ELEMENTS:
        reference = skfem.CellBasis(grid.mesh, SKFEM_ELEMENTS[basis]())
        np.testing.assert_allclose(reference.doflocs.T[dofs], grid.nodes, rtol=0, atol=1e-12)
    else:
        assert dofs is None
