"""CG preconditioned by symmetric Gauss-Seidel in Eisenstat's form (:mod:`femgrid_mpm.mass.gauss_seidel`):
against the textbook iteration written with scipy's triangular solves, and against a direct solve."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from femgrid_mpm.mass.gauss_seidel import gauss_seidel_cg, sweeps_apply
from femgrid_mpm.mass.sparse import _CompiledCSR, upper_is_later
from helpers import advanced_benchmark_block

BASES = ["q1", "q2", "serendipity", "gimp", "bspline2"]


def system_of(basis):
    """A CG system of the benchmarks' block after 3 steps, and a right-hand side on its free rows."""
    mass = advanced_benchmark_block(basis, "cg", steps=3, n=400).mass
    system = mass._systems[0]
    rng = np.random.default_rng(7)
    rhs = np.where(system.excluded[:, None], 0.0, rng.standard_normal((system.matrix.shape[0], 2)))
    return system.matrix, rhs


def textbook(matrix, b, x0, rtol, max_iterations=500):
    """PCG with ``P = (D + L) D^-1 (D + U)`` applied by two triangular solves, stopped at
    ``max |P^-1 r| <= rtol max |x|`` per column: ``(x, iterations)``."""
    A = sp.csr_matrix(matrix)
    lower, upper, diagonal = sp.tril(A, format="csr"), sp.triu(A, format="csr"), A.diagonal()

    def precondition(r):
        return spla.spsolve_triangular(upper, diagonal[:, None] * spla.spsolve_triangular(lower, r, lower=True),
                                       lower=False)

    x = x0.copy()
    r = b - A @ x
    z = precondition(r)
    p, rz = z.copy(), (r * z).sum(axis=0)
    for iteration in range(max_iterations + 1):
        if np.all(np.abs(z).max(axis=0) <= rtol * np.abs(x).max(axis=0)):
            return x, iteration
        Ap = A @ p
        alpha = rz / (p * Ap).sum(axis=0)
        x, r = x + alpha * p, r - alpha * Ap
        z = precondition(r)
        rz_new = (r * z).sum(axis=0)
        p, rz = z + rz_new / rz * p, rz_new
    raise AssertionError("the textbook iteration did not converge")


@pytest.mark.parametrize("basis", BASES)
def test_eisenstat_form_is_the_textbook_iteration(basis):
    """Same iterations and the same solution to 1e-9 of its largest value: the form changes the
    work of an iteration (one pass over the matrix instead of a product and two solves), not CG."""
    matrix, rhs = system_of(basis)
    assert sweeps_apply(matrix)
    x, converged, iterations = gauss_seidel_cg(matrix, rhs, np.zeros_like(rhs), 1e-6, 500)
    reference, reference_iterations = textbook(matrix, rhs, np.zeros_like(rhs), 1e-6)
    assert converged and iterations == reference_iterations
    assert np.abs(x - reference).max() <= 1e-9 * np.abs(reference).max()


@pytest.mark.parametrize("basis", BASES)
def test_solution_against_a_direct_solve(basis):
    """Within 1e-4 of the largest velocity of SuperLU's solution (the test stops at 1e-6 of ``P^-1 r``,
    which bounds the error within the condition of ``P^-1 A``), from a guess and from zero."""
    matrix, rhs = system_of(basis)
    exact = spla.spsolve(sp.csc_matrix(matrix), rhs)
    for guess in (np.zeros_like(rhs), exact * 0.9):
        x, converged, _ = gauss_seidel_cg(matrix, rhs, guess, 1e-6, 500)
        assert converged and np.abs(x - exact).max() <= 1e-4 * np.abs(exact).max()


def test_a_zero_column_has_the_zero_solution():
    matrix, rhs = system_of("q1")
    rhs[:, 1] = 0.0
    x, converged, _ = gauss_seidel_cg(matrix, rhs, np.ones_like(rhs), 1e-6, 500)
    assert converged and not x[:, 1].any() and x[:, 0].any()


