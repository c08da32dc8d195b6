"""The consistent mass solved by CG preconditioned by kept factors ("auto" below the direct
limit, on systems too large to factor every step): the solution against a direct solve of the
same matrix, and the refactor triggers.  The blocks here are small enough for q1 and q2 to be
factored every step (:mod:`femgrid_mpm.mass.ldl`), which :func:`kept_factors_only` turns off."""

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from femgrid_mpm.mass import layout, ldl, trial
from femgrid_mpm.mass.direct import _factor
from femgrid_mpm.mass.reused import REFACTOR_ITERATIONS, ReusedFactors
from femgrid_mpm.mass.gauss_seidel import cg_work
from femgrid_mpm.mass.trial import (ANALYSIS_WORK, FACTOR_ENTRY_WORK, RATE_LIMIT, RATE_WINDOW, TRY_ITERATIONS,
                                    FactoredRate, RefactorRate, kept_work)
from femgrid_mpm.scene import bundled_scene
from femgrid_mpm.solver import Simulation
from helpers import advanced_benchmark_block, benchmark_block



@pytest.fixture(autouse=True)
def kept_factors_only(monkeypatch):
    monkeypatch.setattr(ldl, "EVERY_STEP_NODES", 0)


def advanced(basis, linear_solver="auto", steps=6, n=100):
    return advanced_benchmark_block(basis, linear_solver, steps, n)


@pytest.mark.parametrize("basis", ["q1", "q2", "bspline3"])
def test_kept_factors_solve_to_the_tolerance_of_a_direct_solve(basis):
    """A later step's matrix solved with the first step's factors: the error against scipy's
    sparse LU of the same matrix within twice the tolerance of the largest velocity at every
    node (the criterion is the preconditioned residual, ``M_0^-1 r``, which estimates the
    error as closely as ``M_0`` is close to ``M``)."""
    simulation = advanced(basis)
    mass = simulation.mass
    system = mass._systems[0]
    assert system.kept is not None  # the steps after the first reuse the factors
    matrix = sp.csr_matrix(system.matrix)
    rng = np.random.default_rng(1)
    rhs = np.where(system.excluded[:, None], 0.0, rng.normal(size=(matrix.shape[0], 2)))
    reference = spla.spsolve(sp.csc_matrix(matrix), rhs)
    solution, converged, iterations = system.kept.solve(system.matrix, rhs, np.zeros_like(rhs), mass.tolerance)
    assert converged  # a random right-hand side from zero: a few iterations
    error = np.abs(solution - reference).max(axis=0)
    assert np.all(error <= 2 * mass.tolerance * np.abs(reference).max(axis=0))


def test_applying_kept_factors_is_superlus_solve():
    simulation = advanced("q1", steps=1)
    system = simulation.mass._systems[0]
    factors = _factor(system.matrix)
    kept = ReusedFactors.of(factors, system.excluded, np.zeros(len(system.excluded), bool), system.columns)
    vector = np.random.default_rng(2).normal(size=(system.matrix.shape[0], 2))
    np.testing.assert_allclose(kept.apply(vector), factors.solve(vector), rtol=1e-12, atol=1e-12 * np.abs(
        factors.solve(vector)).max())


def test_factors_of_another_matrix_go_stale():
    """Factors of a matrix far from the one solved take more than REFACTOR_ITERATIONS: stale,
    and the model then factors its own matrix."""
    simulation = advanced("q1", steps=2)
    mass = simulation.mass
    system = mass._systems[0]
    matrix = sp.csr_matrix(system.matrix)
    kept_nodes = ~system.excluded
    # the same structure, every coupling halved and the diagonal doubled: far from M
    other = sp.csr_matrix(0.5 * matrix + sp.diags(np.where(kept_nodes, 1.5 * matrix.diagonal(), 0.0)))
    kept = ReusedFactors.of(_factor(other), system.excluded, mass._weak, system.columns)
    rhs = np.where(system.excluded[:, None], 0.0, np.ones((matrix.shape[0], 2)))
    solution, converged, iterations = kept.solve(system.matrix, rhs, np.zeros_like(rhs), mass.tolerance)
    assert iterations > REFACTOR_ITERATIONS and kept.stale
    assert not kept.fits(system.excluded, mass._weak, system.columns)
    # the model's own: a stale factorization is replaced at the next step
    mass._kept[tuple(system.columns)] = kept
    simulation.advance()
    system = mass._systems[0]
    assert system.kept is None and system.factors is not None
    assert mass._kept[tuple(system.columns)] is not kept and not mass._kept[tuple(system.columns)].stale


