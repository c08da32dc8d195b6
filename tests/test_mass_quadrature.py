"""The consistent mass and momentum by Gauss quadrature over the filled cells
(``[solver] mass_quadrature = "reconstructed"``, :class:`femgrid_mpm.quadrature.MassReconstruction`).

The points' sums are midpoint rules whose edge term leaves a second-order layer of error
along a free edge (docs/accuracy.md); integrated exactly over the filled cells, with the
force's reconstruction, the free bar converges at fourth order on the whole body.
"""

import numpy as np
import pytest
import scipy.sparse as sp

from femgrid_mpm import Grid
from femgrid_mpm.particles import seed_rectangle
from femgrid_mpm.quadrature import MassReconstruction
from femgrid_mpm.scene import SceneError
from femgrid_mpm.solver import Simulation
from helpers import bundled_variant

LOWER, UPPER, SPACING, DENSITY = (0.5, 0.0), (1.5, 0.75), 0.25, 1.3e3


def gauss_points(lower, upper, spacing, order=8):
    """Gauss points and weights of every cell of the rectangle, ``order`` per axis: exact for
    the products of two cubic pieces and a cubic field (degree 9 per axis)."""
    nodes, weights = np.polynomial.legendre.leggauss(order)
    xs = np.arange(lower[0], upper[0] - 1e-12, spacing)
    ys = np.arange(lower[1], upper[1] - 1e-12, spacing)
    cx, cy, gx, gy = np.meshgrid(xs, ys, nodes, nodes, indexing="ij")
    wx = np.broadcast_to(weights[None, None, :, None] * weights[None, None, None, :], cx.shape)
    points = np.column_stack([(cx + 0.5 * spacing * (gx + 1)).ravel(), (cy + 0.5 * spacing * (gy + 1)).ravel()])
    return points, (wx * (0.5 * spacing) ** 2).ravel()


def velocity_field(at, degree):
    """A tensor polynomial of the given degree in each direction, two components."""
    coefficients = np.random.default_rng(degree).normal(size=((degree + 1) ** 2, 2))
    terms = np.column_stack([at[:, 0] ** a * at[:, 1] ** b for a in range(degree + 1) for b in range(degree + 1)])
    return terms @ coefficients


@pytest.mark.parametrize("basis", ["q1", "q2", "serendipity", "bspline2_open", "bspline3", "bspline3_open"])
@pytest.mark.parametrize("points_per_cell", [2, 3, 4])
def test_the_mass_and_momentum_are_the_exact_integrals_over_the_filled_cells(basis, points_per_cell):
    """A block on grid lines (one edge on the grid's), uniform density: ``N^T diag(m) N`` from
    the Gauss rows equals ``int rho N_a N_b`` over the block (an 8-point Gauss rule per cell
    axis) to 1e-12 of its largest entry, and the momentum of a velocity field of the fit's
    degree equals ``int rho N_a v``; the points' own sums miss the mass by more than 1e-4 of it
    (q1 aside, whose products the sum over 2 x 2 or more points integrates exactly)."""
    grid = Grid(basis, (0.0, 0.0), (2.0, 1.0), SPACING)
    x, volume = seed_rectangle(LOWER, UPPER, SPACING, points_per_cell)
    volume = np.full(len(x), volume)
    mass, body = DENSITY * volume, np.zeros(len(x), dtype=int)
    degree = points_per_cell - 1
    N = grid.shape_functions(x)[0].tocsr()
    rows, masses, volumes, velocities = MassReconstruction(grid, degree).rows(
        x, volume, mass, body, velocity_field(x, degree), lambda summed: N[summed])
    assert rows.shape[0] == len(masses) == len(volumes) == len(velocities)
    gauss, weights = gauss_points(LOWER, UPPER, SPACING)
    G = grid.shape_functions(gauss)[0].tocsr()
    exact = (G.T @ sp.diags(DENSITY * weights) @ G).toarray()
    assembled = (rows.T @ sp.diags(masses) @ rows).toarray()
    np.testing.assert_allclose(assembled, exact, rtol=0, atol=1e-12 * np.abs(exact).max())
    exact_momentum = G.T @ (DENSITY * weights[:, None] * velocity_field(gauss, degree))
    np.testing.assert_allclose(rows.T @ (masses[:, None] * velocities), exact_momentum, rtol=0,
                               atol=1e-12 * np.abs(exact_momentum).max())
    assert np.sum(volumes) == pytest.approx((UPPER[0] - LOWER[0]) * (UPPER[1] - LOWER[1]), rel=1e-12)
    if basis != "q1":  # the points' sum, a midpoint rule, is not exact for products of higher pieces
        points_sum = (N.T @ sp.diags(mass) @ N).toarray()
        assert np.abs(points_sum - exact).max() > 1e-4 * np.abs(exact).max()


