"""The compiled L D L^T that factors small consistent-mass systems every step ("auto" below the
direct limit): its solution against scipy's sparse LU of the same matrix, its pivots' test of
singularity, which systems it takes, and a run with it against the direct solver's."""


import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from femgrid_mpm.mass import ldl
from femgrid_mpm.mass.direct import _factor
from femgrid_mpm.mass.trial import factored_work
from helpers import advanced_benchmark_block


def advanced(basis, linear_solver="auto", steps=3, n=1000):
    return advanced_benchmark_block(basis, linear_solver, steps, n)


@pytest.mark.parametrize("basis", ["q1", "q2", "serendipity", "bspline3", "gimp", "bspline2_open"])
def test_factors_solve_as_superlu_does(basis):
    """Every basis' system (factored by SuperLU in "direct"), refactored here: the solution
    within 1e-12 of the largest of scipy's sparse LU solve, zero on the excluded nodes."""
    system = advanced(basis, "direct", steps=2, n=300).mass._systems[0]
    matrix = system.matrix
    symbolic = ldl.SymbolicLDL.analyse(matrix.indptr, matrix.indices, matrix.upper_start, system.excluded)
    factors, weakest = symbolic.factor(matrix.data)
    assert factors is not None and weakest is None
    rhs = np.where(system.excluded[:, None], 0.0, np.random.default_rng(3).normal(size=(matrix.shape[0], 2)))
    reference = spla.spsolve(sp.csc_matrix(matrix), rhs)
    solution = factors.solve(rhs)
    assert np.abs(solution - reference).max() <= 1e-12 * np.abs(reference).max()
    assert not solution[system.excluded].any()


def test_a_singular_matrix_is_found_by_its_pivots():
    """A path's graph Laplacian (positive semi-definite, constants in its null space): a pivot
    falls below PIVOT_RATIO of its diagonal entry, as SuperLU's does in the direct solver."""
    n = 12
    laplacian = sp.diags([-np.ones(n - 1), np.r_[1.0, 2.0 * np.ones(n - 2), 1.0], -np.ones(n - 1)],
                         [-1, 0, 1], format="csr")
    laplacian.sort_indices()
    diagonal_index = np.array([laplacian.indptr[i] + list(laplacian.indices[laplacian.indptr[i]:laplacian.indptr[i + 1]])
                               .index(i) for i in range(n)])
    excluded = np.zeros(n, dtype=bool)
    symbolic = ldl.SymbolicLDL.analyse(laplacian.indptr, laplacian.indices, diagonal_index, excluded)
    factors, weakest = symbolic.factor(laplacian.data)
    assert factors is None and 0 <= weakest < n
    assert _factor(laplacian) is None
    # the same with one node held (a Dirichlet row): definite, and solved exactly
    excluded[0] = True
    held = laplacian.tolil()
    held[0, :], held[:, 0], held[0, 0] = 0.0, 0.0, 1.0
    held = sp.csr_matrix(held)
    symbolic = ldl.SymbolicLDL.analyse(laplacian.indptr, laplacian.indices, diagonal_index, excluded)
    factors, _ = symbolic.factor(laplacian.data)
    rhs = np.r_[0.0, np.ones(n - 1)][:, None]
    np.testing.assert_allclose(factors.solve(rhs), spla.spsolve(sp.csc_matrix(held), rhs)[:, None], rtol=1e-12)


def test_small_systems_are_factored_every_step_and_large_fills_are_not():
    """At 1e3 points q1, q2 and serendipity are factored every step (their numeric pass 15-18
    times L's entries); cubic splines (58) keep their factors as CG's preconditioner."""
    for basis in ("q1", "q2", "serendipity"):
        system = advanced(basis).mass._systems[0]
        assert system.layout.every_step and system.ldl is not None and system.kept is None
    mass = advanced("bspline3").mass
    assert not mass._layout.small[(0, 1)].every_step and mass._systems[0].kept is not None


def test_kept_factors_from_the_compiled_factorization():
    """Cubic splines at 1e3 points keep the L D L^T of the step that factored (as ``U = D L^T``
    and one permutation): applied, they are its solve to 1e-12; a later step's matrix solved
    with them by CG is scipy's sparse LU solve within twice the tolerance of the largest."""
    simulation = advanced("bspline3", steps=1)
    mass = simulation.mass
    system = mass._systems[0]
    assert system.layout is not None and system.ldl is not None  # the first step factors
    kept = mass._kept[(0, 1)]
    np.testing.assert_array_equal(kept.row_permutation, kept.column_permutation)
    rhs = np.where(system.excluded[:, None], 0.0, np.random.default_rng(4).normal(size=(len(system.excluded), 2)))
    exact = system.ldl.solve(rhs)
    assert np.abs(kept.apply(rhs) - exact).max() <= 1e-12 * np.abs(exact).max()
    for _ in range(4):
        simulation.advance()
    system = mass._systems[0]
    assert system.kept is kept and system.layout is None
    reference = spla.spsolve(sp.csc_matrix(system.matrix), rhs)
    solution, converged, _ = kept.solve(system.matrix, rhs, np.zeros_like(rhs), mass.tolerance)
    assert converged
    assert np.all(np.abs(solution - reference).max(axis=0) <= 2 * mass.tolerance * np.abs(reference).max(axis=0))


@pytest.mark.parametrize("basis", ["q1", "q2", "serendipity"])
def test_a_run_factored_every_step_is_the_direct_solvers(basis):
    """30 steps of the block: the points' velocities and positions within 1e-12 of the
    largest of the direct solver's (SuperLU every step), and no CG iteration."""
    direct, every = advanced(basis, "direct", 30), advanced(basis, "auto", 30)
    scale = np.abs(direct.particles.v).max()
    assert np.abs(every.particles.v - direct.particles.v).max() <= 1e-12 * scale
    assert np.abs(every.particles.x - direct.particles.x).max() <= 1e-12
    assert every.mass.iterations == 0


def test_a_layouts_systems_factored_every_step_follow_its_small_layouts():
    """What ``SystemsLayout`` keeps for its small systems' layouts (the systems factored every
    step, their work) is theirs: the same as found afresh, and found again when they are replaced."""
    layout = advanced("q1").mass._layout
    small = layout.small
    assert layout.every_step() == {(0, 1)} and layout.every_step(stale=True) == {(0, 1)}
    assert layout.factored_work() == factored_work(small[(0, 1)], 2) > 0
    layout.small = {}  # a new layout analysis with no small system
    assert layout.every_step() == frozenset() and layout.factored_work() == 0
    layout.small = small
    assert layout.every_step() == {(0, 1)} and layout.factored_work() == factored_work(small[(0, 1)], 2)