def test_factors_do_not_fit_another_set_of_excluded_or_weak_nodes():
    simulation = advanced("q1", steps=2)
    mass = simulation.mass
    system = mass._systems[0]
    kept = mass._kept[tuple(system.columns)]
    assert kept.fits(system.excluded, mass._weak, system.columns)
    excluded = system.excluded.copy()
    excluded[np.flatnonzero(~excluded)[0]] = True
    assert not kept.fits(excluded, mass._weak, system.columns)
    weak = mass._weak.copy()
    weak[0] = not weak[0]
    assert not kept.fits(system.excluded, weak, system.columns)


@pytest.mark.parametrize("basis", ["q1", "serendipity", "bspline3"])
def test_a_run_with_kept_factors_stays_near_the_direct_one(basis):
    """The first RATE_WINDOW steps of the block (CG is tried only after them): the points'
    velocities within 1e-4 of the largest one against the direct solver's (which factors every
    step); the kept factors were refactored only rarely."""
    direct, kept = advanced(basis, "direct", RATE_WINDOW), advanced(basis, "auto", RATE_WINDOW)
    scale = np.abs(direct.particles.v).max()
    assert np.abs(kept.particles.v - direct.particles.v).max() <= 1e-4 * scale
    assert kept.mass._choices.trial.start is None and kept.mass._direct
    assert kept.mass.iterations <= 2 * RATE_WINDOW * REFACTOR_ITERATIONS


def free_block_fill(system) -> float:
    """SuperLU's entries per nonzero entry of the system's free rows, factoring those rows alone."""
    free = np.flatnonzero(~system.excluded)
    block = sp.csc_matrix(sp.csr_matrix(system.matrix)[free][:, free])
    block.eliminate_zeros()
    return _factor(block).nnz / block.nnz


def test_tensor_cg_takes_the_layouts_whose_factors_fill_more_than_the_limit(monkeypatch):
    """With the limit lowered below the small block's fill, "auto" on cubic splines solves by CG on
    the tensor preconditioner (no factors kept), its velocities after 30 steps within 1e-4 of the
    largest against the direct solver's; q1 (no tensor preconditioner) keeps its factors."""
    monkeypatch.setattr(layout, "FILL_LIMIT", 0.5)
    direct, tensor = advanced("bspline3", "direct", 30, n=400), advanced("bspline3", "auto", 30, n=400)
    assert not tensor.mass._layout.direct and not tensor.mass._kept
    assert all(system.factors is None and system.kept is None for system in tensor.mass._systems)
    assert tensor.mass.iterations > 0
    scale = np.abs(direct.particles.v).max()
    assert np.abs(tensor.particles.v - direct.particles.v).max() <= 1e-4 * scale
    q1 = advanced("q1", "auto", 3, n=400)
    assert q1.mass._layout.direct and q1.mass._systems[0].kept is not None


@pytest.mark.parametrize("case, chosen", [("square", "cg"), ("bar", "factors")])
def test_the_fill_decides_between_kept_factors_and_tensor_cg(case, chosen):
    """Cubic splines at ~1e4 points: the square block (2,809 active nodes) fills its factors more
    than FILL_LIMIT and takes CG, the bar at h = 0.0625 (1,577 active nodes, a beam 16 elements
    deep) less and keeps them.  The fill against SuperLU's of the free rows alone, within 5%."""
    from femgrid_mpm.scene import bundled_scene
    from femgrid_mpm.solver import Simulation

    if case == "square":
        simulation = advanced("bspline3", "auto", 1, n=10_000)
    else:
        simulation = Simulation(bundled_scene("vibrating_bar").with_overrides(
            **{"grid.basis": "bspline3", "grid.spacing": 0.0625, "solver.mass": "consistent"}))
        simulation.advance()
    mass = simulation.mass
    system = mass._systems[0]
    factors = system.factors if system.factors is not None else _factor(system.matrix)
    measured = layout._fill(dataclasses.replace(system, factors=factors))
    assert measured == pytest.approx(free_block_fill(system), rel=0.05)
    assert (measured > layout.FILL_LIMIT) == (chosen == "cg") == (not mass._layout.direct)


