"""The consistent mass's weak rows (``solver.weak_ratio``) and the mixed mass (``solver.mix``):
the matrices against their definitions, the critical step against numpy's eigenvalues of
the iteration written out densely, its tightness, rigid motion, and the GIMP block whose
points cross a node line.
"""

import math

import numpy as np
import pytest
import scipy.sparse as sp

from femgrid_mpm.diagnostics import SimulationStopped
from femgrid_mpm.mass.weak_rows import interior_ratio
from femgrid_mpm.scene import Scene
from femgrid_mpm.solver import Simulation
from femgrid_mpm.stability import stiffness_matrix
from femgrid_mpm import Grid
from helpers import block_scene, bundled_variant


def dense_iteration_step(simulation, weak_ratio: float, mix: float, weak_mix: float) -> float:
    """``2 / omega_max`` from the iteration written out with dense numpy arrays: M_C from
    the shape functions, the share ``weak_mix`` of each coupling of a weak row moved onto
    both diagonals, then ``(1 - mix) M + mix diag(M_C 1)``, and the largest |eigenvalue| of
    ``M^-1 M_C M^-1 K`` on the free degrees of freedom (numpy.linalg.eigvals)."""
    p, grid = simulation.particles, simulation.grid
    N, dNdx, dNdy = grid.shape_functions(p.x)
    consistent = (N.T @ sp.diags(p.mass) @ N).toarray()
    lumped = consistent.sum(axis=1)
    active = np.diag(consistent) > 0
    ratio = np.divide(np.diag(consistent), lumped, out=np.ones_like(lumped), where=active)
    weak = active & (ratio < weak_ratio * interior_ratio(grid))
    assert weak.any() == (weak_ratio > 0)  # the case has such rows
    mass = consistent.copy()
    for i in range(len(mass)):
        for j in range(len(mass)):
            if i != j and (weak[i] or weak[j]):
                mass[i, i] += weak_mix * consistent[i, j]
                mass[i, j] -= weak_mix * consistent[i, j]
    mass = (1 - mix) * mass + mix * np.diag(lumped)
    material = simulation.materials[0]
    lam, mu = material.lame_lambda, material.shear_modulus
    moduli = np.tile([lam + 2 * mu, lam, lam + 2 * mu, mu], (p.n, 1))
    free = np.repeat(active, 2)
    K = stiffness_matrix(dNdx, dNdy, p.volume, moduli).toarray()[free][:, free]
    mass2 = np.kron(mass, np.eye(2))[free][:, free]
    inverse = np.linalg.inv(mass2)
    iteration = inverse @ np.kron(consistent, np.eye(2))[free][:, free] @ inverse @ K
    return 2.0 / math.sqrt(np.max(np.abs(np.linalg.eigvals(iteration))))


def small_block(basis="bspline3", **solver):
    """A free block 1.5 x 1 in a grid of spacing 0.5: 3 x 3 points per cell, ~100 unknowns."""
    scene = block_scene(basis, "consistent", upper=(2.25, 1.5), dt="auto", end=1.0, every=None)
    return scene.with_overrides(**{f"solver.{key}": value for key, value in solver.items()})


@pytest.mark.parametrize("weak_ratio,weak_mix,mix", [(0.5, 0.02, 0.0), (0.5, 1.0, 0.0), (0.5, 0.1, 0.3), (0.0, 0.1, 0.3)])
def test_critical_step_is_that_of_the_dense_iteration(weak_ratio, weak_mix, mix):
    """The estimate (sparse factors, M^-1 M_C M^-1) against numpy's eigenvalues of the same
    iteration assembled densely by hand, to 1e-8 relative (no volume-fraction lumping)."""
    simulation = Simulation(small_block(weak_ratio=weak_ratio, weak_mix=weak_mix, mix=mix, weak_fraction=0.0))
    reference = dense_iteration_step(simulation, weak_ratio, mix, weak_mix)
    assert simulation.critical_dt == pytest.approx(reference, rel=1e-8)


def test_the_weak_rows_raise_the_cubic_splines_step_to_the_interior_one():
    """Cubic splines, the block: plain consistent mass is bound by the ring of nodes outside
    its edges; with the weak rows' treatment the step is at least twice as large."""
    plain = Simulation(small_block(weak_fraction=0.0, weak_ratio=0.0)).critical_dt
    treated = Simulation(small_block(weak_fraction=0.0, weak_ratio=0.5)).critical_dt  # weak_mix 0.02 (default)
    assert treated > 2 * plain


