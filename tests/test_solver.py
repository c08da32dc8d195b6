"""The explicit step against exact discrete solutions.

Each test states its reference: rigid motion must be exact to round-off
(tolerance 1e-12 m over the run); free fall and damping follow closed-form
discrete recurrences of the paper's update order.
"""

import numpy as np
import pytest

from femgrid_mpm.bases import BASES
from femgrid_mpm.diagnostics import SimulationStopped
from femgrid_mpm.materials import LinearElastic
from femgrid_mpm.scene import Scene, bundled_scene
from femgrid_mpm.solver import Simulation
from helpers import block_scene


@pytest.mark.filterwarnings("ignore::femgrid_mpm.diagnostics.NegativeMassWarning")
@pytest.mark.parametrize("mass", ["lumped", "consistent"])
@pytest.mark.parametrize("basis", list(BASES))
def test_rigid_translation_is_exact(basis, mass):
    """A block with uniform velocity and no loads moves rigidly, crossing cells
    (1 m in x at spacing 0.5), to round-off, for every basis and mass kind."""
    velocity = np.array([1.0, 0.25])
    result = Simulation(block_scene(basis, mass, velocity)).run()
    p = result.particles
    displacement = p.x - p.x0
    np.testing.assert_allclose(displacement, np.broadcast_to(velocity * 1.0, displacement.shape), rtol=0, atol=1e-12)
    # Lumped q2/serendipity masses pass near zero as the block's edge crosses
    # an element (measured down to 2e-5 of a cell's mass): a = f / m amplifies
    # the round-off of f by that much, hence 1e-10 there instead of 1e-12.
    amplified = mass == "lumped" and not BASES[basis].nonnegative
    np.testing.assert_allclose(p.v, np.broadcast_to(velocity, p.v.shape), rtol=0, atol=1e-10 if amplified else 1e-12)
    assert np.abs(p.stress).max() < 1e-6  # Pa, against E = 1e4: round-off only
    # energy is conserved exactly as well
    np.testing.assert_allclose(result.energy["total"], result.energy["total"][0], rtol=1e-12)


