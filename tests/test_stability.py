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
    """Above LARGE_PROBLEM degrees of freedom ARPACK's solves with ``kron(M, I2)`` go through
    each component's factors of the nodal M (:class:`_ComponentSolve`): with x fixed on the
    block's left part only, so that the components' free nodes differ, it inverts the reduced mass
    to 1e-10, and the critical step is the one of scipy's own factorization within ARPACK's tolerance."""
    import scipy.sparse as sp

    from femgrid_mpm import stability
    from helpers import advanced_benchmark_block

    # q2 (no weak nodes lumped: M is N.T diag(m) N) on ~1,000 nodes, above the dense problems' 1500 dofs
    scene = advanced_benchmark_block("q2", steps=0, n=4000).scene.with_overrides(
        supports=[{"where": "x <= 5.0", "fix": ["x"]}])
    reference = Simulation(scene).critical_dt
    built = []
    original = stability._ComponentSolve

    def recording(nodal, free):
        solve = original(nodal, free)
        built.append((solve, sp.kron(nodal, sp.identity(2), format="csr")[free][:, free]))
        return solve

    monkeypatch.setattr(stability, "LARGE_PROBLEM", 0)
    monkeypatch.setattr(stability, "_ComponentSolve", recording)
    simulation = Simulation(scene)
    # ARPACK stops at a relative tolerance of 1e-4 from a starting vector it draws afresh at each
    # call in a process: two estimates of one step differ by about that much (1.2e-4 seen)
    assert simulation.critical_dt == pytest.approx(reference, rel=1e-3)
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