@pytest.mark.parametrize("basis", ["q1", "bspline3", "q2"])
def test_the_whole_mix_of_one_is_lumped_mass(basis):
    """mix = 1 is lumped mass: the same critical step (M_L^-1 M_C M_L^-1) to 1e-8, and for a
    non-negative basis the matrix is diag(row sums) exactly."""
    mixed = Simulation(small_block(basis, mix=1.0, weak_fraction=0.0))
    lumped = Simulation(small_block(basis).with_overrides(**{"solver.mass": "lumped"}))
    if basis != "q2":  # q2's partly filled elements: the HRZ diagonal replaces non-positive row sums
        assert mixed.critical_dt == pytest.approx(lumped.critical_dt, rel=1e-8)


@pytest.mark.parametrize("engine", ["numba", "scipy"])
@pytest.mark.parametrize("basis", ["q1", "bspline3", "gimp"])
def test_mixed_and_weak_rows_keep_the_row_sums(basis, engine):
    """Row sums of the modified matrix equal the lumped masses N.T m (to 1e-13 relative),
    and the matrix stays symmetric."""
    simulation = Simulation(small_block(basis, mix=0.3, weak_ratio=0.5, engine=engine))
    simulation.project()
    mass = simulation.mass
    matrix = sp.csr_matrix(mass.matrix).toarray()
    N = simulation.grid.shape_functions(simulation.particles.x)[0]
    lumped = N.T @ simulation.particles.mass
    np.testing.assert_allclose(matrix.sum(axis=1), lumped, rtol=0, atol=1e-13 * lumped.max())
    np.testing.assert_allclose(matrix, matrix.T, rtol=0, atol=1e-15 * lumped.max())
    assert mass.weak_rows > 0  # the rows outside the block's edges


@pytest.mark.parametrize("engine", ["numba", "scipy"])
@pytest.mark.parametrize("basis", ["q1", "q2", "bspline3", "gimp"])
def test_a_rigid_translation_is_exact(basis, engine):
    """A free block moving at one velocity across cells moves exactly with it under the
    mixed mass and the weak rows (the frame's share of a diagonal that is not the row sums)."""
    scene = block_scene(basis, "consistent", velocity=(1.0, 0.5), end=0.2, dt=0.01, engine=engine, every=None)
    simulation = Simulation(scene.with_overrides(**{"solver.mix": 0.3, "solver.weak_ratio": 0.5}))
    x0 = simulation.particles.x.copy()
    simulation.run()
    np.testing.assert_allclose(simulation.particles.v, np.tile([1.0, 0.5], (len(x0), 1)), rtol=0, atol=1e-12)
    np.testing.assert_allclose(simulation.particles.x - x0, np.tile([0.2, 0.1], (len(x0), 1)), rtol=0, atol=1e-12)


def grows(scene, factor) -> bool:
    """Whether 400 steps at factor x the critical step blow up (the bar starts at 0.01 m/s)."""
    critical = Simulation(scene).critical_dt
    run = Simulation(scene.with_overrides(**{"time.dt": factor * critical, "time.end": 400 * factor * critical,
                                             "output": None}))
    try:
        run.run()
    except SimulationStopped:
        return True
    return bool(np.abs(run.particles.v).max() > 10.0 or not np.isfinite(run.particles.v).all())


@pytest.mark.parametrize("basis,solver", [("bspline3", {"weak_ratio": 0.5}), ("q1", {"mix": 0.3})])
def test_the_estimate_is_tight(basis, solver):
    """The bar: 0.9 of the estimate runs, 1.1 of it blows up."""
    scene = bundled_variant("vibrating_bar", basis, "consistent", "warn",
                            **{f"solver.{key}": value for key, value in solver.items()})
    assert not grows(scene, 0.9)
    assert grows(scene, 1.1)


