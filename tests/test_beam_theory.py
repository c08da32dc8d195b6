"""The cantilever references of femgrid_mpm.beam_theory against independent values.

Independent values used here: the strains of the T&G displacement field
(by finite differences) pushed through Hooke's law; the paper's Eqs. 33-34
transcribed literally in T&G's own frame; Gauss quadrature of the
tractions; the linear limits PL^3/3EI and PL^2/2EI; Mattiasson's (1981)
elliptic-integral table of the elastica (Bisshopp & Drucker's problem,
5 digits); and beta_1 L = 1.8751 for the clamped-free beam.
"""

import numpy as np
import pytest

from femgrid_mpm.beam_theory import (
    ROOT_CONDITIONS,
    cantilever_bending_period,
    cantilever_bending_period_fe,
    clamped_free_eigenvalue,
    clamped_tip_deflection_fe,
    elastica_shape,
    elastica_tip,
    euler_bernoulli_tip_deflection,
    euler_bernoulli_tip_rotation,
    load_parameter,
    navier_stress,
    plane_elastic_constants,
    second_moment_of_area,
    timoshenko_beam_tip_deflection,
    timoshenko_goodier_displacement,
    timoshenko_goodier_stress,
    timoshenko_goodier_tip_deflection,
)

# The paper's beam (section 4.1).
L, H, E, NU, RHO = 8.0, 1.0, 3e5, 0.0, 1e3
I = second_moment_of_area(H)

# Sample points over the whole beam, corners included.
GRID_X, GRID_Y = np.meshgrid(np.linspace(0.0, L, 9), np.linspace(-H / 2, H / 2, 7))


def derivative(function, x, y, axis, step=1e-3):
    """Fourth-order central difference: exact for the cubic T&G field up to round-off."""
    dx, dy = (step, 0.0) if axis == 0 else (0.0, step)
    values = [np.asarray(function(x + k * dx, y + k * dy)) for k in (-2, -1, 1, 2)]
    return (values[0] - 8 * values[1] + 8 * values[2] - values[3]) / (12 * step)


def stresses_from_displacement(P, nu, plane, root):
    """Strains of the displacement field by finite differences, then in-plane Hooke's law."""

    def u(x, y):
        return timoshenko_goodier_displacement(x, y, P, L, H, E, nu, root=root, plane=plane)[0]

    def v(x, y):
        return timoshenko_goodier_displacement(x, y, P, L, H, E, nu, root=root, plane=plane)[1]

    eps_x = derivative(u, GRID_X, GRID_Y, 0)
    eps_y = derivative(v, GRID_X, GRID_Y, 1)
    gamma = derivative(u, GRID_X, GRID_Y, 1) + derivative(v, GRID_X, GRID_Y, 0)
    G = E / (2 * (1 + nu))
    if plane == "stress":
        factor = E / (1 - nu**2)
        return factor * (eps_x + nu * eps_y), factor * (eps_y + nu * eps_x), G * gamma
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    return (lam + 2 * G) * eps_x + lam * eps_y, (lam + 2 * G) * eps_y + lam * eps_x, G * gamma


@pytest.mark.parametrize("root", ROOT_CONDITIONS)
@pytest.mark.parametrize("nu, plane", [(0.0, "strain"), (0.3, "stress"), (0.3, "strain")])
def test_tg_displacement_gives_the_tg_stress(root, nu, plane):
    """sigma_x = P (L - x) y / I, sigma_y = 0, parabolic tau, to 1e-8 of each field's scale."""
    P = 100.0
    sigma_x, sigma_y, tau = stresses_from_displacement(P, nu, plane, root)
    expected_x, _, expected_tau = timoshenko_goodier_stress(GRID_X, GRID_Y, P, L, H)
    bending_scale, shear_scale = P * L * (H / 2) / I, 1.5 * P / H
    assert np.max(np.abs(sigma_x - expected_x)) < 1e-8 * bending_scale
    assert np.max(np.abs(sigma_y)) < 1e-8 * bending_scale
    assert np.max(np.abs(tau - expected_tau)) < 1e-8 * shear_scale


