"""Critical time step: the largest eigenvalue of ``M^-1 K`` for the actual points and grid.

The explicit step (symplectic Euler in the paper's update order) is stable
while ``omega_max dt < 2``, with ``omega_max^2`` the largest eigenvalue of
``K u = omega^2 M u`` on the free degrees of freedom.  ``K`` is the MPM
stiffness the points integrate, ``sum_p V_p B_p^T D B_p`` (small-strain
tangent of each body's material), and ``M`` the step's own mass, lumped or
consistent, with supports and empty nodes removed.

:func:`critical_time_step` computes it at set-up (once; points that move
far change it, see the stress suite).  The table :data:`BLOCH_FACTORS`
gives the classic full-grid values in units of element width over p-wave
speed, for comparison only: near supports and partly filled cells the true
limit can be far smaller (the cantilever with consistent cubic B-splines:
a mode with 1e-4 of the lumped mass, unstable at the table's step).
Lumped masses that are negative (serendipity corners, q2 past an element
edge) admit no stable step at all, nor does a singular consistent mass
(a mode without inertia; the run then relies on ``consistent_fallback``):
the estimate is then 0.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

#: (basis, mass) -> dt_crit * c_p / element_width on a full, unsupported grid
BLOCH_FACTORS = {
    ("q1", "lumped"): 1.0,
    ("q1", "consistent"): 0.5,
    ("q2", "lumped"): 0.4,
    ("q2", "consistent"): 0.2,
    ("bspline3", "lumped"): 1.9,
    ("bspline3", "consistent"): 0.55,
    ("serendipity", "lumped"): 0.0,
    ("serendipity", "consistent"): 0.2,
    ("bspline3_open", "lumped"): 1.9,
    ("bspline3_open", "consistent"): 0.55,
}


def bloch_time_step(basis: str, mass: str, element_width: float, wave_speed: float) -> float:
    """The table's estimate (s); 0 if no step is stable."""
    factor = BLOCH_FACTORS[(basis, mass)]
    return factor * element_width / wave_speed if wave_speed > 0 else math.inf


def stiffness_matrix(dNdx: sp.csr_matrix, dNdy: sp.csr_matrix, volume: np.ndarray, moduli: np.ndarray) -> sp.csr_matrix:
    """MPM stiffness ``sum_p V_p B_p^T D B_p``, shape (2 n_nodes, 2 n_nodes).

    Parameters
    ----------
    dNdx, dNdy : csr_matrix, shape (n_points, n_nodes)
    volume : ndarray, shape (n_points,)
        Point volumes (m^2).
    moduli : ndarray, shape (n_points, 4)
        ``D_11, D_12, D_22, G`` per point (Pa): the in-plane elasticity
        matrix with engineering shear.

    Degrees of freedom are ordered node by node, (x, y), as ``field.ravel()``
    of a (n_nodes, 2) array.
    """
    def weighted(a, b, w):
        return (a.T @ a.__class__(b.multiply((volume * w)[:, None]))).tocsr()

    d11, d12, d22, shear = moduli.T
    k_xx = weighted(dNdx, dNdx, d11) + weighted(dNdy, dNdy, shear)
    k_yy = weighted(dNdy, dNdy, d22) + weighted(dNdx, dNdx, shear)
    k_xy = weighted(dNdx, dNdy, d12) + weighted(dNdy, dNdx, shear)
    n = dNdx.shape[1]
    # interleave (x, y) per node
    order = np.empty(2 * n, dtype=np.int64)
    order[0::2] = np.arange(n)
    order[1::2] = np.arange(n) + n
    blocks = sp.bmat([[k_xx, k_xy], [k_xy.T, k_yy]], format="csr")
    return blocks[order][:, order].tocsr()


def largest_frequency_squared(stiffness: sp.csr_matrix, mass: sp.spmatrix) -> float:
    """Largest ``omega^2`` of ``K u = omega^2 M u`` (M symmetric positive definite)."""
    n = stiffness.shape[0]
    if n == 0:
        return 0.0
    if n <= 400:  # small problems: dense and exact
        import scipy.linalg as sla

        return float(sla.eigh(stiffness.toarray(), mass.toarray(), eigvals_only=True, subset_by_index=[n - 1, n - 1])[0])
    diagonal = mass.diagonal()
    if sp.issparse(mass) and mass.nnz == np.count_nonzero(diagonal):  # diagonal mass: a symmetric scaling
        scale = sp.diags(1.0 / np.sqrt(diagonal))
        value = spla.eigsh(scale @ stiffness @ scale, k=1, which="LA", tol=1e-4, return_eigenvectors=False)
    else:
        value = spla.eigsh(stiffness, k=1, M=mass.tocsc(), which="LA", tol=1e-4, return_eigenvectors=False)
    return float(value[0])


def critical_time_step(simulation) -> float:
    """``2 / omega_max`` (s) for the simulation's points, grid, supports and mass
    model (as it will be assembled, weak nodes lumped); 0 if no step is stable."""
    grid, p, mass_model = simulation.grid, simulation.particles, simulation.mass
    N, dNdx, dNdy = grid.shape_functions(p.x)
    moduli = np.empty((p.n, 4))
    for material, members in zip(simulation.materials, simulation.body_slices):
        lam, mu = material.lame_lambda, material.shear_modulus
        moduli[members] = [lam + 2 * mu, lam, lam + 2 * mu, mu]
    stiffness = stiffness_matrix(dNdx, dNdy, p.volume, moduli)
    mass_model.assemble(N, p.mass, p.volume)
    free = np.repeat(mass_model.active, 2)
    fixed = _fixed_degrees_of_freedom(simulation)
    if fixed is not None:
        free &= ~fixed.ravel()
    if mass_model.kind == "lumped":
        lumped = np.repeat(mass_model.lumped, 2)[free]
        if np.any(lumped < 0.0):
            return 0.0  # a negative mass: exponential growth at any step
        mass = sp.diags(lumped)
    else:
        mass = sp.kron(mass_model.matrix, sp.identity(2), format="csr")[free][:, free]
    try:
        omega_squared = largest_frequency_squared(stiffness[free][:, free], mass)
    except (np.linalg.LinAlgError, spla.ArpackError, RuntimeError):
        return 0.0  # a singular consistent mass: some mode has no inertia
    return 2.0 / math.sqrt(omega_squared) if omega_squared > 0 else math.inf


def _fixed_degrees_of_freedom(simulation):
    from .effects.base import Stage

    fixed = [action.fixed for _, action in simulation.effects[Stage.CONSTRAIN] if hasattr(action, "fixed")]
    return np.logical_or.reduce(fixed) if fixed else None
