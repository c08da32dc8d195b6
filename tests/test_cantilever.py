"""The paper's cantilever (section 4.1) against beam theory.

References (femgrid_mpm.beam_theory, tested on their own): Timoshenko-Goodier
2D elasticity with root condition (b) (the vertical element fixed), which
the grid's clamp is closest to (a fully clamped 2D FE solution lies 80% of
the way from (a) to (b)); Navier's sigma_x = M y / I; the elastica.  Every
comparison uses the force the beam actually receives.
"""

import functools

import numpy as np
import pytest

from femgrid_mpm import beam_theory
from femgrid_mpm.reproduce.cantilever import AXIS_Y, HEIGHT, LENGTH, E, received_force, reference_deflection, simulate
from femgrid_mpm.scene import bundled_scene
from femgrid_mpm.solver import Simulation


@functools.cache
def quasi_static(basis, spacing=0.5, mass="lumped"):
    return simulate("cantilever_quasistatic", **{"grid.basis": basis, "grid.spacing": spacing, "solver.mass": mass})


def tip_ratio(run):
    """Tip deflection (last column, neutral axis) over T&G (b) at the same x."""
    x_tip, _, v_tip = run.tip()
    return -v_tip / reference_deflection(x_tip, run.force, "vertical_element")


def test_paper_eq35_load_is_the_force_over_the_number_of_points():
    """Eq. 35 accelerates one point by F / m_tot: the beam receives F m_p / m_tot,
    F / 288 at the paper's resolution and 16 times less at spacing 0.125."""
    for spacing, points in ((0.5, 288), (0.125, 4608)):
        simulation = Simulation(bundled_scene("cantilever").with_overrides(**{"grid.spacing": spacing}))
        assert simulation.particles.n == points
        assert received_force(simulation) == pytest.approx(100.0 / points, rel=1e-12)


def test_quasi_static_runs_end_at_rest():
    for basis in ("q1", "q2", "bspline3"):
        run = quasi_static(basis)
        assert run.status == "completed" and "at rest" in run.message


@pytest.mark.parametrize("basis", ["q2", "bspline3", "bspline3_open"])
def test_tip_deflection_four_cells_through_the_depth(basis):
    """Within 5% of Timoshenko-Goodier at 4 cells (measured: q2 -0.4%, bspline3 +3.9%, open -0.4%)."""
    assert tip_ratio(quasi_static(basis, 0.25)) == pytest.approx(1.0, abs=0.05)


@pytest.mark.parametrize("basis", ["q2", "bspline3_open"])
def test_tip_deflection_eight_cells_through_the_depth(basis):
    """Within 2.5% at 8 cells.  (The paper's ghost column is +1.6% here: it
    converges only at first order, which the open knots fix.)"""
    assert tip_ratio(quasi_static(basis, 0.125)) == pytest.approx(1.0, abs=0.025)


def test_ghost_column_support_is_too_soft_and_converges_slowly():
    """bspline3 with the paper's extra column: +10% at 2 cells, halving per refinement;
    open knots: within 2% already at 2 cells."""
    coarse, fine = tip_ratio(quasi_static("bspline3", 0.5)), tip_ratio(quasi_static("bspline3", 0.25))
    assert coarse > 1.07 and 1.0 < fine < coarse
    assert abs(tip_ratio(quasi_static("bspline3_open", 0.5)) - 1) < 0.02


def test_q1_locks_and_the_gap_narrows():
    """At 2 cells through the depth q1 deflects less than the cubic splines; the
    gap closes under refinement (shear locking of bilinear elements in bending)."""
    gap_coarse = tip_ratio(quasi_static("bspline3_open", 0.5)) - tip_ratio(quasi_static("q1", 0.5))
    gap_fine = tip_ratio(quasi_static("bspline3_open", 0.25)) - tip_ratio(quasi_static("q1", 0.25))
    assert gap_coarse > 0.05
    assert 0 < gap_fine < gap_coarse / 2


@pytest.mark.parametrize("basis,tolerance", [("q2", 0.10), ("bspline3", 0.05), ("bspline3_open", 0.05)])
def test_top_fibre_stress_near_mid_span_is_navier(basis, tolerance):
    """sigma_x at the points nearest the top fibre within 1 m of mid-span, at 4 cells
    through the depth, against M y / I evaluated at those points."""
    run = quasi_static(basis, 0.25)
    p = run.particles
    chosen = np.flatnonzero(np.isclose(p.x0[:, 1], p.x0[:, 1].max()) & (np.abs(p.x0[:, 0] - LENGTH / 2) <= 1.0))
    assert len(chosen) >= 8
    navier = beam_theory.navier_stress(p.x0[chosen, 0], p.x0[chosen, 1] - AXIS_Y, run.force, LENGTH, beam_theory.second_moment_of_area(HEIGHT))
    np.testing.assert_allclose(p.stress[chosen, 0], navier, rtol=tolerance)


def test_q2_masses_stay_positive_under_the_small_load():
    for spacing in (0.5, 0.25):
        run = simulate("cantilever_quasistatic", **{"grid.basis": "q2", "grid.spacing": spacing, "solver.negative_mass": "error"})
        assert run.status == "completed"  # the "error" policy would have stopped it


def test_consistent_and_lumped_mass_reach_the_same_equilibrium():
    """Statics does not depend on the mass matrix (supports must be left out of
    the consistent solve, not zeroed after it)."""
    lumped, consistent = quasi_static("q1"), quasi_static("q1", mass="consistent")
    assert consistent.tip()[2] == pytest.approx(lumped.tip()[2], rel=1e-4)


def test_paper_protocol_is_not_quasi_static():
    """Ramped over 20 s with a 23 s bending period, the tip overshoots the static value."""
    paper = simulate("cantilever", **{"grid.basis": "bspline3"})
    assert paper.tip()[2] / quasi_static("bspline3").tip()[2] > 1.1


@pytest.mark.parametrize("model", ["linear_elastic", "neo_hookean"])
def test_large_rotation_against_the_elastica(model):
    """F = 800 in full: alpha = 2.05, tip rotation 45 degrees.  Open-knot splines at
    2 cells through the depth land within 3% of the elastica's tip drop (shear
    adds ~1%), where linear theory is 36% off."""
    run = simulate("cantilever_large", **{"grid.basis": "bspline3_open", "bodies.0.material.model": model})
    elastica = beam_theory.elastica_tip(800.0, LENGTH, E, beam_theory.second_moment_of_area(HEIGHT))
    _, u_tip, v_tip = run.tip()
    assert -v_tip == pytest.approx(elastica.deflection, rel=0.03)
    assert -u_tip == pytest.approx(elastica.shortening, rel=0.06)
    linear = beam_theory.euler_bernoulli_tip_deflection(800.0, LENGTH, E, beam_theory.second_moment_of_area(HEIGHT))
    assert linear / elastica.deflection > 1.3
