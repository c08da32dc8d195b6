"""Supports with mirrored ghost nodes (``ghosts = "mirrored"``): the ghost-column splines'
extra column tied to its mirror image across the wall (femgrid_mpm/mass/constraint.py)."""

import sys
from pathlib import Path

import numpy as np
import pytest

from femgrid_mpm.effects import Support
from femgrid_mpm.grid import Grid
from femgrid_mpm.mass import NodeConstraint
from femgrid_mpm.scene.loading import bundled_scene
from femgrid_mpm.solver import Simulation

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "experiments"))
from error_sources import run  # noqa: E402

WALL = np.linspace(0.01, 0.99, 23)


def constraint_of(grid, supports):
    held = [support.fixed(grid) for support in supports]
    return NodeConstraint.combine(grid.n_nodes, np.logical_or.reduce(held),
                                  [support.mirror(grid) for support in supports])


@pytest.mark.parametrize("basis", ["bspline3", "bspline2"])
def test_a_mirrored_wall_is_a_roller_and_a_clamp_for_any_reduced_velocity(basis):
    """Rollers on x = 0 and y = 0, a clamp on x = 1: for a random reduced velocity w, the field
    of v = T w has, on x = 0, v_x = 0 and d v_y / dx = 0 (no shear strain rate: no shear
    traction); on y = 0 the same with x and y swapped, corner included; on x = 1, v = 0.  To
    1e-13 of |w|; without the mirror (fixed ghosts) v_x on x = 0 is of the order of w."""
    grid = Grid(basis, [0.0, 0.0], [1.0, 1.0], 0.125)
    supports = [Support(where="x <= 0", fix=("x",), ghosts="mirrored"),
                Support(where="y <= 0", fix=("y",), ghosts="mirrored"),
                Support(where="x >= 1", fix=("x", "y"), ghosts="mirrored")]
    constraint = constraint_of(grid, supports)
    w = np.random.default_rng(3).normal(size=(grid.n_nodes, 2))
    v = constraint.unfold(w)
    zero = np.zeros_like(WALL)
    for wall, normal in ((np.column_stack([zero, WALL]), 0), (np.column_stack([WALL, zero]), 1)):
        N, dNdx, dNdy = grid.shape_functions(wall)
        gradient = (dNdx, dNdy)[normal]
        np.testing.assert_allclose(N @ v[:, normal], 0.0, atol=1e-13)
        np.testing.assert_allclose(gradient @ v[:, 1 - normal], 0.0, atol=1e-13)
        assert np.abs(N @ w[:, normal]).max() > 0.1  # the unconstrained field does not vanish there
    N, _, _ = grid.shape_functions(np.column_stack([zero + 1.0, WALL]))
    np.testing.assert_allclose(N @ v, 0.0, atol=1e-13)


def test_fold_is_the_transpose_of_unfold():
    """<T.T a, b> = <a, T b> for random a, b (the reduced mass T.T M T is symmetric), to 1e-12."""
    grid = Grid("bspline3", [0.0, 0.0], [1.0, 1.0], 0.25)
    constraint = constraint_of(grid, [Support(where="x >= 1", fix=("x",), ghosts="mirrored"),
                                      Support(where="y >= 1", fix=("x", "y"), ghosts="mirrored")])
    a, b = np.random.default_rng(5).normal(size=(2, grid.n_nodes, 2))
    b = np.where(constraint.free, b, 0.0)
    assert np.sum(constraint.fold(a) * b) == pytest.approx(np.sum(a * constraint.unfold(b)), rel=1e-12)


def rollers(basis, mass, spacing, ghosts="mirrored"):
    """The bundled mode on rollers, 2 x 2 points, dt = T / (37.5 / h) (docs/accuracy.md)."""
    scene = bundled_scene("manufactured_rollers")
    supports = [dict(where=s.where, fix=list(s.fix), ghosts=ghosts) for s in scene.supports]
    return scene.with_overrides(**{"grid.basis": basis, "solver.mass": mass, "grid.spacing": spacing,
                                   "time.dt": scene.time.end / round(37.5 / spacing), "supports": supports,
                                   "output.energy": False})


