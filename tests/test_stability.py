"""The critical time step from M^-1 K is tight: 0.9 of it runs, 1.1 of it blows up.

Each case runs 400 steps from the scene's own start; an unstable mode grows
by a factor ~2.4 per step at 1.1 x critical (omega dt = 2.2), so round-off
reaches order one well within that.
"""

import numpy as np
import pytest

from femgrid_mpm.diagnostics import SimulationStopped
from femgrid_mpm.scene import bundled_scene
from femgrid_mpm.solver import Simulation
from femgrid_mpm.stability import bloch_time_step
from helpers import bundled_variant

CASES = [
    ("vibrating_bar", "q1", "lumped"),
    ("vibrating_bar", "bspline3", "lumped"),
    ("vibrating_bar", "serendipity", "lumped"),
    ("vibrating_bar", "q2", "consistent"),
    ("cantilever", "q2", "lumped"),
    ("cantilever", "bspline3", "consistent"),
    ("cantilever", "bspline3_open", "lumped"),
    # the Jacobi-corrected lumped inverse A_k: its inverse mass A_k M_C A_k (.mass.iterated)
    ("vibrating_bar", "bspline3", "iterated"),
    ("cantilever", "bspline3", "iterated"),
    ("vibrating_bar", "q1", "iterated"),
]


def scene(name, basis, mass, **overrides):
    return bundled_variant(name, basis, mass, "warn", **overrides)


def grows(name, basis, mass, factor, **overrides) -> bool:
    """Whether 400 steps at factor x critical blow up (stop, or speeds 1e3 x the start)."""
    critical = Simulation(scene(name, basis, mass, **overrides)).critical_dt
    simulation = Simulation(scene(name, basis, mass, **{"time.dt": factor * critical, "time.end": 400 * factor * critical,
                                                        "output": None, **overrides}))
    try:
        simulation.run()
    except SimulationStopped:
        return True
    start_speed = max(0.01, 1e-3)  # the bar starts at 0.01 m/s; the cantilever at rest
    return bool(np.abs(simulation.particles.v).max() > 1e3 * start_speed or not np.isfinite(simulation.particles.v).all())


@pytest.mark.parametrize("name,basis,mass", CASES)
def test_critical_time_step_is_tight(name, basis, mass):
    assert not grows(name, basis, mass, 0.9)
    assert grows(name, basis, mass, 1.1)


@pytest.mark.parametrize("basis, mass", [("q1", "lumped"), ("q2", "consistent")])
def test_the_fourth_order_scheme_has_its_own_tight_critical_step(basis, mass):
    """``scheme = "yoshida4"`` is stable for omega_max dt < 1.5734 (tests/test_schemes.py
    computes it from the composed step), against 2 for the central difference: its critical
    step is 0.78670 of the paper's (to 1e-12), and tight: 0.9 of it runs, 1.1 blows up (an
    unstable mode grows 2.9 times a step there)."""
    paper = Simulation(scene("vibrating_bar", basis, mass)).critical_dt
    composed = Simulation(scene("vibrating_bar", basis, mass, **{"solver.scheme": "yoshida4"})).critical_dt
    assert composed / paper == pytest.approx(1.5734019474 / 2, rel=1e-12)
    assert not grows("vibrating_bar", basis, mass, 0.9, **{"solver.scheme": "yoshida4"})
    assert grows("vibrating_bar", basis, mass, 1.1, **{"solver.scheme": "yoshida4"})


def test_bloch_table_against_the_estimate_for_q1():
    """The bar fills its cells.  Consistent mass: within 10% of the Bloch value
    (0.5 element width / p-wave speed).  Lumped mass with FLIP: the grid
    velocity is re-projected from the points every step, so the iteration's
    inverse mass is M_L^-1 M_C M_L^-1, smaller than M_L^-1: the step exceeds
    the Bloch value 1.0 by more than 30% (measured 1.55x) -- and the
    tightness test above shows it is the right one."""
    steps = {}
    for mass in ("lumped", "consistent"):
        simulation = Simulation(scene("vibrating_bar", "q1", mass))
        wave_speed = simulation.materials[0].wave_speed
        steps[mass] = simulation.critical_dt / bloch_time_step("q1", mass, simulation.grid.spacing, wave_speed)
    assert steps["consistent"] == pytest.approx(1.0, rel=0.1)
    assert steps["lumped"] > 1.3


def test_supports_shrink_the_consistent_bspline_step_below_the_table():
    """Near the clamp a consistent cubic-spline mode has little inertia: the true
    step of the plain consistent mass is under half the table's (measured 0.30x),
    which the table would miss; the weak rows' treatment (``solver.weak_ratio = 0.5``,
    tests/test_weak_rows.py) lifts it above the table's."""
    plain = Simulation(scene("cantilever", "bspline3", "consistent", **{"solver.weak_ratio": 0.0}))
    table = bloch_time_step("bspline3", "consistent", 0.5, plain.materials[0].wave_speed)
    assert plain.critical_dt < 0.5 * table
    assert Simulation(scene("cantilever", "bspline3", "consistent", **{"solver.weak_ratio": 0.5})).critical_dt > table