def test_tg_stress_is_navier_and_balances_the_load():
    """Tension on top for a downward load; tip shear sums to -P; root moment is P L (Gauss, exact)."""
    P = 100.0
    assert navier_stress(0.0, H / 2, P, L, I) > 0
    sigma_x, sigma_y, _ = timoshenko_goodier_stress(GRID_X, GRID_Y, P, L, H)
    np.testing.assert_allclose(sigma_x, navier_stress(GRID_X, GRID_Y, P, L, I), rtol=0, atol=1e-12)
    assert np.all(sigma_y == 0)

    nodes, weights = np.polynomial.legendre.leggauss(4)
    y, w = nodes * H / 2, weights * H / 2
    tip_shear = np.sum(w * timoshenko_goodier_stress(L, y, P, L, H)[2])
    root_moment = np.sum(w * y * timoshenko_goodier_stress(0.0, y, P, L, H)[0])
    assert tip_shear == pytest.approx(-P, rel=1e-13)
    assert root_moment == pytest.approx(P * L, rel=1e-13)


def paper_eqs_33_34(x_tg, y_tg, P, l, c, E, nu):
    """The paper's Eqs. 33-34 as printed: T&G frame, load at x = 0, support at x = l, y down."""
    G, inertia = E / (2 * (1 + nu)), 2 * c**3 / 3
    u = (
        -P * x_tg**2 * y_tg / (2 * E * inertia)
        - nu * P * y_tg**3 / (6 * E * inertia)
        + P * y_tg**3 / (6 * G * inertia)
        + (P * l**2 / (2 * E * inertia) - P * c**2 / (2 * G * inertia)) * y_tg
    )
    v = (
        nu * P * x_tg * y_tg**2 / (2 * E * inertia)
        + P * x_tg**3 / (6 * E * inertia)
        - P * l**2 * x_tg / (2 * E * inertia)
        + P * l**3 / (3 * E * inertia)
    )
    return u, v