def test_free_fall_follows_the_discrete_recurrence():
    """Gravity only: v_k = g k dt and, positions using the grid velocity of
    the step's start (Eq. 20), x_k = x_0 + g dt^2 k (k - 1) / 2 exactly.
    The external work booked at mid-step velocity equals the kinetic energy."""
    g = np.array([0.0, -9.81])
    scene = block_scene(velocity=(0.0, 0.0), end=0.3, loads=[{"kind": "gravity", "acceleration": list(g)}])
    result = Simulation(scene).run()
    k = 30
    p = result.particles
    np.testing.assert_allclose(p.v, np.broadcast_to(g * k * 0.01, p.v.shape), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(p.x - p.x0, np.broadcast_to(g * 0.01**2 * k * (k - 1) / 2, p.x.shape), rtol=1e-10, atol=1e-14)
    energy = result.energy
    np.testing.assert_allclose(energy["external_work"], energy["kinetic"], rtol=1e-10)
    np.testing.assert_allclose(energy["total_error"], 0.0, atol=1e-10 * energy["kinetic"][-1])


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_mass_damping_decays_geometrically(mass):
    """f = -c M v on a rigid motion: v_{k+1} = v_k (1 - c dt) exactly.  Consistent mass is
    solved by CG on kept factors ("auto"): its tolerance far below the test's 1e-10."""
    c = 2.0
    scene = block_scene(mass=mass, end=0.5, damping={"kind": "mass", "coefficient": c})
    scene = scene.with_overrides(**{"solver.cg_tolerance": 1e-14})
    result = Simulation(scene).run()
    expected = np.array([1.0, 0.25]) * (1 - c * 0.01) ** 50
    np.testing.assert_allclose(result.particles.v, np.broadcast_to(expected, (result.particles.n, 2)), rtol=1e-10)
    # the damping work is the kinetic energy lost (energy balance closes)
    energy = result.energy
    assert energy["external_work"][-1] < 0
    np.testing.assert_allclose(energy["total_error"][-1], 0.0, atol=0.02 * abs(energy["external_work"][-1]))


def test_point_load_changes_momentum_by_its_impulse():
    """Total momentum sum(m v) grows by F t exactly (shape functions sum to one)."""
    force = np.array([3.0, -2.0])
    scene = block_scene(
        velocity=(0.0, 0.0),
        end=0.5,
        loads=[{"kind": "point", "body": "block", "at": [1.75, 1.5], "force": list(force)}],
    )
    result = Simulation(scene).run()
    momentum = (result.particles.mass[:, None] * result.particles.v).sum(axis=0)
    np.testing.assert_allclose(momentum, force * 0.5, rtol=1e-10, atol=1e-14)


def test_point_load_ramp():
    """A ramp to full force at t_r: the discrete sum of the force at each step's force time
    t + dt (F t^2 / (2 t_r) is the integral, before t_r)."""
    force = np.array([0.0, -4.0])
    scene = block_scene(
        velocity=(0.0, 0.0),
        end=0.5,
        loads=[{"kind": "point", "body": "block", "at": [1.0, 1.0], "force": list(force), "ramp": 1.0}],
    )
    result = Simulation(scene).run()
    momentum = (result.particles.mass[:, None] * result.particles.v).sum(axis=0)
    impulse = force * 0.01 * sum(k * 0.01 / 1.0 for k in range(1, 51))
    np.testing.assert_allclose(momentum, impulse, rtol=1e-10, atol=1e-14)


def test_point_load_ramp_with_the_centred_step_is_its_integral():
    """The centred step's half kicks at the start and end make the impulse the trapezoidal
    sum of the force at the step's instants, exact for a linear ramp: momentum F T^2 / (2 t_r)
    at the end time T (the ramp read a step late gave F T (T - dt) / (2 t_r))."""
    force = np.array([0.0, -4.0])
    scene = block_scene(
        velocity=(0.0, 0.0),
        end=0.5,
        loads=[{"kind": "point", "body": "block", "at": [1.0, 1.0], "force": list(force), "ramp": 1.0}],
    ).with_overrides(**{"solver.scheme": "centred"})
    result = Simulation(scene).run()
    momentum = (result.particles.mass[:, None] * result.particles.v).sum(axis=0)
    np.testing.assert_allclose(momentum, force * 0.5**2 / 2.0, rtol=1e-10, atol=1e-14)


def test_paper_eq35_point_load_applies_force_times_mass_fraction():
    force = np.array([0.0, -100.0])
    load = {"kind": "point", "body": "block", "at": [1.75, 1.5], "force": list(force), "model": "paper_eq35"}
    simulation = Simulation(block_scene(velocity=(0.0, 0.0), end=0.1, loads=[load]))
    result = simulation.run()
    momentum = (result.particles.mass[:, None] * result.particles.v).sum(axis=0)
    n = result.particles.n  # equal point masses: the body receives F / n
    np.testing.assert_allclose(momentum, force / n * 0.1, rtol=1e-10, atol=1e-14)


def test_supports_hold_nodes():
    """Every node fixed: the grid velocity is zero, so no point moves (Eq. 20)."""
    scene = block_scene(supports=[{"where": "x > -10", "fix": ["x", "y"]}])
    result = Simulation(scene).run()
    np.testing.assert_array_equal(result.particles.x, result.particles.x0)


@pytest.mark.filterwarnings("ignore::femgrid_mpm.diagnostics.NegativeMassWarning")
@pytest.mark.parametrize("density", [1e3, 1e-9])
@pytest.mark.parametrize("basis", list(BASES))
def test_system_made_in_place_keeps_the_mass_matrix(basis, density):
    """The consistent solve's system ``R = keep M keep + diag(excluded)`` is made from the
    assembled entries in place, recording what it overwrites.  Against scipy, with empty
    nodes and a support: R exactly (zeros and ones), ``mass.matrix`` (M rebuilt) equal to
    ``N.T diag(m) N`` entry by entry to 1e-12 relative, and ``mass.apply`` (as damping and
    the energy record use it) equal to ``M @ v`` to 1e-12 relative.  At a density of 1e-9
    the masses are ~1e-12 kg: rebuilding M from differences ``M_ii - 1`` on the fixed nodes'
    diagonals lost 8e-6 of them (a second review found it)."""
    import scipy.sparse as sp

    scene = block_scene(basis, "consistent", supports=[{"where": "x <= 1", "fix": ["x", "y"]}])
    scene = scene.with_overrides(**{"solver.weak_fraction": 0.0, "solver.weak_ratio": 0.0,  # M is the product
                                    "bodies.0.material.density": density})
    simulation = Simulation(scene)
    simulation.particles.v[:] = np.random.default_rng(5).normal(size=simulation.particles.v.shape)
    simulation.project()
    mass, p = simulation.mass, simulation.particles
    assert mass._correction is not None and len(mass._systems) == 1
    N = simulation.grid.shape_functions(p.x)[0]
    product = (N.T @ sp.diags(p.mass) @ N).toarray()
    M = sp.csr_matrix(mass.matrix).toarray()
    np.testing.assert_allclose(M, product, rtol=1e-12, atol=1e-14 * np.abs(product).max())
    excluded = mass._systems[0].excluded
    assert excluded.sum() > 0 and (mass.active & excluded).sum() > 0  # empty nodes and supported ones
    keep = np.diag((~excluded).astype(float))
    np.testing.assert_array_equal(sp.csr_matrix(mass._systems[0].matrix).toarray(),
                                  keep @ M @ keep + np.diag(excluded.astype(float)))
    vector = np.random.default_rng(6).normal(size=(mass.n_nodes, 2))
    expected = product @ vector
    scale = np.abs(product) @ np.abs(vector)  # each entry's own size: rounding is relative to it
    assert np.all(np.abs(mass.apply(vector) - expected) <= 1e-12 * scale + 1e-300)


@pytest.mark.filterwarnings("ignore::femgrid_mpm.diagnostics.NegativeMassWarning")
@pytest.mark.parametrize("solver", ["direct", "cg"])
@pytest.mark.parametrize("basis", list(BASES))
def test_consistent_grid_velocity_next_to_supports_is_the_constrained_projection(basis, solver):
    """With consistent mass and supports, the grid velocity solves ``M_ff v_f = p_f``
    (v = 0 where fixed), whatever the frame the step works in (one point's velocity).

    Reference: scipy's direct solve of the free block of the step's own matrix
    (weak nodes lumped) with the absolute momentum ``N.T @ (m_p v_p)``.  Random point
    velocities, so the frame is not zero; tolerance 1e-10 of the largest velocity
    (direct), 1e-8 (CG at tolerance 1e-12).  Before the supports' couplings were moved
    to the right-hand side, the velocities next to the support were off by
    ``M_ff^-1 M_fc v_ref`` (order one of the frame velocity), which made the consistent
    open-knot cantilever grow exponentially.
    """
    import scipy.sparse.linalg as spla

    beam = {"name": "beam", "lower": [0.5, 0.5], "upper": [3.5, 2.0], "points_per_cell": 3,
            "material": {"E": 1e4, "nu": 0.3, "density": 1e3}}
    scene = block_scene(basis, "consistent", bodies=[beam], supports=[{"where": "x <= 1", "fix": ["x", "y"]}])
    scene = scene.with_overrides(**{"solver.linear_solver": solver, "solver.cg_tolerance": 1e-12})
    simulation = Simulation(scene)
    p = simulation.particles
    p.v[:] = np.random.default_rng(7).normal(size=p.v.shape)
    velocity = simulation.project().velocity
    N = simulation.grid.shape_functions(p.x)[0]
    momentum = N.T @ (p.mass[:, None] * p.v)
    matrix = simulation.mass.matrix.tocsr()
    free = simulation.mass.active & ~simulation.mass.fixed[:, 0]
    assert free.sum() > 10 and simulation.mass.fixed[:, 0].sum() > 0 and simulation.mass.blended_steps == 0
    reference = np.zeros_like(velocity)
    reference[free] = np.column_stack([spla.spsolve(matrix[free][:, free].tocsc(), momentum[free, k]) for k in range(2)])
    tolerance = (1e-10 if solver == "direct" else 1e-8) * np.abs(p.v).max()
    np.testing.assert_allclose(velocity[free], reference[free], rtol=0, atol=tolerance)
    np.testing.assert_array_equal(velocity[simulation.mass.fixed[:, 0]], 0.0)


@pytest.mark.filterwarnings("ignore::femgrid_mpm.diagnostics.NegativeMassWarning")
@pytest.mark.parametrize("supports", [[], [{"where": "x <= 1", "fix": ["y"]}]])
@pytest.mark.parametrize("basis", ["q1", "q2", "serendipity"])
def test_blended_grid_velocity_is_the_blended_projection_in_any_frame(basis, supports, monkeypatch):
    """When the consistent solve falls back to ``B = (1 - b) M + b D`` (D the row sums, or
    for q2 and serendipity, whose row sums are not all positive, the HRZ diagonal), the
    grid velocity solves ``B_ff v_f = p_f`` whatever point the frame follows.

    Reference: scipy's direct solve with the step's own ``M`` and ``D``; the blend forced
    by failing every unblended solve.  Tolerance 1e-10 of the largest point velocity.
    With the HRZ diagonal ``B 1 != L``, and before ``b (L - D) v_ref`` was added to the
    right-hand side the velocities moved by up to 8.5 (q2) when another point came first.
    """
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from femgrid_mpm.mass import ldl

    # systems factored every step: their pivots say singular too, so that the solve falls back
    monkeypatch.setattr(ldl.SymbolicLDL, "factor", lambda self, data: (None, None))
    beam = {"name": "beam", "lower": [0.5, 0.5], "upper": [3.5, 2.0], "points_per_cell": 3,
            "material": {"E": 1e4, "nu": 0.3, "density": 1e3}}
    for first in (0, 57):
        simulation = Simulation(block_scene(basis, "consistent", bodies=[beam], supports=supports))
        mass, p = simulation.mass, simulation.particles
        velocities = np.random.default_rng(7).normal(size=p.v.shape)
        unblended = mass._solve
        mass._solve = lambda system, rhs, kind: (unblended(system, rhs, kind) if system.blended
                                                 else (np.zeros_like(rhs), False))
        order = np.arange(p.n)
        order[[0, first]] = order[[first, 0]]
        p.x[:] = p.x[order]
        p.v[:] = velocities[order]
        velocity = simulation.project().velocity
        assert mass.blended_steps == len(mass._systems)  # x and y apart when fixed apart
        N = simulation.grid.shape_functions(p.x)[0]
        momentum = N.T @ (p.mass[:, None] * p.v)
        blended = ((1 - mass.blend) * mass.matrix + mass.blend * sp.diags(mass._blend_target())).tocsr()
        fixed = mass.fixed if mass.fixed is not None else np.zeros((simulation.grid.n_nodes, 2), dtype=bool)
        for k in range(2):
            free = mass.active & ~fixed[:, k]
            reference = spla.spsolve(blended[free][:, free].tocsc(), momentum[free, k])
            np.testing.assert_allclose(velocity[free, k], reference, rtol=0, atol=1e-10 * np.abs(velocities).max())
    # the case the test is for: row sums not all positive, the HRZ diagonal (q1: the row sums)
    assert np.all(mass.lumped[mass.active] > 0) == (basis == "q1")


def test_support_fixing_one_component():
    """Fixing only y everywhere: x motion is free and exact, y motion none."""
    scene = block_scene(supports=[{"where": "x > -10", "fix": ["y"]}])
    result = Simulation(scene).run()
    displacement = result.particles.x - result.particles.x0
    np.testing.assert_allclose(displacement[:, 0], 1.0, atol=1e-12)
    np.testing.assert_array_equal(displacement[:, 1], 0.0)


@pytest.mark.parametrize("basis", ["q1", "serendipity", "bspline3"])
@pytest.mark.parametrize("held", [["y"], ["x"]])
def test_consistent_mass_with_a_component_held_at_every_node(basis, held):
    """The bar with one velocity component held at every node: that component's system has no
    free row (its factorization's work was a division by zero).  Solved by "auto" (factors,
    their rates and CG's trial) and by CG as by the direct solver, to 1e-9 and 1e-5 of the
    largest displacement, the held component exactly zero."""
    results = {}
    for solver in ("auto", "cg", "direct"):
        scene = bundled_scene("vibrating_bar").with_overrides(**{
            "grid.basis": basis, "solver.mass": "consistent", "solver.negative_mass": "warn", "time.end": 0.3,
            "solver.linear_solver": solver, "supports": [{"where": "y > -100", "fix": held}],
            "bodies.0.velocity": ["0.01*cos(pi*x/5)", "0.01*cos(pi*x/5)"]})  # both: the free one moves
        simulation = Simulation(scene)
        simulation.run()
        results[solver] = simulation.particles.x - simulation.particles.x0
    column = 0 if held == ["x"] else 1
    scale = np.abs(results["direct"]).max()
    assert scale > 0
    for solver, tolerance in (("auto", 1e-9), ("cg", 1e-5)):  # CG: cg_tolerance 1e-6 a solve, 100 steps
        assert not results[solver][:, column].any()
        np.testing.assert_allclose(results[solver], results["direct"], rtol=0, atol=tolerance * scale)


def test_zero_strength_effects_change_nothing():
    """Declared effects of zero strength give bit-identical results."""
    plain = Simulation(block_scene(end=0.2)).run()
    zero = Simulation(
        block_scene(
            end=0.2,
            loads=[
                {"kind": "gravity", "acceleration": [0.0, 0.0]},
                {"kind": "point", "body": "block", "at": [1, 1], "force": [0.0, 0.0]},
            ],
            damping={"kind": "mass", "coefficient": 0.0},
        )
    )
    assert set(zero.active_effects) >= {"gravity", "point_load", "damping"}
    zero_result = zero.run()
    np.testing.assert_array_equal(zero_result.particles.x, plain.particles.x)
    np.testing.assert_array_equal(zero_result.particles.v, plain.particles.v)


def test_undeclared_effects_are_not_run():
    simulation = Simulation(block_scene(output=None))
    assert simulation.active_effects == []
    simulation = Simulation(block_scene())
    assert simulation.active_effects == ["energy"]


@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_linear_elastic_increment(plane):
    """D : d(eps) against the textbook matrices (Voigt, engineering shear)."""
    E, nu = 2.0e5, 0.25
    material = LinearElastic(E, nu, 1.0, plane)
    strain = np.array([[1e-3, -2e-4, 5e-4]])  # xx, yy, tensor xy
    voigt = np.array([strain[0, 0], strain[0, 1], 2 * strain[0, 2]])
    if plane == "stress":
        D = E / (1 - nu**2) * np.array([[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]])
    else:
        D = E / ((1 + nu) * (1 - 2 * nu)) * np.array([[1 - nu, nu, 0], [nu, 1 - nu, 0], [0, 0, (1 - 2 * nu) / 2]])
    stress = material.stress_increment(strain, out=np.zeros((1, 3)))
    np.testing.assert_allclose(stress[0], D @ voigt, rtol=1e-14)


def test_particle_leaving_the_grid_stops_the_run_with_its_name():
    scene = block_scene(velocity=(10.0, 0.0), end=1.0)
    with pytest.raises(SimulationStopped, match=r"step \d+ \(t = [\d.]+ s\): a particle left the grid: \d+ of 36 points lie outside") as stop:
        Simulation(scene).run()
    assert stop.value.reason == "particle_left_grid"
    result = stop.value.result
    assert result.status == "stopped" and len(result.energy["time"]) >= 1  # records so far are kept


@pytest.mark.parametrize("every", [None, 1])
@pytest.mark.parametrize("end", [0.24, 0.25])
def test_a_particle_the_last_step_takes_off_the_grid_stops_the_run_as_at_any_step(every, end):
    """The block's last column of six points (x = 1.75 - 1/12) moves rigidly at 10 m/s and passes
    the grid's edge x = 4 at t = 0.2333 s: after step 24 (t = 0.24 s).  A run ending there
    stops there, as the run that goes on does, with records or without (the last record's
    P2G found it; without records the run reported success with a point off the grid)."""
    scene = block_scene(velocity=(10.0, 0.0), end=end, every=every)
    with pytest.raises(SimulationStopped, match=r"^step 24 \(t = 0\.24 s\): a particle left the grid: 6 of 36 points "
                                                 r"lie outside the grid \[0, 4\] x \[0, 3\]") as stop:
        Simulation(scene).run()
    assert stop.value.reason == "particle_left_grid" and stop.value.result.status == "stopped"
    assert abs(stop.value.result.particles.x[:, 0].max() - (1.75 - 1 / 12 + 2.4)) < 1e-12


def rank_deficient_scene(fallback):
    """Cubic B-splines, 2 points per cell across a body 2 cells thick: 4 points
    for the 5 functions that span its depth, so N.T diag(m) N is singular."""
    return Scene.model_validate({
        "grid": {"basis": "bspline3", "lower": [0, 0], "upper": [7, 3], "spacing": 0.5},
        "time": {"dt": 0.003, "end": 3.0},
        "solver": {"mass": "consistent", "consistent_fallback": fallback},
        "bodies": [{"name": "bar", "lower": [1, 1], "upper": [6, 2], "points_per_cell": 2,
                    "velocity": ["0.01*cos(pi*(x-1)/5)", "0"], "material": {"E": 1e4, "nu": 0.3, "density": 1e3}}],
        "output": {"every": 10},
    })


@pytest.mark.parametrize("solver", ["direct", "cg"])
def test_rank_deficient_consistent_mass_is_detected(solver):
    """Stopped at step 0, naming the place: a node whose function the body's points reach
    (a positive row sum of the mass), its coordinates those of the grid."""
    import re

    simulation = Simulation(rank_deficient_scene("error").with_overrides(**{"solver.linear_solver": solver}))
    with pytest.raises(SimulationStopped, match=r"step 0 \(t = 0 s\): the consistent mass matrix is singular") as stop:
        simulation.run()
    assert stop.value.reason == "singular_mass"
    node, x, y = re.search(r"; weakest at node (\d+) at \(([-\d.e]+), ([-\d.e]+)\)$", str(stop.value)).groups()
    assert simulation.mass.lumped[int(node)] > 0
    np.testing.assert_allclose(simulation.grid.nodes[int(node)], [float(x), float(y)], rtol=1e-5)


def test_rank_deficient_consistent_mass_blends_and_stays_bounded():
    """With the blend fallback every step is blended and energy is conserved
    within 1% over 1000 steps (before the pivot threshold was 1e-8, a few
    singular steps slipped through and the points flew off at step 961)."""
    simulation = Simulation(rank_deficient_scene("blend"))
    result = simulation.run()
    total = result.energy["total"]
    assert result.summary["consistent_mass"]["blended_steps"] == simulation.n_steps + 1
    assert np.max(np.abs(total - total[0])) < 0.01 * total[0]


def test_the_linear_solver_is_chosen_in_the_scene():
    """``solver.linear_solver = "cg"`` solves even a small consistent system by CG, and
    at the default tolerance (1e-6) the bar's velocities stay within 1e-4 of their
    amplitude (0.01 m/s) of the direct solve's after 0.5 s (measured: ~1e-6)."""
    scene = bundled_scene("vibrating_bar").with_overrides(
        **{"solver.mass": "consistent", "solver.linear_solver": "cg", "time.end": 0.5})
    by_cg = Simulation(scene)
    by_cg.run()
    direct = Simulation(scene.with_overrides(**{"solver.linear_solver": "direct"}))
    direct.run()
    assert by_cg.mass.iterations > 0 and direct.mass.iterations == 0
    np.testing.assert_allclose(by_cg.particles.v, direct.particles.v, rtol=0, atol=1e-4 * 0.01)