def test_kept_ldl_factors_are_d_l_transpose_exactly():
    """The upper factor kept from a compiled ``L D L^T`` is ``D L^T`` entry for entry (scipy's
    transpose and product as the reference), its columns' rows increasing."""
    simulation = advanced("bspline3", steps=2, n=400)
    mass = simulation.mass
    system = mass._systems[0]
    symbolic = ldl.SymbolicLDL.analyse(system.matrix.indptr, system.matrix.indices, system.matrix.upper_start,
                                       system.excluded)
    factors, _ = symbolic.factor(system.matrix.data)
    kept = ReusedFactors.of_ldl(factors, system.excluded, mass._weak, (0, 1))
    n = len(system.excluded)
    lower = sp.csc_matrix((kept.lower[2], kept.lower[1], kept.lower[0]), shape=(n, n))
    upper = sp.csc_matrix((kept.upper[2], kept.upper[1], kept.upper[0]), shape=(n, n))
    reference = sp.csc_matrix(lower.T.multiply(kept.upper_diagonal[:, None]))
    assert (upper != reference).nnz == 0
    assert all(np.all(np.diff(upper.indices[upper.indptr[j]:upper.indptr[j + 1]]) > 0) for j in range(n))


def test_refactor_rate_switches_at_its_limit():
    """Eight refactorizations in a window of twenty steps switch to factoring every step, seven do not;
    the count starts again with each window and comes back from a checkpoint's values."""
    assert (RATE_WINDOW, RATE_LIMIT) == (20, 0.4)
    below, at = RefactorRate(), RefactorRate()
    for step in range(RATE_WINDOW):
        below.observe(step < 7)
        at.observe(step >= 12)
    assert not below.stale and at.stale
    below.observe(True)
    assert (below.steps, below.refactors) == (1, 1)
    assert RefactorRate.restored(below.values()) == below and RefactorRate.restored(None) == RefactorRate()


def test_refactor_rate_measures_the_kept_factors_work_a_step():
    """Five iterations and two solves a step on factors of fill 1, no refactorization: each step costs
    ``kept_work(2, 5, 0, 1) = 7 (1 + 1.1) = 14.7`` products in every window.  The rate is observed at a step's start,
    so a window that begins with a count holds one step fewer of iterations (the first, and the one
    after CG, :meth:`restart`), as does the rest of a window resumed from an older checkpoint."""
    assert FACTOR_ENTRY_WORK == 1.1 and kept_work(2, 5, 0, 1.0) == pytest.approx(14.7, rel=1e-12)

    def run(rate, steps, iterations):
        for _ in range(steps):
            rate.observe(False, iterations, 2, 1.0)
            iterations += 5
        return iterations

    rate = RefactorRate()
    iterations = run(rate, RATE_WINDOW, 100)
    assert rate.per_step == pytest.approx(14.7, rel=1e-12)
    rate.per_step = None
    iterations = run(rate, RATE_WINDOW, iterations)
    assert rate.per_step == pytest.approx(14.7, rel=1e-12)
    rate.restart()
    rate.per_step = None
    run(rate, RATE_WINDOW, iterations)
    assert rate.per_step == pytest.approx(14.7, rel=1e-12)
    older = RefactorRate.restored([10, 0, False])  # a window half done, its iterations not known
    run(older, RATE_WINDOW - 10, 0)
    assert older.per_step == pytest.approx(14.7, rel=1e-12) and older.steps == 0


def against_direct(scene, windows: int = 2) -> Simulation:
    """The scene after ``windows`` windows of the refactor rate with "auto", checked within 1e-4 of
    the largest velocity of the direct solver's."""
    runs = {}
    for solver in ("direct", "auto"):
        simulation = Simulation(scene.with_overrides(**{"solver.linear_solver": solver}))
        for _ in range(windows * RATE_WINDOW + 5):
            simulation.advance()
        runs[solver] = simulation
    scale = np.abs(runs["direct"].particles.v).max()
    assert np.abs(runs["auto"].particles.v - runs["direct"].particles.v).max() <= 1e-4 * scale
    return runs["auto"]


