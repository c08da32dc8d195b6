"""Constitutive laws: linear elasticity in the paper's incremental form (Eq. 6)."""

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

    Stress and strain are stored as (xx, yy, xy) with tensor shear.
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