def bar_errors(spacing: float, **solver) -> tuple[float, float]:
    """The free bar's exact first mode (nu = 0), consistent cubic splines, 4 x 4 points,
    ``scheme = "yoshida4"`` at ``dt = "auto"``, to t = 1 s, with the updated-Lagrangian term
    removed: ``2 u(A) - u(2 A)`` at A = 1e-4 m/s (the motion's departure from the linear mode is
    linear in A; the position round-off at so small an amplitude as would make it negligible
    is not).  Returns the RMS of the error over the whole bar relative to the amplitude, and
    the largest within one cell of its ends."""
    w = 1.9869176531592203
    shapes = []
    for amplitude in (1e-4, 2e-4):
        current = bundled_variant("vibrating_bar_exact", "bspline3", "consistent", **{
            "solver.scheme": "yoshida4", "grid.spacing": spacing, "time.end": 1.0, "output": None,
            "bodies.0.points_per_cell": 4, "bodies.0.velocity": [f"{amplitude}*cos(pi*x/5)", "0"],
            "reference.constants": {"A": amplitude, "L": 5.0, "w": w}, **{f"solver.{k}": v for k, v in solver.items()}})
        simulation = Simulation(current)
        p = simulation.run().particles
        shapes.append((p.x - p.x0) / (amplitude / w))
    linear = 2 * shapes[0] - shapes[1]
    exact = np.cos(np.pi * p.x0[:, 0] / 5) * np.sin(w * simulation.end_time)
    error = np.hypot(linear[:, 0] - exact, linear[:, 1])
    ends = np.minimum(p.x0[:, 0], 5 - p.x0[:, 0])
    return float(np.sqrt(np.mean(error**2))), float(error[ends < spacing].max())


def test_the_free_bar_converges_at_fourth_order_with_the_mass_and_force_reconstructed():
    """With the points' sums the bar's ends err at second order (the whole bar's RMS at 2.5:
    8.19e-5 -> 1.43e-5 from h = 0.5 to 0.25, ratio 5.7); with the mass, momentum and force
    integrated over the cells the error falls 16 times (5.44e-6 -> 3.42e-7, order 4.0), at the
    ends as inside (7.27e-6 -> 4.79e-7): both ratios above 8 (third order), and the error at
    h = 0.5 below a tenth of the points' sums'."""
    reconstructed = {"force_quadrature": "reconstructed", "mass_quadrature": "reconstructed"}
    whole_coarse, ends_coarse = bar_errors(0.5, **reconstructed)
    whole_fine, ends_fine = bar_errors(0.25, **reconstructed)
    assert whole_coarse / whole_fine > 8, (whole_coarse, whole_fine)
    assert ends_coarse / ends_fine > 8, (ends_coarse, ends_fine)
    points_coarse, _ = bar_errors(0.5)
    assert whole_coarse < 0.1 * points_coarse, (whole_coarse, points_coarse)


def test_the_engines_agree_with_the_reconstructed_mass():
    """scipy and numba, 40 steps of the bar at h = 0.5 with the mass and the force
    reconstructed, each system factored (CG would stop at its tolerance on its own path): the same velocities and stresses to 1e-12 of each's largest, and positions to
    1e-12 of the coordinates (the displacements, ~1e-6 m, are at the coordinates' round-off)."""
    results = {}
    for engine in ("scipy", "numba"):
        current = bundled_variant("vibrating_bar_exact", "bspline3", "consistent", **{
            "solver.engine": engine, "solver.mass_quadrature": "reconstructed", "solver.linear_solver": "direct",
            "bodies.0.points_per_cell": 4,
            "solver.force_quadrature": "reconstructed", "time.dt": 0.005, "time.end": 0.2, "output": None})
        results[engine] = Simulation(current).run().particles
    for name, of in (("position", lambda p: p.x), ("velocity", lambda p: p.v), ("stress", lambda p: p.stress)):
        reference = of(results["scipy"])
        np.testing.assert_allclose(of(results["numba"]), reference, rtol=0, atol=1e-12 * np.abs(reference).max(),
                                   err_msg=name)


@pytest.mark.parametrize("changes, message", [
    ({"solver.mass": "lumped"}, "solver.mass_quadrature: 'reconstructed' integrates the consistent mass"),
    ({"grid.basis": "gimp"}, "solver.mass_quadrature: 'reconstructed' needs functions that are polynomials"),
    ({"bodies.0.points_per_cell": 1}, "solver.mass_quadrature: 'reconstructed' needs points_per_cell >= 4"),
    ({"bodies.0.points_per_cell": 3}, "solver.mass_quadrature: 'reconstructed' needs points_per_cell >= 4 with bspline3"),
    ({"grid.basis": "q2", "bodies.0.points_per_cell": 2}, "needs points_per_cell >= 3 with q2"),
])
def test_a_scene_whose_mass_cannot_be_reconstructed_is_refused_in_one_line(changes, message):
    with pytest.raises(SceneError, match=message.replace("(", r"\(")) as error:
        bundled_variant("vibrating_bar_exact", "bspline3", "consistent",
                        **{"solver.mass_quadrature": "reconstructed", **changes})
    assert "\n" not in str(error.value)