GIMP_BLOCK = benchmark_block("gimp", "consistent", 1000).with_overrides(**{"solver.weak_fraction": 0.1})


def test_small_systems_whose_kept_factors_go_stale_are_factored_every_step(monkeypatch):
    """GIMP's block at 1e3 points remakes its kept factors at most steps: within two windows the small
    system is factored every step (its own factors, none kept), and the run stays within 1e-4 of the
    direct solver's; cubic splines' factors last, and stay kept."""
    monkeypatch.setattr(ldl, "EVERY_STEP_NODES", 1500)  # the fixture's 0 would leave no small system
    mass = against_direct(GIMP_BLOCK).mass
    assert mass._choices.rate.stale
    system = mass._systems[0]
    assert system.ldl is not None and system.kept is None and not mass._kept
    splines = advanced("bspline3", "auto", 2 * RATE_WINDOW + 5, n=1000)
    assert not splines.mass._choices.rate.stale and splines.mass._systems[0].kept is not None


def test_kept_factors_dearer_than_cg_give_way_to_it():
    """The same block with no small system (the fixture): its SuperLU factors, made again at most
    steps, cost more than CG on symmetric Gauss-Seidel; within two windows the run solves by CG
    (no factors, none kept; GIMP's block at 1e4 points 13.2 -> 4.0 ms a step), which after
    another costs less than the factors did (CgTrial) and stays, within 1e-4 of the largest
    velocity of the direct solver's.  q1's on the clamped cantilever take one iteration an
    acceleration and are not remade: they cost less than CG and stay kept."""
    mass = against_direct(GIMP_BLOCK, windows=3).mass
    trial = mass._choices.trial
    assert trial.verdict is True and not mass._direct and not mass._kept
    assert trial.fill > 1 and trial.steps == RATE_WINDOW
    assert all(system.factors is None and system.ldl is None for system in mass._systems)
    cantilever = bundled_scene("cantilever").with_overrides(**{
        "grid.basis": "q1", "grid.spacing": 0.25, "solver.mass": "consistent"})
    lasting = against_direct(cantilever, windows=3).mass
    assert lasting._choices.trial.verdict is False and lasting._direct and lasting._systems[0].kept is not None


def test_stale_cg_that_costs_more_than_the_factors_goes_back_to_them():
    """Quadratic splines on the drifting bar (h = 0.125, 374 free nodes, SuperLU by the fixture):
    their kept factors go stale, CG costs more than they did in its trial window (on the bar at
    h = 0.04 Jacobi took 109 iterations a solve, 47 against 21 ms a step), and the run goes back
    to kept factors for good, within 1e-4 of the direct solver's."""
    scene = bundled_scene("drifting_bar").with_overrides(**{
        "grid.basis": "bspline2", "grid.spacing": 0.125, "solver.mass": "consistent", "solver.weak_fraction": 0.1,
        "solver.negative_mass": "warn", "solver.consistent_fallback": "blend"})
    mass = against_direct(scene, windows=3).mass
    trial = mass._choices.trial
    assert mass._choices.rate.stale and trial.verdict is False and mass._direct and mass._kept


def test_kept_factors_that_go_stale_after_a_lost_trial_are_tried_again():
    """q1 on the clamped cantilever (h = 0.25): its first trial of CG is lost (kept factors cost
    less); if the kept factors then go stale (set here: remade at 8 or more of 20 steps), CG is
    tried once more, and that trial is the last."""
    cantilever = bundled_scene("cantilever").with_overrides(**{
        "grid.basis": "q1", "grid.spacing": 0.25, "solver.mass": "consistent"})
    simulation = Simulation(cantilever)
    for _ in range(2 * RATE_WINDOW + 5):
        simulation.advance()
    choices = simulation.mass._choices
    assert choices.trial.verdict is False and not choices.trial.stale and simulation.mass._direct
    choices.rate.stale = True
    for _ in range(RATE_WINDOW + 5):
        simulation.advance()
    assert choices.trial.stale and choices.trial.start is not None and choices.trial.verdict is not None