def test_cubic_splines_with_mirrored_rollers_converge_faster_than_second_order():
    """Consistent cubic splines on the mode on rollers: measured 1.15e-4 and 2.23e-5 at h = 1/8
    and 1/16 (order 2.4, the step's time error in the second); with fixed ghosts 0.447 (not a
    roller), open knots 1.42e-2.  Asserted: below 1.5e-4 and 3e-5, a ratio above 4, fixed
    ghosts above 0.3."""
    coarse = run(rollers("bspline3", "consistent", 1 / 8))["whole"]
    fine = run(rollers("bspline3", "consistent", 1 / 16))["whole"]
    assert coarse < 1.5e-4 and fine < 3e-5 and coarse / fine > 4
    assert run(rollers("bspline3", "consistent", 1 / 8, ghosts="fixed"))["whole"] > 0.3


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_a_rigid_translation_along_a_roller_wall_stays_exact(mass):
    """A block resting on the roller wall y = 0 (mirrored), moving at (0.3, 0) m/s: 30 steps move
    every point by 0.3 t along x and not at all along y, to 1e-13 m."""
    scene = bundled_scene("manufactured_rollers").with_overrides(**{
        "grid.basis": "bspline3", "solver.mass": mass, "grid.upper": [2.0, 1.0], "grid.spacing": 0.125,
        "bodies.0.lower": [0.5, 0.0], "bodies.0.upper": [1.5, 0.5], "bodies.0.velocity": [0.3, 0.0],
        "supports": [{"where": "y <= 0", "fix": ["y"], "ghosts": "mirrored"}], "reference": None,
        "time.dt": 0.001, "time.end": 0.03, "output.energy": False})
    simulation = Simulation(scene)
    p = simulation.run().particles
    np.testing.assert_allclose(p.x - p.x0, np.column_stack([np.full(p.n, 0.3 * simulation.time), np.zeros(p.n)]),
                               rtol=0, atol=1e-13)


def test_bases_without_a_ghost_column_fix_their_edge_nodes_as_fixed_ghosts_do():
    """q1: ghosts = "mirrored" builds no constraint and runs bit for bit as "fixed" (20 steps)."""
    final = {}
    for ghosts in ("fixed", "mirrored"):
        scene = rollers("q1", "lumped", 1 / 8, ghosts).with_overrides(**{"time.end": 0.02})
        simulation = Simulation(scene)
        assert simulation.constraint is None
        final[ghosts] = simulation.run().particles.x
    assert np.array_equal(final["fixed"], final["mirrored"])


def test_a_mirrored_wall_must_be_a_half_plane_of_nodes():
    grid = Grid("bspline3", [0.0, 0.0], [1.0, 1.0], 0.25)
    with pytest.raises(ValueError, match="one side of a grid line"):
        Support(where="x <= 0 or y <= 0", fix=("x",), ghosts="mirrored").mirror(grid)


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_the_engines_agree_with_mirrored_rollers(mass):
    """scipy and numba, 60 steps of the mode on rollers at h = 1/8: positions equal to 1e-15 m
    (measured: bit for bit)."""
    final = []
    for engine in ("numba", "scipy"):
        scene = bundled_scene("manufactured_rollers").with_overrides(**{
            "solver.engine": engine, "solver.mass": mass, "grid.spacing": 0.125, "time.end": 0.1,
            "output.energy": False})
        final.append(Simulation(scene).run().particles.x)
    np.testing.assert_allclose(final[0], final[1], rtol=0, atol=1e-15)


def test_a_singular_constrained_consistent_mass_stops_the_run_in_one_line():
    """One point per cell: the cubic splines' consistent mass is singular, reduced or not; the
    run stops with the singular-mass message (not a traceback)."""
    from femgrid_mpm.diagnostics import SimulationStopped

    scene = rollers("bspline3", "consistent", 1 / 8).with_overrides(**{"bodies.0.points_per_cell": 1,
                                                                        "time.end": 0.01})
    with pytest.raises(SimulationStopped, match="singular"):
        Simulation(scene).run()
