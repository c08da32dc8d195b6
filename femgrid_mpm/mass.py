"""Grid mass: lumped (paper Eqs. 15-16) and consistent (Eqs. 10, 17, 19, 20).

Both models share one interface: ``assemble(N, m_p)`` once per step, then
``solve(rhs)`` for the nodal velocities (rhs = momentum, Eq. 17) and for the
nodal accelerations (rhs = force, Eq. 10).  Nodes that no point touches are
*inactive*: their solution is zero.  ``lumped`` (the row sums, Eq. 15) is
always available for diagnostics.

Consistent mass and its singularities
-------------------------------------
``M = N.T @ diag(m_p) @ N`` is positive semi-definite.  It is singular when
a node's function is seen by too few points to fix its value, e.g. a node
touched only by the far edge of a body, or, globally, a body with fewer
points across than basis functions span it (cubic B-splines with 2 points
per cell in a body 2 cells thick).  Momentum always lies in the range of
``M`` (so velocities *at the points* are right), but internal forces in
general do not, and velocity *gradients* there are arbitrary.  We treat it
in three layers:

1. *Empty nodes* (``M_ii = 0``) are removed: identity rows, zero solution.
2. *Weak nodes* of non-negative bases (q1, bspline3), whose material volume
   fraction ``(N.T @ V_p)_i / integral(phi_i)`` is below ``weak_fraction``,
   are lumped: each coupling ``M_ij`` to a weak node is moved onto both
   diagonals.  This keeps every row sum (so rigid motion and momentum stay
   exact) and only adds positive semi-definite terms, so it never makes the
   matrix less definite.
3. What remains singular is *detected*: preconditioned CG then fails to
   converge on the force system.  The ``fallback`` policy decides:
   ``"error"`` raises :class:`SingularMassError`; ``"blend"`` solves with
   ``(1 - blend) M + blend * diag(lumped)`` for that step, counts the event
   and goes on.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp


class SingularMassError(RuntimeError):
    """The consistent mass matrix could not be solved (singular or nearly)."""


@dataclass
class LumpedMass:
    """Row-sum (lumped) nodal masses, Eq. 15; the solve is a division, Eq. 16.

    Parameters
    ----------
    n_nodes : int
    reference_mass : float
        Mass of one full lattice cell (kg); masses with ``|m_i|`` below
        ``1e-12 * reference_mass`` count as empty.
    """

    n_nodes: int
    reference_mass: float
    kind = "lumped"
    lumped: np.ndarray = field(init=False, repr=False)
    active: np.ndarray = field(init=False, repr=False)

    def assemble(self, N: sp.csr_matrix, m_p: np.ndarray, volume_p: np.ndarray | None = None) -> None:
        self.lumped = N.T @ m_p
        self.active = np.abs(self.lumped) > 1e-12 * self.reference_mass
        self._inverse = np.divide(1.0, self.lumped, out=np.zeros(self.n_nodes), where=self.active)

    def solve(self, rhs: np.ndarray, kind: str = "velocity") -> np.ndarray:
        """``rhs / m_i`` on active nodes, zero elsewhere; rhs shape (n_nodes, 2)."""
        return rhs * self._inverse[:, None]

    def apply(self, vector: np.ndarray) -> np.ndarray:
        """``M @ vector`` with the lumped matrix."""
        return vector * self.lumped[:, None]


@dataclass
class ConsistentMass:
    """Consistent mass ``N.T diag(m_p) N`` solved by Jacobi-preconditioned CG.

    Parameters
    ----------
    n_nodes : int
    reference_mass : float
        Mass of one full lattice cell (kg), the scale for "empty".
    node_integrals : ndarray, shape (n_nodes,)
        ``integral(phi_i)`` over the grid (m^2), for the weak-node test.
    nonnegative : bool
        Whether the basis is non-negative (weak-node lumping applies).
    weak_fraction : float
        Volume fraction below which a node is weak.
    tolerance : float
        Relative residual at which CG stops.
    fallback : {"error", "blend"}
        What to do when the matrix is found singular.
    blend : float
        Weight of the lumped mass in the fallback.
    """

    n_nodes: int
    reference_mass: float
    node_integrals: np.ndarray = field(repr=False)
    nonnegative: bool = True
    weak_fraction: float = 0.01
    tolerance: float = 1e-10
    fallback: str = "error"
    blend: float = 0.1
    kind = "consistent"
    iterations: int = 0
    weak_nodes: int = 0
    blended_steps: int = 0

    def __post_init__(self):
        self._previous: dict[str, np.ndarray] = {}
        self.max_iterations = int(200 + 20 * np.sqrt(self.n_nodes))

    def assemble(self, N: sp.csr_matrix, m_p: np.ndarray, volume_p: np.ndarray | None = None) -> None:
        weighted = N.multiply(m_p[:, None]).tocsr()
        matrix = (N.T @ weighted).tocsr()
        self.lumped = N.T @ m_p
        diagonal = matrix.diagonal()
        self.active = diagonal > 1e-24 * self.reference_mass
        if self.nonnegative and volume_p is not None:
            fraction = np.divide(N.T @ volume_p, self.node_integrals, out=np.ones(self.n_nodes), where=self.active)
            weak = self.active & (fraction < self.weak_fraction)
            self.weak_nodes = int(weak.sum())
            if self.weak_nodes:
                matrix = _lump_couplings(matrix, weak)
                diagonal = matrix.diagonal()
        # empty nodes: identity rows, so CG sees a definite block there
        self.matrix = matrix + sp.diags((~self.active).astype(float))
        self._inverse_diagonal = 1.0 / np.where(self.active, diagonal, 1.0)
        self._blended = False

    def apply(self, vector: np.ndarray) -> np.ndarray:
        """``M @ vector`` with the consistent matrix (empty rows zero)."""
        return (self.matrix @ vector) * self.active[:, None]

    def solve(self, rhs: np.ndarray, kind: str = "velocity") -> np.ndarray:
        """Solve ``M x = rhs`` for the two columns of rhs (n_nodes, 2).

        The initial guess is the previous step's solution of the same kind
        (warm start) where a node was active then, and the lumped solution
        elsewhere; for a rigid motion that guess is already exact.
        """
        rhs = np.where(self.active[:, None], rhs, 0.0)
        guess = self._initial_guess(rhs, kind)
        solution, converged, iterations = _preconditioned_cg(
            self.matrix, rhs, guess, self._inverse_diagonal, self.tolerance, self.max_iterations
        )
        self.iterations += iterations
        if not converged:
            if self.fallback != "blend":
                raise SingularMassError(
                    f"the consistent mass matrix is singular or nearly so: CG did not converge in "
                    f"{iterations} iterations on the {kind} system (too few points per cell for the basis, "
                    f"or weakly supported nodes); use more points per cell, lumped mass, or "
                    f"solver.consistent_fallback = 'blend'"
                )
            solution = self._solve_blended(rhs, guess, kind)
        self._previous[kind] = solution
        return solution

    def _initial_guess(self, rhs: np.ndarray, kind: str) -> np.ndarray:
        scale = np.where(np.abs(self.lumped) > 1e-12 * self.reference_mass, self.lumped, 1.0 / self._inverse_diagonal)
        guess = rhs / scale[:, None]
        previous = self._previous.get(kind)
        if previous is not None:
            guess = np.where((previous != 0.0).any(axis=1)[:, None], previous, guess)
        return guess * self.active[:, None]

    def _solve_blended(self, rhs: np.ndarray, guess: np.ndarray, kind: str) -> np.ndarray:
        if not self._blended:
            if np.any(self.lumped[self.active] <= 0):
                raise SingularMassError(
                    "the consistent mass matrix is singular and cannot be blended with the lumped mass, "
                    "which is not positive (negative shape functions); use more points per cell"
                )
            lumped = sp.diags(np.where(self.active, self.lumped, 0.0))
            self.matrix = (1.0 - self.blend) * self.matrix + self.blend * lumped + sp.diags(
                self.blend * (~self.active).astype(float)
            )
            self._inverse_diagonal = 1.0 / self.matrix.diagonal()
            self._blended = True
            self.blended_steps += 1
        solution, converged, iterations = _preconditioned_cg(
            self.matrix, rhs, guess, self._inverse_diagonal, self.tolerance, self.max_iterations
        )
        self.iterations += iterations
        if not converged:
            raise SingularMassError(f"CG did not converge on the blended mass matrix ({kind} system)")
        return solution


def _lump_couplings(matrix: sp.csr_matrix, weak: np.ndarray) -> sp.csr_matrix:
    """Move every off-diagonal entry that touches a weak node onto both diagonals."""
    coo = matrix.tocoo()
    moved = (coo.row != coo.col) & (weak[coo.row] | weak[coo.col])
    to_diagonal = np.bincount(coo.row[moved], weights=coo.data[moved], minlength=matrix.shape[0])
    data = np.where(moved, 0.0, coo.data)
    kept = sp.csr_matrix((data, (coo.row, coo.col)), shape=matrix.shape)
    kept.eliminate_zeros()
    return (kept + sp.diags(to_diagonal)).tocsr()


def _preconditioned_cg(A, b, x0, inverse_diagonal, rtol, max_iterations):
    """Jacobi-preconditioned CG on the columns of ``b`` (n, k) at once.

    Returns ``(x, converged, iterations)``.  Converged means every column's
    residual fell to ``rtol * |b|``.  A non-positive curvature ``p.A.p``
    (singular matrix met by an inconsistent right-hand side) stops the
    iteration as not converged.
    """
    x = x0.copy()
    target = rtol * np.linalg.norm(b, axis=0)
    r = b - A @ x
    z = inverse_diagonal[:, None] * r
    p = z.copy()
    rz = np.einsum("ij,ij->j", r, z)
    for iteration in range(max_iterations + 1):
        if np.all(np.linalg.norm(r, axis=0) <= target) or not np.any(rz):
            return x, True, iteration
        if iteration == max_iterations:
            break
        Ap = A @ p
        curvature = np.einsum("ij,ij->j", p, Ap)
        if np.any((curvature <= 0) & (rz != 0)):
            return x, False, iteration
        alpha = np.divide(rz, curvature, out=np.zeros_like(rz), where=curvature > 0)
        x += alpha * p
        r -= alpha * Ap
        z = inverse_diagonal[:, None] * r
        rz_new = np.einsum("ij,ij->j", r, z)
        beta = np.divide(rz_new, rz, out=np.zeros_like(rz), where=rz != 0)
        p = z + beta * p
        rz = rz_new
    return x, False, max_iterations