def test_factored_rate_counts_the_analyses_of_new_layouts():
    """Two products a step of factorization and solves on one layout for 25 steps, another for 5,
    a third for 10: its first layout is not counted (any solver's first step makes one), the two
    after it are, 140 products a system: 2 products a step after the first window, ``(40 * 2 + 2 *
    140) / 40 = 9`` after the second (the run's average), twice the analyses with two systems.  CG
    is tried above its work at TRY_ITERATIONS a solve (two solves: ``2 * 2 + 1.4 * 11 = 19.4``), and
    only if the last step was factored every step."""
    rate, two = FactoredRate(), FactoredRate()
    for step in range(2 * RATE_WINDOW):
        layout = "first" if step < 25 else "second" if step < 30 else "third"
        rate.observe(layout, 1, 2.0)
        two.observe(layout, 2, 4.0)
        if step == RATE_WINDOW - 1:
            assert rate.per_step == 2.0
    assert ANALYSIS_WORK == 140 and rate.per_step == 9.0 and two.analyses == 4 and two.per_step == 18.0
    assert cg_work(2, 2 * TRY_ITERATIONS) == pytest.approx(19.4, rel=1e-12) and not rate.pays_to_try(2)
    rate.per_step = 19.3
    assert not rate.pays_to_try(2)
    rate.per_step = 19.5
    assert rate.pays_to_try(2)
    rate.last = False
    assert not rate.pays_to_try(2)
    assert FactoredRate.restored(rate.values()) == rate and FactoredRate.restored(None) == FactoredRate()


def test_systems_factored_every_step_whose_layouts_keep_changing_give_way_to_cg(monkeypatch):
    """GIMP's block at 1e3 points with ``dt = "auto"``: its small system is factored every step
    (its kept factors went stale), but the points make a new layout at 4 of the steps 21-80, each
    analysed afresh (140 products): 26.0 products a step against CG's 19.4 at 5.5 iterations a
    solve, so CG is tried at step 81 and, at 17.9 products a step, stays (the run's wall time
    389-448 -> 274-336 ms); within 1e-4 of the largest velocity of the direct solver's.  q1's
    block analyses once: 7.6 products a step, factored every step to the end."""
    monkeypatch.setattr(ldl, "EVERY_STEP_NODES", 1500)  # the fixture's 0 would leave no small system
    scene = benchmark_block("gimp", "consistent", 1000).with_overrides(**{"time.dt": "auto"})
    mass = against_direct(scene, windows=6).mass
    choices = mass._choices
    assert choices.factored.analyses >= 4 and choices.factored.pays_to_try(2)
    assert choices.trial.factored and choices.trial.verdict is True and not mass._direct
    assert all(system.ldl is None and system.factors is None for system in mass._systems)
    q1 = Simulation(benchmark_block("q1", "consistent", 1000).with_overrides(**{"time.dt": "auto"}))
    for _ in range(6 * RATE_WINDOW + 5):
        q1.advance()
    assert q1.mass._choices.factored.per_step < 10 and q1.mass._choices.trial.start is None
    assert q1.mass._direct and q1.mass._systems[0].ldl is not None


def test_a_lost_trial_against_systems_factored_every_step_goes_back_to_them(monkeypatch):
    """q1's block at 1e3 points factored every step (7.6 products a step), tried on CG with the
    threshold set to no iteration at all (4 products): CG's 20 steps cost more (16.7 a
    step), and the run goes back to factoring every step for good, its layout analysed again,
    within 1e-4 of the largest velocity of the direct solver's."""
    monkeypatch.setattr(ldl, "EVERY_STEP_NODES", 1500)  # the fixture's 0 would leave no small system
    monkeypatch.setattr(trial, "TRY_ITERATIONS", 0.0)
    scene = benchmark_block("q1", "consistent", 1000).with_overrides(**{"time.dt": "auto"})
    mass = against_direct(scene, windows=3).mass
    choices = mass._choices
    assert choices.trial.factored and choices.trial.steps == RATE_WINDOW and choices.trial.verdict is False
    assert mass._direct and mass._layout.small and mass._systems[0].ldl is not None
