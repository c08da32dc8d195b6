"""Exact monomial form of an element's local basis functions.

Every basis used here is a polynomial of degree at most ``d`` in each local
coordinate on its cell.  Evaluating scikit-fem's ``lbasis`` one function at a
time costs ~300 ns per particle for Q2; instead the element's own ``lbasis``
is sampled once on a ``(d+1) x (d+1)`` tensor lattice, which determines the
polynomial exactly, and every later evaluation is a single small matrix
product ``monomials @ coefficients`` (~10-25 ns per particle with one BLAS
thread).  The element stays the definition: the coefficients are derived from
it and checked against it (values and gradients) when they are built.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

#: ``lbasis(X, i) -> (phi, dphi)``: scikit-fem's calling convention, with
#: ``X`` of shape (2, n) on the unit square, ``phi`` (n,) and ``dphi`` (2, n).
LocalBasis = Callable[[np.ndarray, int], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class LocalPolynomials:
    """Monomial coefficients of ``n_local`` functions on the unit cell.

    The cell coordinates are ``(xi, eta)`` in [0, 1]^2 with ``xi`` along
    global x and ``eta`` along global y.  Monomial ``k = a * (degree + 1) + b``
    is ``xi**a * eta**b``.

    Attributes
    ----------
    degree : int
        Highest power of each coordinate.
    values, d_xi, d_eta : ndarray, shape (n_monomials, n_local)
        Coefficients of the functions and of their two partial derivatives.
    """

    degree: int
    values: np.ndarray
    d_xi: np.ndarray
    d_eta: np.ndarray

    @property
    def n_local(self) -> int:
        return self.values.shape[1]

    @classmethod
    def from_lbasis(
        cls,
        lbasis: LocalBasis,
        n_local: int,
        degree: int,
        to_reference: np.ndarray,
        offset: np.ndarray,
    ) -> "LocalPolynomials":
        """Fit the exact monomial coefficients of ``lbasis`` and verify them.

        Parameters
        ----------
        lbasis : callable
            The element's local basis, ``lbasis(X, i) -> (phi, dphi)``.
        n_local : int
            Number of local functions.
        degree : int
            Polynomial degree in each coordinate (1 for Q1, 2 for Q2 and
            serendipity, 3 for cubic B-splines).
        to_reference : ndarray, shape (2, 2)
            Linear part of the map from cell coordinates to the element's
            reference coordinates, ``X = to_reference @ (xi, eta) + offset``.
        offset : ndarray, shape (2,)
            Constant part of that map.
        """
        n_1d = degree + 1
        samples_1d = np.linspace(0.0, 1.0, n_1d)
        xi, eta = (a.ravel() for a in np.meshgrid(samples_1d, samples_1d, indexing="ij"))
        cell_points = np.vstack([xi, eta])
        vandermonde = monomials(cell_points.T, degree)
        reference = to_reference @ cell_points + offset[:, None]
        sampled = np.column_stack([lbasis(reference, i)[0] for i in range(n_local)])
        values = np.linalg.solve(vandermonde, sampled)
        polynomials = cls(degree, values, *_derivative_coefficients(values, degree))
        polynomials._verify(lbasis, to_reference, offset)
        return polynomials

    def _verify(self, lbasis: LocalBasis, to_reference: np.ndarray, offset: np.ndarray) -> None:
        """Compare with ``lbasis`` at random points: proves the degree was right."""
        rng = np.random.default_rng(12345)
        cell_points = rng.random((2, 64))
        reference = to_reference @ cell_points + offset[:, None]
        phi, d_xi, d_eta = self.evaluate(cell_points.T)
        for i in range(self.n_local):
            ref_phi, ref_dphi = lbasis(reference, i)
            # chain rule: d/d(xi, eta) = to_reference.T @ d/dX
            ref_dcell = to_reference.T @ ref_dphi
            for ours, theirs in ((phi[:, i], ref_phi), (d_xi[:, i], ref_dcell[0]), (d_eta[:, i], ref_dcell[1])):
                error = np.max(np.abs(ours - theirs))
                if error > 1e-11:
                    raise AssertionError(
                        f"local function {i} is not a polynomial of degree {self.degree} "
                        f"in each coordinate (mismatch {error:.2e})"
                    )

    def evaluate(self, cell_points: np.ndarray, element: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Values and cell-coordinate derivatives at points in the unit cell.

        Parameters
        ----------
        cell_points : ndarray, shape (n, 2)
            ``(xi, eta)`` of each point.
        element : ndarray, optional
            Ignored: every element has the same local functions.

        Returns
        -------
        phi, dphi_dxi, dphi_deta : ndarray, shape (n, n_local)
        """
        basis = monomials(cell_points, self.degree)
        return basis @ self.values, basis @ self.d_xi, basis @ self.d_eta


def monomials(cell_points: np.ndarray, degree: int) -> np.ndarray:
    """Monomials ``xi**a * eta**b`` at points, shape (n, (degree + 1)**2).

    Built by repeated multiplication into one buffer (``**`` on broadcast
    arrays was half the cost of a whole shape-function evaluation).
    """
    n, n_1d = len(cell_points), degree + 1
    xi_powers = np.empty((n, n_1d))
    eta_powers = np.empty((n, n_1d))
    xi_powers[:, 0] = 1.0
    eta_powers[:, 0] = 1.0
    for a in range(1, n_1d):
        np.multiply(xi_powers[:, a - 1], cell_points[:, 0], out=xi_powers[:, a])
        np.multiply(eta_powers[:, a - 1], cell_points[:, 1], out=eta_powers[:, a])
    result = np.empty((n, n_1d, n_1d))
    np.multiply(xi_powers[:, :, None], eta_powers[:, None, :], out=result)
    return result.reshape(n, n_1d * n_1d)


def _derivative_coefficients(values: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients of d/dxi and d/deta in the same monomial basis."""
    n_1d = degree + 1
    grid = values.reshape(n_1d, n_1d, -1)  # [a, b, function]
    d_xi = np.zeros_like(grid)
    d_eta = np.zeros_like(grid)
    powers = np.arange(1, n_1d)
    d_xi[:-1] = grid[1:] * powers[:, None, None]
    d_eta[:, :-1] = grid[:, 1:] * powers[None, :, None]
    return d_xi.reshape(values.shape), d_eta.reshape(values.shape)