def test_horizontal_element_root_is_the_papers_eqs_33_34():
    """Mapping x_TG = L - x, y_TG = -y reverses both displacement components."""
    P, nu = 100.0, 0.3
    u, v = timoshenko_goodier_displacement(GRID_X, GRID_Y, P, L, H, E, nu, root="horizontal_element")
    u_tg, v_tg = paper_eqs_33_34(L - GRID_X, -GRID_Y, P, L, H / 2, E, nu)
    scale = euler_bernoulli_tip_deflection(P, L, E, I)
    np.testing.assert_allclose(u, -u_tg, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(v, -v_tg, rtol=0, atol=1e-13 * scale)


@pytest.mark.parametrize("root, constrained", [("horizontal_element", "dv/dx"), ("vertical_element", "du/dy")])
def test_root_conditions(root, constrained):
    """Both roots pin the axis point; each fixes its own material element and not the other."""
    P, nu = 100.0, 0.3

    def component(index):
        return lambda x, y: timoshenko_goodier_displacement(x, y, P, L, H, E, nu, root=root)[index]

    assert np.allclose(timoshenko_goodier_displacement(0.0, 0.0, P, L, H, E, nu, root=root), 0.0, atol=1e-15)
    slopes = {"dv/dx": derivative(component(1), 0.0, 0.0, 0), "du/dy": derivative(component(0), 0.0, 0.0, 1)}
    shear_angle = P * (H / 2) ** 2 / (2 * E / (2 * (1 + nu)) * I)
    assert abs(slopes[constrained]) < 1e-12 * shear_angle
    other = "du/dy" if constrained == "dv/dx" else "dv/dx"
    assert abs(slopes[other]) == pytest.approx(shear_angle, rel=1e-8)


def test_tg_tip_deflections():
    """Case a is P L^3 / 3EI exactly; case b adds 3 P L / (2 G H), a Timoshenko beam with k = 2/3."""
    P, nu = 100.0, 0.3
    G = E / (2 * (1 + nu))
    bending = euler_bernoulli_tip_deflection(P, L, E, I)
    assert timoshenko_goodier_tip_deflection(P, L, H, E, nu, "horizontal_element") == pytest.approx(bending, rel=1e-14)
    with_shear = timoshenko_goodier_tip_deflection(P, L, H, E, nu, "vertical_element")
    assert with_shear == pytest.approx(bending + 1.5 * P * L / (G * H), rel=1e-14)
    assert with_shear == pytest.approx(timoshenko_beam_tip_deflection(P, L, E, G, H, shear_coefficient=2 / 3))
    # The nu term vanishes at the tip: the whole tip section drops by the same amount.
    _, v_tip = timoshenko_goodier_displacement(L, np.linspace(-H / 2, H / 2, 5), P, L, H, E, nu)
    np.testing.assert_allclose(v_tip, -bending, rtol=1e-14)


def test_plane_strain_constants_keep_the_shear_modulus():
    E_strain, nu_strain = plane_elastic_constants(E, 0.3, "strain")
    assert E_strain == pytest.approx(E / 0.91)
    assert E_strain / (2 * (1 + nu_strain)) == pytest.approx(E / 2.6, rel=1e-14)
    assert plane_elastic_constants(E, 0.0, "strain") == plane_elastic_constants(E, 0.0, "stress")
    with pytest.raises(ValueError):
        plane_elastic_constants(E, 0.3, "axisymmetric")
    with pytest.raises(ValueError):
        timoshenko_goodier_displacement(0.0, 0.0, 1.0, L, H, E, 0.0, root="clamped")


def test_full_clamp_lies_between_the_tg_roots_nearer_b():
    """Static Q2 FE with the whole root section fixed (like the grid clamp), nu = 0.

    Measured: 0.68905 at P = 100, 80% of the way from case a (0.68267) to
    case b (0.69067); stiffer than b because it stops the root warping.
    """
    P = 100.0
    clamp = clamped_tip_deflection_fe(P, L, H, E, NU)
    case_a = timoshenko_goodier_tip_deflection(P, L, H, E, NU, "horizontal_element")
    case_b = timoshenko_goodier_tip_deflection(P, L, H, E, NU, "vertical_element")
    assert 0.7 < (clamp - case_a) / (case_b - case_a) < 0.9
    assert clamp == pytest.approx(timoshenko_beam_tip_deflection(P, L, E, E / 2, H), rel=2e-4)


def test_elastica_small_load_is_linear():
    """alpha = 0.01: deflection alpha/3, rotation alpha/2, shortening alpha^2/15 (integral of w'^2 / 2)."""
    alpha = 0.01
    for method in ("elliptic", "shooting"):
        tip = elastica_tip(alpha, 1.0, 1.0, 1.0, method=method)
        assert tip.deflection == pytest.approx(euler_bernoulli_tip_deflection(alpha, 1.0, 1.0, 1.0), rel=1e-3)
        assert tip.rotation == pytest.approx(euler_bernoulli_tip_rotation(alpha, 1.0, 1.0, 1.0), rel=1e-3)
        assert tip.shortening == pytest.approx(alpha**2 / 15, rel=1e-3)


# Mattiasson (1981), IJNME 17:145-153, Table 1: PL^2/EI -> (w/L, u/L) at the tip,
# the Bisshopp & Drucker (1945) problem to 5 digits (quoted via a public test suite).
PUBLISHED_ELASTICA = {1.0: (0.30172, 0.05643), 2.0: (0.49346, 0.16064), 5.0: (0.71379, 0.38763), 10.0: (0.81061, 0.55500)}


@pytest.mark.parametrize("alpha", sorted(PUBLISHED_ELASTICA))
def test_elastica_matches_published_table(alpha):
    """Within the table's rounding, half a unit in the 5th decimal."""
    deflection, shortening = PUBLISHED_ELASTICA[alpha]
    tip = elastica_tip(alpha, 1.0, 1.0, 1.0)
    assert tip.deflection == pytest.approx(deflection, abs=5e-6)
    assert tip.shortening == pytest.approx(shortening, abs=5e-6)


@pytest.mark.parametrize("alpha", [0.01, 0.256, 1.0, 2.048, 5.0, 10.0, 100.0])
def test_elastica_methods_agree(alpha):
    """Elliptic closed form against shooting on the ODE, 1e-8 of the length (rad for the rotation)."""
    P, length, modulus, inertia = alpha * 3.0, 2.0, 3.0, 4.0  # P L^2 / EI = alpha, lengths not 1
    assert load_parameter(P, length, modulus, inertia) == pytest.approx(alpha)
    closed = elastica_tip(P, length, modulus, inertia)
    shooting = elastica_tip(P, length, modulus, inertia, method="shooting")
    np.testing.assert_allclose(closed, shooting, rtol=0, atol=1e-8 * length)


def test_elastica_sign_and_zero_load():
    down, up = elastica_tip(800.0, L, E, I), elastica_tip(-800.0, L, E, I)
    assert down.deflection > 0 and down.rotation > 0
    assert up == pytest.approx((-down.deflection, down.shortening, -down.rotation), rel=1e-14)
    assert elastica_tip(0.0, L, E, I) == (0.0, 0.0, 0.0)


def test_elastica_shape_is_inextensible_and_ends_at_the_tip():
    P = 800.0
    x, y = elastica_shape(P, L, E, I, n=2001)
    tip = elastica_tip(P, L, E, I)
    assert (x[0], y[0]) == (0.0, 0.0)
    assert x[-1] == pytest.approx(L - tip.shortening, abs=1e-9 * L)
    assert y[-1] == pytest.approx(-tip.deflection, abs=1e-9 * L)
    assert np.sum(np.hypot(np.diff(x), np.diff(y))) == pytest.approx(L, rel=1e-6)  # chords of equal arcs
    assert np.arctan2(y[1] - y[0], x[1] - x[0]) == pytest.approx(0.0, abs=1e-3)  # clamped: leaves horizontally


def test_paper_beam_f800_is_strongly_nonlinear():
    """alpha = 2.048: the tip turns about 45.5 deg; linear theory overestimates the deflection by ~36%."""
    P = 800.0
    tip = elastica_tip(P, L, E, I)
    assert np.degrees(tip.rotation) == pytest.approx(45.5, abs=0.1)
    assert euler_bernoulli_tip_deflection(P, L, E, I) / tip.deflection == pytest.approx(1.365, abs=2e-3)


def test_euler_bernoulli_period():
    """beta_1 L = 1.8751 (tables), T = 2 pi / ((1.8751 / L)^2 sqrt(EI / rho A)) = 22.874 s."""
    assert clamped_free_eigenvalue() == pytest.approx(1.8751, abs=5e-5)
    expected = 2 * np.pi / ((1.8751 / L) ** 2 * np.sqrt(E * I / (RHO * H)))
    assert cantilever_bending_period(L, H, E, NU, RHO) == pytest.approx(expected, rel=1e-4)
    strain, stress = (cantilever_bending_period(L, H, E, 0.3, RHO, plane) for plane in ("strain", "stress"))
    assert strain / stress == pytest.approx(np.sqrt(1 - 0.3**2), rel=1e-14)


def test_fe_period_against_euler_bernoulli():
    """2D FE is longer by shear and rotary inertia: a Timoshenko beam (k = 5/6) predicts +1.02% at L/H = 8.

    Measured: 23.1065 s against 22.874 s (+1.02%); converged (16 vs 32 elements: 1e-4).
    """
    fe = cantilever_bending_period_fe(L, H, E, NU, RHO)
    assert 0.005 < fe / cantilever_bending_period(L, H, E, NU, RHO) - 1 < 0.015
    assert cantilever_bending_period_fe(L, H, E, NU, RHO, elements_along=16) == pytest.approx(fe, rel=2e-4)
    # Plane strain stiffens bending by 1 / (1 - nu^2): periods scale by sqrt(1 - nu^2), shear aside.
    strain, stress = (cantilever_bending_period_fe(L, H, E, 0.3, RHO, plane) for plane in ("strain", "stress"))
    assert strain / stress == pytest.approx(np.sqrt(1 - 0.3**2), rel=2e-3)
