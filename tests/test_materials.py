"""Constitutive laws against independent references.

Neo-Hookean: the Cauchy stress must equal the derivative of the stored
energy, sigma = (1/J) dW/dF F^T (central differences, tolerance 1e-6
relative); a rigid rotation gives no stress; small strains agree with the
linear law to second order.
"""

import numpy as np
import pytest

from femgrid_mpm.materials import LinearElastic, NeoHookean
from femgrid_mpm.particles import Particles

E, NU, RHO = 3.0e5, 0.3, 1.0e3


def one_point(F):
    particles = Particles(
        x=np.zeros((1, 2)), v=np.zeros((1, 2)), mass=np.array([RHO]), density=np.array([RHO]),
        stress=np.zeros((1, 3)), strain=np.zeros((1, 3)), body=np.zeros(1, dtype=np.int32), x0=np.zeros((1, 2)),
        deformation_gradient=np.asarray(F, dtype=float).reshape(1, 4),
    )
    return particles


def stored_energy(material, F):
    return material.strain_energy(one_point(F), slice(0, 1))  # V0 = 1 m^2


@pytest.mark.parametrize("nu", [0.0, 0.3])
def test_neo_hookean_stress_is_the_energy_derivative(nu):
    material = NeoHookean(E, nu, RHO)
    F = np.array([[1.3, 0.2], [-0.1, 0.9]])
    first_piola = np.zeros((2, 2))
    step = 1e-6
    for i in range(2):
        for j in range(2):
            shift = np.zeros((2, 2))
            shift[i, j] = step
            first_piola[i, j] = (stored_energy(material, F + shift) - stored_energy(material, F - shift)) / (2 * step)
    J = np.linalg.det(F)
    expected = first_piola @ F.T / J
    sigma = material.cauchy_stress(F[None])[0]
    np.testing.assert_allclose(sigma, [expected[0, 0], expected[1, 1], expected[0, 1]], rtol=1e-6, atol=1e-6 * E)
    assert abs(expected[0, 1] - expected[1, 0]) < 1e-6 * E  # symmetric, as it must be


def test_neo_hookean_rigid_rotation_is_stress_free_and_objective():
    material = NeoHookean(E, NU, RHO)
    angle = 0.7
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    np.testing.assert_allclose(material.cauchy_stress(R[None]), 0.0, atol=1e-9)
    F = np.array([[1.1, 0.05], [0.0, 0.95]])
    s = material.cauchy_stress(F[None])[0]
    rotated = material.cauchy_stress((R @ F)[None])[0]
    sigma = np.array([[s[0], s[2]], [s[2], s[1]]])
    expected = R @ sigma @ R.T
    np.testing.assert_allclose(rotated, [expected[0, 0], expected[1, 1], expected[0, 1]], rtol=1e-12, atol=1e-9)
    assert stored_energy(material, R) == pytest.approx(0.0, abs=1e-9)


def test_neo_hookean_small_strain_is_linear_elastic():
    """For |grad u| = 1e-5 the two laws differ by O(1e-10) relative to the stress."""
    gradient = 1e-5 * np.array([[1.0, 0.4], [-0.3, 0.5]])
    F = np.eye(2) + gradient
    strain = 0.5 * (gradient + gradient.T)
    linear = LinearElastic(E, NU, RHO).stress_increment(np.array([[strain[0, 0], strain[1, 1], strain[0, 1]]]), out=np.zeros((1, 3)))
    neo = NeoHookean(E, NU, RHO).cauchy_stress(F[None])
    np.testing.assert_allclose(neo, linear, rtol=0, atol=1e-4 * np.abs(linear).max())


def test_neo_hookean_update_composes_increments():
    """F <- (I + dt L) F: two increments of a simple shear add up exactly."""
    material = NeoHookean(E, NU, RHO)
    particles = one_point(np.eye(2))
    increment = np.array([[0.0, 0.01, 0.0, 0.0]])  # dt L with only L_xy
    for _ in range(2):
        material.update(particles, slice(0, 1), np.zeros((1, 3)), increment)
    np.testing.assert_allclose(particles.deformation_gradient, [[1.0, 0.02, 0.0, 1.0]], atol=1e-15)
