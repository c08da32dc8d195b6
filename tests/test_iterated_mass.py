"""The iterated mass (``solver.mass = "iterated"``, :mod:`femgrid_mpm.mass.iterated`): the
consistent mass solved by k Jacobi corrections of the lumped solution.

Its solve against the truncated Neumann series built densely here, a uniform velocity projected
exactly, the engines alike, the bar's error against the exact mode; its critical step's
tightness is in tests/test_stability.py, its checkpoints in tests/test_checkpoint.py.
"""

import numpy as np
import pytest

from femgrid_mpm.scene import SceneError, bundled_scene
from femgrid_mpm.solver import Simulation
from helpers import bundled_variant
from test_kernels import assert_steps_agree, block_scene


def assembled(scene):
    """The scene's mass model assembled on its points at the start, and ``N`` there."""
    simulation = Simulation(scene)
    N = simulation.grid.shape_functions(simulation.particles.x)[0]
    model = simulation.mass_model()
    model.assemble(N, simulation.particles.mass, simulation.particles.volume)
    return simulation, model, N


@pytest.mark.parametrize("basis", ["q1", "bspline3", "gimp"])
@pytest.mark.parametrize("corrections", [1, 3])
def test_the_solve_is_the_truncated_neumann_series_of_the_consistent_mass(basis, corrections):
    """On the clamped cantilever (supports: each component's free nodes differ from the
    active ones), ``x = sum_(j=0..k) (I - L^-1 M_ff)^j L^-1 b`` on each component's free
    active nodes, ``M = N.T diag(m) N`` and ``L`` its full row sums, made densely here: to 1e-12."""
    scene = bundled_variant("cantilever", basis, "iterated", **{"solver.mass_corrections": corrections})
    simulation, model, N = assembled(scene)
    mass = (N.T @ (N.multiply(simulation.particles.mass[:, None]))).toarray()
    row_sums = mass.sum(axis=1)
    rhs = np.random.default_rng(1).standard_normal((simulation.grid.n_nodes, 2)) * row_sums[:, None]
    solution = model.solve(rhs, "acceleration")
    fixed = simulation.fixed if simulation.fixed is not None else np.zeros((len(row_sums), 2), dtype=bool)
    assert fixed.any()
    for column in range(2):
        free = model.active & ~fixed[:, column]  # active: row sums above round-off (gimp has 1e-15s)
        jacobi = np.eye(free.sum()) - mass[np.ix_(free, free)] / row_sums[free, None]
        series, term = np.zeros_like(jacobi), np.eye(free.sum())
        for _ in range(corrections + 1):
            series, term = series + term, jacobi @ term
        expected = np.zeros(len(row_sums))
        expected[free] = series @ (rhs[free, column] / row_sums[free])
        np.testing.assert_allclose(solution[:, column], expected, rtol=0, atol=1e-12 * np.abs(expected).max())


@pytest.mark.parametrize("basis", ["q1", "bspline3"])
def test_a_uniform_velocity_is_projected_exactly(basis):
    """``L^-1 M 1 = 1`` without supports: the momentum of a uniform velocity gives it back at
    every active node whatever k (a rigid translation stays one), to 1e-14."""
    scene = bundled_variant("vibrating_bar", basis, "iterated", **{"solver.mass_corrections": 4})
    simulation, model, _ = assembled(scene)
    velocity = np.array([0.3, -1.7])
    momentum = model.lumped[:, None] * velocity
    solution = model.solve(momentum, "velocity")
    active = model.lumped > 0
    np.testing.assert_allclose(solution[active], np.broadcast_to(velocity, solution[active].shape), rtol=1e-14)
    assert not solution[~active].any()


@pytest.mark.parametrize("basis", ["q1", "bspline3"])
def test_the_grid_velocity_does_not_depend_on_the_frame_with_supports(basis):
    """The step projects the momentum relative to a frame (the first point's velocity); on the
    clamped cantilever the velocity so found is the absolute solve's ``A_k p`` at every free
    active node, to 1e-13 of the largest (``A_k`` of the relative momentum alone missed
    ``sum_(j=1..k) E^j 1 v_ref`` next to the clamp: 2.7e-2 and 6.7e-2 of ``v_ref``)."""
    scene = bundled_variant("cantilever", basis, "iterated", **{"solver.mass_corrections": 3})
    simulation, model, _ = assembled(scene)
    momentum = np.random.default_rng(2).standard_normal((simulation.grid.n_nodes, 2)) * model.lumped[:, None]
    frame = np.array([0.7, -0.4])
    absolute = model.solve(momentum, "velocity")
    _, velocity = model.grid_velocity(momentum - model.lumped[:, None] * frame, frame)
    free = model.active[:, None] & ~simulation.fixed
    assert free.sum() > 0 and (~free & model.active[:, None]).any()
    np.testing.assert_allclose(velocity[free], absolute[free], rtol=0, atol=1e-13 * np.abs(absolute).max())


