"""Measurements on runs and the independent references they are compared with.

Examples
--------
>>> import numpy as np
>>> t = np.linspace(0, 10, 2001)
>>> round(zero_crossing_period(t, np.cos(2 * np.pi * t / 3.0)), 6)
3.0
>>> round(bar_axial_period_1d(5.0, 1e4, 0.3, 1e3, "stress"), 3)
3.162
"""

from __future__ import annotations

import numpy as np

from .observers.probe import Probe
from .oscillation import zero_crossing_period  # noqa: F401  (one of the measurements offered here)
from .stability import arpack_start
from .step import StepContext


def modal_velocity_probe(length: float) -> Probe:
    """Mass-weighted projection of the points' x-velocity on ``cos(pi x0 / L)``.

    For the vibrating bar this is the amplitude of the first axial mode.
    """

    def project(ctx: StepContext) -> float:
        p = ctx.particles
        shape = np.cos(np.pi * p.x0[:, 0] / length)
        return float(np.sum(p.mass * p.v[:, 0] * shape) / np.sum(p.mass * shape**2))

    return Probe(project, name="modal_velocity")


def _plane(plane: str) -> str:
    """``plane``, checked: any other word than "stress" was taken for plane strain, without an error."""
    if plane not in ("strain", "stress"):
        raise ValueError(f"plane must be 'strain' or 'stress' (a scene's material.plane), got {plane!r}")
    return plane


def bar_axial_period_1d(length: float, E: float, nu: float, density: float, plane: str) -> float:
    """Free-free rod, first axial mode: ``2 L / c`` with ``c^2 = E' / rho``.

    ``E' = E`` in plane stress and ``E / (1 - nu^2)`` in plane strain.
    """
    modulus = E if _plane(plane) == "stress" else E / (1 - nu**2)
    return float(2 * length / np.sqrt(modulus / density))


def bar_axial_period_2d(
    length: float, height: float, E: float, nu: float, density: float, plane: str, elements_along: int = 40
) -> float:
    """First axial mode of the free-free 2D bar by a converged FE modal analysis.

    An independent reference: scikit-fem's vector Q2 elements, consistent
    mass, ``elements_along`` elements along the bar (40 gives 5 significant
    digits: 3.0261 s plane strain, 3.1671 s plane stress for the paper's
    bar).  The axial mode is the one whose mode shape has the largest mean
    |u_x| relative to |u_y| among the first few elastic modes.
    """
    import skfem
    from scipy.sparse.linalg import eigsh
    from skfem.helpers import dot
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    across = max(2, round(elements_along * height / length))
    mesh = skfem.MeshQuad.init_tensor(np.linspace(0, length, elements_along + 1), np.linspace(0, height, across + 1))
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementQuad2()))
    lam, mu = lame_parameters(E, nu)
    if _plane(plane) == "stress":
        lam = 2 * lam * mu / (lam + 2 * mu)

    @skfem.BilinearForm
    def mass(u, v, w):
        return density * dot(u, v)

    stiffness = skfem.asm(linear_elasticity(lam, mu), basis)
    eigenvalues, modes = eigsh(stiffness, k=8, M=skfem.asm(mass, basis), sigma=-1e-3 * E / density,
                               v0=arpack_start(stiffness.shape[0]))
    order = np.argsort(eigenvalues)[3:]  # three rigid-body modes first
    ux = np.abs(modes[basis.nodal_dofs[0]][:, order]).mean(axis=0)
    uy = np.abs(modes[basis.nodal_dofs[1]][:, order]).mean(axis=0)
    axial = order[np.argmax(ux / (uy + 1e-300))]
    return float(2 * np.pi / np.sqrt(eigenvalues[axial]))