def test_interior_ratio_of_the_bases():
    """integral(phi^2) / integral(phi) of an interior function: q1 (2/3)^2, cubic splines
    (151/315)^2, quadratic splines (11/20)^2 (1D: exact integrals of the hat and the splines;
    the midpoint rule of 8 x 8 samples per cell is within 1e-2: a threshold's scale)."""
    for basis, one_d in [("q1", 2 / 3), ("bspline3", 151 / 315), ("bspline2", 11 / 20)]:
        grid = Grid(basis, (0.0, 0.0), (4.0, 4.0), 0.5)
        assert interior_ratio(grid) == pytest.approx(one_d**2, rel=1e-2)


def crossing_gimp_block(**solver) -> Scene:
    """A free GIMP block (2 points per cell) thrown at 1 m/s across node lines: a point's square
    first reaches past a node line at t = 0.25 s; 1.5 s of it, dt from the set-up estimate."""
    return Scene.model_validate({
        "grid": {"basis": "gimp", "lower": [0, 0], "upper": [4, 4], "spacing": 0.5},
        "time": {"dt": "auto", "end": 1.5},
        "solver": {"mass": "consistent", **solver},
        "bodies": [{"name": "block", "lower": [0.5, 0.5], "upper": [1.5, 1.5], "points_per_cell": 2,
                    "velocity": ["1.0 + 0.05*sin(pi*(x - 0.5))", "0.5"],
                    "material": {"E": 1e4, "nu": 0.3, "density": 1e3}}],
        "output": {"every": 10, "energy": True},
    })


def test_gimp_points_crossing_a_node_line_keep_their_energy():
    """Consistent GIMP: once a point's square reaches past a node line the next node has a
    weight of order (overlap / spacing)^2, a mode of almost no mass, and the run at the
    set-up's step runs away (the energy guard stops it at t = 0.23 s, measured).  The weak
    rows' treatment (``weak_ratio = 0.5``) takes it: the run completes with the energy balance
    kept to 1e-3 of the initial energy (measured 3.2e-5)."""
    with pytest.raises(SimulationStopped, match="energy ran away"):
        Simulation(crossing_gimp_block(weak_ratio=0.0)).run()
    result = Simulation(crossing_gimp_block(weak_ratio=0.5)).run()
    assert result.status == "completed"
    energy = result.energy
    assert np.abs(energy["total_error"]).max() < 1e-3 * energy["total"][0]
    assert result.summary["consistent_mass"]["weak_rows_last_step"] > 0


@pytest.mark.parametrize("per_node", [False, True])
@pytest.mark.parametrize("weak_test", [False, True])
def test_the_nodes_tests_are_numpys(per_node, weak_test):
    """The compiled pass of a step's node tests against numpy's formulas: active where the diagonal
    is above 1e-24 of a full cell, weak where also the volume fraction is below ``weak_fraction``,
    their count, the smallest row sum, and whether both sets are the last ones."""
    from femgrid_mpm.mass.exclusion import active_and_weak
    from femgrid_mpm.mass.scale import NO_SCALES, scale_arguments

    rng = np.random.default_rng(3)
    n = 400
    cell = rng.uniform(0.5, 2.0, n) if per_node else 1.3
    diagonal = np.where(rng.random(n) < 0.2, 0.0, rng.uniform(0.0, 1.0, n)) * cell
    diagonal[:5] = 1e-24 * (cell[:5] if per_node else cell) * np.array([0.5, 1.0, 1.5, 2.0, 0.0])
    lumped = rng.normal(1.0, 1.0, n)
    volume, integrals = rng.uniform(0.0, 0.05, n), rng.uniform(0.5, 1.5, n)
    active = diagonal > 1e-24 * cell
    fraction = np.divide(volume, integrals, out=np.ones(n), where=active)
    weak = active & (fraction < 0.02) if weak_test else np.zeros(n, dtype=bool)
    for last in (None, (active, weak), (active, ~weak)):
        got_active, got_weak = np.empty(n, dtype=bool), np.empty(n, dtype=bool)
        count, smallest, unchanged = active_and_weak(
            diagonal, *scale_arguments(cell), lumped, *((volume, integrals) if weak_test else (NO_SCALES,) * 2),
            0.02, got_active, got_weak, *(last or (np.zeros(0, dtype=bool),) * 2))
        np.testing.assert_array_equal(got_active, active)
        np.testing.assert_array_equal(got_weak, weak)
        assert count == np.count_nonzero(weak) and smallest == lumped.min()
        assert unchanged == (last is not None and np.array_equal(last[1], weak))