@pytest.mark.parametrize("basis", ["q1", "bspline3", "bspline2", "gimp"])
@pytest.mark.parametrize("corrections", [1, 3])
def test_the_compiled_products_are_the_consistent_matrix(basis, corrections):
    """The numba engine's products, from the points where ``8 k <= s + 4`` (``s`` the functions
    a point touches) and from the assembled pattern otherwise, equal ``N.T diag(m) N f`` made by
    scipy at the points' places, to 1e-13 of the largest entry."""
    scene = block_scene(basis, "iterated", "numba").with_overrides(**{"solver.mass_corrections": corrections})
    simulation = Simulation(scene)
    simulation.project()
    model = simulation.mass
    assert model.assembled == (8 * corrections > simulation.grid.n_local + 4)
    N = simulation.grid.shape_functions(simulation.particles.x)[0]
    field = np.random.default_rng(3).standard_normal((simulation.grid.n_nodes, 2))
    expected = N.T @ (simulation.particles.mass[:, None] * (N @ field))
    np.testing.assert_allclose(model.apply(field), expected, rtol=0, atol=1e-13 * np.abs(expected).max())


@pytest.mark.parametrize("basis", ["q1", "bspline3", "bspline2", "gimp"])
def test_engines_agree_per_step(basis):
    """The compiled engine (the mass pattern's matrix) and scipy's give the same steps to 1e-12."""
    reference = Simulation(block_scene(basis, "iterated", "scipy"))
    compiled = Simulation(block_scene(basis, "iterated", "numba"))
    assert_steps_agree(reference, compiled, steps=8)


def test_the_bar_converges_at_fourth_order_with_three_corrections_and_yoshida4():
    """The bar's exact first mode with cubic splines, ``mass_corrections = 3`` and the
    fourth-order scheme at its own ``dt = "auto"``: the largest displacement error over the run
    falls from h = 0.25 to 0.125 by more than 2^3.5 (measured 4.81e-4 -> 2.37e-5, 20x) and at
    h = 0.125 is below 3e-5 (consistent mass at its own step: 2.44e-5; lumped 1.81e-2)."""
    errors = []
    for spacing in (0.25, 0.125):
        scene = bundled_scene("vibrating_bar_exact").with_overrides(**{
            "grid.basis": "bspline3", "grid.spacing": spacing, "solver.mass": "iterated",
            "solver.mass_corrections": 3, "solver.scheme": "yoshida4"})
        errors.append(Simulation(scene).run().summary["reference"]["error_max"])
    assert errors[0] / errors[1] > 2 ** 3.5
    assert errors[1] < 3e-5


def test_signed_bases_are_refused_with_a_clear_message():
    """q2 and serendipity's row sums can be zero or negative: a one-line scene error."""
    for basis in ("q2", "serendipity"):
        with pytest.raises(SceneError, match="'iterated' divides by the row sums"):
            bundled_variant("vibrating_bar", basis, "iterated")


def test_mirrored_ghosts_are_refused_naming_the_key(tmp_path, capsys):
    """Supports with mirrored ghosts on a basis with ghost columns: one line naming
    ``supports.ghosts`` and the iterated mass, exit code 2, nothing written; on q1 (no ghost
    column, the support fixes its nodes) the same scene runs."""
    from femgrid_mpm import cli
    from femgrid_mpm.scene import BUNDLED_SCENES

    scene = BUNDLED_SCENES / "manufactured_rollers.toml"
    code = cli.main(["run", str(scene), "--mass", "iterated", "--set", "time.end=0.01", "--out", str(tmp_path / "a")])
    error = capsys.readouterr().err
    assert code == 2 and not (tmp_path / "a").exists()
    assert error.count("\n") == 1 and "supports.ghosts: 'mirrored'" in error and 'solver.mass = "iterated"' in error
    code = cli.main(["run", str(scene), "--mass", "iterated", "--basis", "q1", "--set", "time.end=0.01",
                     "--no-progress", "--out", str(tmp_path / "b")])
    assert code == 0