def test_serendipity_lumped_has_a_finite_step_despite_negative_masses():
    """Its corner masses are negative (-0.70 of a full cell here), yet
    M_L^-1 M_C M_L^-1 is positive semi-definite: the linear iteration is
    stable below a finite step, which the tightness test confirms.  (A Bloch
    analysis with M_L^-1 says no step is stable.)"""
    simulation = Simulation(scene("vibrating_bar", "serendipity", "lumped"))
    assert 0 < simulation.critical_dt < 1.0


def test_large_problems_solve_with_the_mass_component_by_component(monkeypatch):
    """Above DENSE_LIMIT degrees of freedom ARPACK's solves with ``kron(M, I2)`` go through
    each component's factors of the nodal M (:class:`_ComponentSolve`): with x fixed on the
    block's left part only, so that the components' free nodes differ, it inverts the reduced mass
    to 1e-10, and the critical step is the one of scipy's own factorization of the interleaved mass
    (ARPACK from the same first vector) to 1e-9."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from femgrid_mpm import stability
    from helpers import advanced_benchmark_block

    # q2 (no weak nodes lumped: M is N.T diag(m) N) on ~1,000 nodes, above the dense problems' 1500 dofs
    scene = advanced_benchmark_block("q2", steps=0, n=4000).scene.with_overrides(
        supports=[{"where": "x <= 5.0", "fix": ["x"]}])
    built, problems = [], []
    original, largest = stability._ComponentSolve, stability.largest_frequency_squared

    def recording(nodal, free):
        solve = original(nodal, free)
        built.append((solve, sp.kron(nodal, sp.identity(2), format="csr")[free][:, free]))
        return solve

    def recording_problem(stiffness, mass, solve=None):
        problems.append((stiffness, mass))
        return largest(stiffness, mass, solve)

    monkeypatch.setattr(stability, "_ComponentSolve", recording)
    monkeypatch.setattr(stability, "largest_frequency_squared", recording_problem)
    critical = Simulation(scene).critical_dt
    (stiffness, mass), = problems
    assert mass.shape[0] > stability.DENSE_LIMIT
    reference = spla.eigsh(stiffness, k=1, M=mass.tocsc(), which="LA", tol=stability.ARPACK_TOLERANCE,
                           v0=stability.arpack_start(mass.shape[0]), return_eigenvectors=False)[0]
    assert critical == pytest.approx(2 / np.sqrt(reference), rel=1e-9)
    (solve, mass), = built
    assert len({id(factors) for _, factors in solve.parts}) == 2  # the components apart
    x = np.random.default_rng(5).normal(size=mass.shape[0])
    assert np.abs(solve @ (mass @ x) - x).max() <= 1e-10 * np.abs(x).max()


def test_the_estimate_of_a_large_problem_is_the_same_every_time():
    """Above 1500 degrees of freedom the critical step comes from ARPACK: three simulations of one
    scene in one process (cubic splines, consistent mass, 3,154 degrees of freedom) get the same
    step bit for bit (ARPACK's own first vector changed from call to call: the 11th digit did)."""
    scene = bundled_scene("vibrating_bar").with_overrides(
        **{"grid.basis": "bspline3", "grid.spacing": 0.0625, "solver.mass": "consistent", "time.dt": "auto"})
    steps = {Simulation(scene).critical_dt for _ in range(3)}
    assert len(steps) == 1


@pytest.mark.parametrize("basis,mass,overrides", [("q1", "lumped", {}), ("bspline3", "hrz", {}),
                                                  ("bspline3", "consistent", {"solver.mix": 0.25})])
def test_small_symmetric_problems_give_the_general_eigenvalue(monkeypatch, basis, mass, overrides):
    """Below 1500 degrees of freedom the largest eigenvalue of ``B K`` with a symmetric ``B``
    (one diagonal for velocity and acceleration, ``D^-1 C D^-1``; or a mixed mass's
    ``M^-1 C M^-1``) is that of ``L^T K L`` by B's Cholesky factor: it equals the largest
    modulus of the general (non-symmetric) eigenvalues of the product to 1e-12."""
    from femgrid_mpm import stability
    from helpers import benchmark_block

    seen = []
    original = stability.largest_eigenvalue_of_product

    def recording(inverse_mass, stiffness, symmetric=False):
        value = original(inverse_mass, stiffness, symmetric)
        seen.append((value, symmetric, inverse_mass.toarray(), stiffness.toarray()))
        return value

    monkeypatch.setattr(stability, "largest_eigenvalue_of_product", recording)
    scene = benchmark_block(basis, mass, 400).with_overrides(**{"time.dt": "auto", **overrides})
    Simulation(scene)
    (value, symmetric, inverse_mass, stiffness), = seen
    assert symmetric and 0 < stiffness.shape[0] <= 1500
    general = np.max(np.abs(np.linalg.eigvals(inverse_mass @ stiffness)))
    assert value == pytest.approx(general, rel=1e-12)


def test_a_singular_symmetric_inverse_mass_takes_the_general_eigenvalues():
    """A symmetric ``B`` with a zero row (a degree of freedom without mass) has no Cholesky
    factor: the general eigenvalues answer, the largest of ``diag(0, 1, 2) K``."""
    import scipy.sparse as sp

    from femgrid_mpm.stability import largest_eigenvalue_of_product

    stiffness = sp.csr_matrix(np.array([[2.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 2.0]]))
    inverse_mass = sp.diags([0.0, 1.0, 2.0]).tocsr()
    expected = np.max(np.abs(np.linalg.eigvals(inverse_mass.toarray() @ stiffness.toarray())))
    assert largest_eigenvalue_of_product(inverse_mass, stiffness, symmetric=True) == pytest.approx(expected, rel=1e-14)


def test_a_large_mixed_or_treated_mass_solves_component_by_component(monkeypatch):
    """Above DENSE_LIMIT a mass other than the points' consistent one (a mixed mass, ``mix =
    0.25``) gives ``M^-1 C M^-1 K`` to ARPACK through each component's factors of the nodal M:
    cubic splines on the bar at h = 0.0625 have the critical step of scipy's own factors of the
    interleaved mass (ARPACK from the same first vector) to 1e-9."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from femgrid_mpm import stability

    seen = []
    original = stability._largest_frequency_squared

    def recording(inertia, point_mass, free, stiffness):
        seen.append((inertia, free, stiffness))
        return original(inertia, point_mass, free, stiffness)

    monkeypatch.setattr(stability, "_largest_frequency_squared", recording)
    scene = bundled_scene("vibrating_bar").with_overrides(
        **{"grid.basis": "bspline3", "grid.spacing": 0.0625, "solver.mass": "consistent", "solver.mix": 0.25,
           "time.dt": "auto"})
    critical = Simulation(scene).critical_dt
    (inertia, free, stiffness), = seen
    assert inertia.consistent is not None and stiffness.shape[0] > stability.DENSE_LIMIT
    mass, consistent = (sp.kron(matrix, sp.identity(2), format="csc")[free][:, free]
                        for matrix in (inertia.matrix, inertia.consistent))
    factors, n = spla.splu(mass), stiffness.shape[0]
    operator = spla.LinearOperator((n, n), dtype=float,
                                   matvec=lambda x: factors.solve(consistent @ factors.solve(stiffness @ x)))
    reference = np.max(np.abs(spla.eigs(operator, k=1, which="LM", tol=stability.ARPACK_TOLERANCE, v0=stability.arpack_start(n),
                                        return_eigenvectors=False)))
    assert critical == pytest.approx(2 / np.sqrt(reference), rel=1e-9)


def test_components_sharing_factors_solve_in_one_call():
    """Where both components have the same free nodes, :class:`_ComponentSolve` solves them as
    one two-column call to the shared factors: the result is ``kron(M, I2)[free][:, free]^-1``
    applied to the vector (against a dense solve, to 1e-12), and each component's part is the
    one-column solve of its own values (to 1e-14: the same numbers where the BLAS treats one
    and two columns alike)."""
    import scipy.sparse as sp

    from femgrid_mpm.stability import _ComponentSolve

    rng = np.random.default_rng(3)
    n = 40
    points = sp.random(160, n, density=0.08, random_state=4, format="csr") + sp.eye(160, n, format="csr")
    nodal = (points.T @ sp.diags(rng.uniform(0.5, 2.0, 160)) @ points).tocsr()  # a Gram matrix: SPD
    free_nodes = np.ones(n, dtype=bool)
    free_nodes[[0, 7, 31]] = False  # held nodes, the same for both components
    free = np.repeat(free_nodes, 2)
    solve = _ComponentSolve(nodal, free)
    assert len(solve.parts) == 2 and solve.parts[0][1] is solve.parts[1][1]  # the two-column call
    mass = sp.kron(nodal, sp.identity(2), format="csr")[free][:, free].toarray()
    x = rng.normal(size=int(free.sum()))
    result = solve @ x
    assert np.abs(result - np.linalg.solve(mass, x)).max() <= 1e-12 * np.abs(result).max()
    for places, factors in solve.parts:
        one = factors.solve(x[places])
        assert np.abs(result[places] - one).max() <= 1e-14 * np.abs(one).max()
