"""Constitutive laws, one class each, selected by ``material.model`` in a scene.

A material updates the stress of its own points once per step from the
step's displacement-gradient increment ``dt * L`` (and the strain increment,
its symmetric part), and knows its stored energy for the energy ledger.

* :class:`LinearElastic` (``"linear_elastic"``): the paper's hypo-elastic
  increment, ``d(sigma) = D : d(epsilon)`` (Eq. 6).  Not objective: under
  large rotation the stress does not rotate with the material.
* :class:`NeoHookean` (``"neo_hookean"``): compressible neo-Hookean on the
  deformation gradient, ``F <- (I + dt L) F``; objective, hyperelastic
  (exact stored energy), the finite-strain option for large rotations.

Stress and strain are stored as (xx, yy, xy) with tensor shear; the
deformation gradient as (F_xx, F_xy, F_yx, F_yy).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LinearElastic:
    """Hypo-elastic linear law, ``d(sigma) = D : d(epsilon)`` (paper Eq. 6).

    Parameters
    ----------
    E : float
        Young's modulus (Pa).
    nu : float
        Poisson's ratio, in (-1, 0.5).
    density : float
        Initial mass density (kg/m^3).
    plane : {"strain", "stress"}
        2D idealisation.
    """

    E: float
    nu: float
    density: float
    plane: str = "strain"

    @property
    def shear_modulus(self) -> float:
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lame_lambda(self) -> float:
        """The in-plane lambda: 3D lambda in plane strain, 2*lambda*mu/(lambda + 2*mu) in plane stress."""
        if self.plane == "stress":
            return self.E * self.nu / (1.0 - self.nu**2)
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def p_wave_modulus(self) -> float:
        """lambda + 2 mu (Pa): stiffness of in-plane compression."""
        return self.lame_lambda + 2.0 * self.shear_modulus

    @property
    def wave_speed(self) -> float:
        """Dilatational (p-)wave speed (m/s) at the initial density."""
        return float(np.sqrt(self.p_wave_modulus / self.density))

    def stress_increment(self, strain_increment: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Add ``D : d(epsilon)`` to ``out`` in place.

        Parameters
        ----------
        strain_increment : ndarray, shape (n, 3)
        out : ndarray, shape (n, 3)
            Stress to update (Pa).
        """
        lam, mu = self.lame_lambda, self.shear_modulus
        volumetric = strain_increment[:, 0] + strain_increment[:, 1]
        out[:, 0] += lam * volumetric + 2.0 * mu * strain_increment[:, 0]
        out[:, 1] += lam * volumetric + 2.0 * mu * strain_increment[:, 1]
        out[:, 2] += 2.0 * mu * strain_increment[:, 2]
        return out

    def update(self, particles, members: slice, strain_increment: np.ndarray, gradient_increment: np.ndarray) -> None:
        """One step for the points ``members``: Eq. 6."""
        self.stress_increment(strain_increment[members], out=particles.stress[members])

    def strain_energy(self, particles, members: slice) -> float:
        """Paper Eq. 27, ``1/2 sum V sigma : epsilon`` (J per unit thickness)."""
        weights = np.array([1.0, 1.0, 2.0])  # tensor shear counts twice
        volume = particles.mass[members] / particles.density[members]
        return 0.5 * float(np.einsum("p,pk,pk,k->", volume, particles.stress[members], particles.strain[members], weights))


@dataclass(frozen=True)
class NeoHookean(LinearElastic):
    """Compressible neo-Hookean solid in plane strain (``F_zz = 1``).

    ``sigma = mu / J (b - I) + lambda ln(J) / J I`` with ``b = F F^T`` and
    ``J = det F``; stored energy per reference volume
    ``W = mu / 2 (tr b + 1 - 3) - mu ln J + lambda / 2 (ln J)^2``.  ``E``
    and ``nu`` give the small-strain ``mu`` and ``lambda``, so small
    deformations agree with :class:`LinearElastic`.
    """

    def update(self, particles, members: slice, strain_increment: np.ndarray, gradient_increment: np.ndarray) -> None:
        F = particles.deformation_gradient[members].reshape(-1, 2, 2)
        increment = gradient_increment[members].reshape(-1, 2, 2) + np.eye(2)
        F = np.matmul(increment, F)
        particles.deformation_gradient[members] = F.reshape(-1, 4)
        particles.stress[members] = self.cauchy_stress(F)

    def cauchy_stress(self, F: np.ndarray) -> np.ndarray:
        """Cauchy stress (xx, yy, xy), shape (n, 3), from ``F`` of shape (n, 2, 2)."""
        lam, mu = self.lame_lambda, self.shear_modulus
        J = F[:, 0, 0] * F[:, 1, 1] - F[:, 0, 1] * F[:, 1, 0]
        b = np.matmul(F, np.swapaxes(F, 1, 2))
        # a crushed point (J <= 0) gives NaN here, which stops the run by name (the state is
        # no longer finite, at that point): numpy's own warning would only come before it
        with np.errstate(invalid="ignore", divide="ignore"):
            pressure_like = (lam * np.log(J) - mu) / J
            return np.column_stack([
                mu / J * b[:, 0, 0] + pressure_like,
                mu / J * b[:, 1, 1] + pressure_like,
                mu / J * b[:, 0, 1],
            ])

    def strain_energy(self, particles, members: slice) -> float:
        """``sum V_0 W(F)`` (J per unit thickness), ``V_0 = m / rho_0``."""
        lam, mu = self.lame_lambda, self.shear_modulus
        F = particles.deformation_gradient[members]
        J = F[:, 0] * F[:, 3] - F[:, 1] * F[:, 2]
        trace_b = np.einsum("pk,pk->p", F, F)  # F_xx^2 + F_xy^2 + F_yx^2 + F_yy^2
        with np.errstate(invalid="ignore", divide="ignore"):  # a crushed point: NaN, see cauchy_stress
            log_J = np.log(J)
            density = 0.5 * mu * (trace_b - 2.0) - mu * log_J + 0.5 * lam * log_J**2
        return float(np.sum(particles.mass[members] / self.density * density))


MODELS = {"linear_elastic": LinearElastic, "neo_hookean": NeoHookean}


def make_material(spec) -> LinearElastic:
    """The material of a scene's ``material`` table."""
    return MODELS[spec.model](spec.E, spec.nu, spec.density, spec.plane)