def test_sweeps_need_the_upper_triangle_after_each_diagonal():
    """A symmetric matrix stored with a lower entry after a row's diagonal is not swept (CG takes
    Jacobi on it): the sweeps would solve with another triangle than the product's."""
    ordered = _CompiledCSR(sp.csr_matrix(np.array([[2.0, 1.0, 0.0], [1.0, 2.0, 1.0], [0.0, 1.0, 2.0]])))
    ordered.upper_start = np.array([0, 3, 6])  # each row's diagonal entry
    assert upper_is_later(ordered.indptr, ordered.indices, ordered.upper_start)
    # row 1 stored as (diagonal, column 0, column 2): column 0 follows the diagonal
    swapped = _CompiledCSR((np.array([2.0, 1.0, 2.0, 1.0, 1.0, 1.0, 2.0]), np.array([0, 1, 1, 0, 2, 1, 2]),
                            np.array([0, 2, 5, 7])), shape=(3, 3))
    swapped.upper_start = np.array([0, 2, 6])
    assert not upper_is_later(swapped.indptr, swapped.indices, swapped.upper_start)
    ordered.upper_ordered = True
    assert sweeps_apply(ordered) and not sweeps_apply(swapped)
    # any CSR matrix with sorted columns and every diagonal stored is swept by its upper triangle
    # (the scipy path's); not one whose columns are unsorted, nor one without a diagonal entry
    assert sweeps_apply(sp.csr_matrix(ordered))
    unsorted = sp.csr_matrix((swapped.data, swapped.indices, swapped.indptr), shape=(3, 3))
    unsorted.has_sorted_indices = False
    assert not sweeps_apply(unsorted)
    assert not sweeps_apply(sp.csr_matrix(np.array([[0.0, 1.0], [1.0, 2.0]])))


def test_a_general_csr_matrix_is_solved_like_the_pattern_half():
    """The scipy path's CSR matrix (both halves stored, product row by row) against the pattern's
    half: the same iterations, the same solution to 1e-12 of its largest value."""
    matrix, rhs = system_of("q2")
    general = sp.csr_matrix(matrix)  # a product row by row: the full matrix, columns sorted
    general.sort_indices()
    half = gauss_seidel_cg(matrix, rhs, np.zeros_like(rhs), 1e-6, 500)
    full = gauss_seidel_cg(general, rhs, np.zeros_like(rhs), 1e-6, 500)
    assert half[1] and full[1] and half[2] == full[2]
    assert np.abs(half[0] - full[0]).max() <= 1e-12 * np.abs(half[0]).max()


def test_the_engines_stay_together_over_a_long_cg_run():
    """CG leaves error below its tolerance as it is, and each solve starts from the last ones:
    a first guess whose recursion amplifies what CG does not touch (the cubic through the last
    four accelerations grows it up to 1.4x a step) lets the two engines' round-off grow to CG's
    tolerance (1.3e-7 of the largest velocity here after 200 steps). The line through the last
    two does not: the serendipity bar with consistent mass, Gauss-Seidel CG and the centred
    scheme, numba against scipy, after 200 steps within 1e-12 (3e-15 measured)."""
    from femgrid_mpm.scene import bundled_scene
    from femgrid_mpm.solver import Simulation

    runs = [Simulation(bundled_scene("vibrating_bar").with_overrides(**{
        "grid.basis": "serendipity", "solver.mass": "consistent", "solver.linear_solver": "cg",
        "solver.scheme": "centred", "solver.engine": engine, "output": None})) for engine in ("numba", "scipy")]
    for _ in range(200):
        for simulation in runs:
            simulation.advance()
    numba, scipy_ = (simulation.particles.v for simulation in runs)
    assert np.abs(numba - scipy_).max() <= 1e-12 * np.abs(scipy_).max()
