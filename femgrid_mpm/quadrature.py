"""The internal force by Gauss quadrature of a stress reconstructed from the points.

The paper's force is the sum over the points, ``f = -sum_p grad N(x_p) sigma_p V_p``: a
midpoint rule on the sub-cells the points were seeded in.  Its error over one cell is
``h_s^2 / 24`` times the jump of the integrand's derivative across the cell's sides; over
cells where the integrand is C1 these cancel from cell to cell, except at a body's edge,
where the stress stops (the integrand ``grad N sigma`` jumps to zero).  There the sum leaves a
force error that does not shrink with h (of the order ``sigma / ppc^2`` at the nodes of the
boundary cells), and the displacement error is first order in h (docs/accuracy.md).

Here, in every lattice cell the points fill (:meth:`StressReconstruction.fill`), the stress
is the tensor polynomial of degree ``m`` in each direction fitted by least squares (weighted
by the points' volumes) to the cell's own points, ``m = points_per_cell - 1``: it
interpolates a ``(m + 1) x (m + 1)`` lattice of points (the per-cell least squares of
Sulsky and Gong 2016; Tielen et al. 2017 reconstruct with B-splines), and the force
``-int grad N . sigma_h`` is integrated by a tensor Gauss rule exact for the basis' pieces
times the polynomial, so that no edge term remains.  Cells that the points fill only partly,
that hold two bodies, or with too few points for the polynomial keep the sum over their points.

Why the cell's own points and not a patch of neighbours: the strain at the points is that
of the grid, ``B_p u``, so the stiffness is ``K = B_G^T W D Pi B_p`` (``B_G`` at the Gauss
points, ``Pi`` the fit).  Where the fit reproduces the basis' strain on the cell (``m`` at
least the basis' degree, e.g. q1 with 2 x 2, q2 with 3 x 3, cubic splines with 4 x 4
points), ``Pi B_p = B_G`` and ``K`` is the symmetric stiffness of Gauss quadrature.  A fit
over a patch of 3 x 3 cells cannot reproduce the piecewise strain of the basis: its ``K`` is
not symmetric and has negative eigenvalues (cubic splines at h = 1/8: ``M^-1 K`` down to -441
with 2 x 2 points), and the run grows without bound (docs/accuracy.md).
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import scipy.sparse as sp

#: a cell is integrated by Gauss if the volumes of its points add to at least this share of its area
FILL = 0.99
#: a patch whose normal matrix has a smaller ratio of extreme eigenvalues keeps the points' sum
SMALLEST_EIGENVALUE_RATIO = 1e-12


def legendre(t: np.ndarray, degree: int) -> np.ndarray:
    """Legendre polynomials ``P_0 .. P_degree`` at ``t``, shape ``t.shape + (degree + 1,)``:
    nearly orthogonal on a patch, so the normal equations stay well conditioned."""
    values = [np.ones_like(t), t]
    for n in range(1, degree):
        values.append(((2 * n + 1) * t * values[n] - n * values[n - 1]) / (n + 1))
    return np.stack(values[: degree + 1], axis=-1)


def tensor_exponents(degree: int) -> np.ndarray:
    """The pairs ``(a, b)`` with ``a, b <= degree``: the tensor polynomial's terms."""
    return np.array([(a, b) for a in range(degree + 1) for b in range(degree + 1)])


def polynomial_terms(xi: np.ndarray, eta: np.ndarray, degree: int) -> np.ndarray:
    """The tensor polynomial's terms at local coordinates, shape (n, n_terms)."""
    pairs = tensor_exponents(degree)
    return legendre(xi, degree)[:, pairs[:, 0]] * legendre(eta, degree)[:, pairs[:, 1]]


class StressReconstruction:
    """Least squares of the points' stress in each filled cell, and the Gauss force.

    Parameters
    ----------
    grid : femgrid_mpm.Grid
        A grid whose functions are polynomials on each lattice cell (every basis but GIMP).
    degree : int
        Degree ``m`` of the stress polynomial in each direction (``points_per_cell - 1``);
        the Gauss rule has ``ceil((d + m + 1) / 2)`` points along each axis for a basis of
        degree ``d``: exact for ``grad N . sigma_h`` on the cell.
    order : int, optional
        Another number of Gauss points along each axis (:class:`MassReconstruction`'s).
    """

    def __init__(self, grid, degree: int, order: int | None = None):
        self.grid = grid
        self.degree = degree
        self.h = grid.spacing
        self.cells = tuple(int(c) for c in grid.cells)
        nx, ny = self.cells
        self.n_cells = nx * ny
        self.n_terms = len(tensor_exponents(degree))
        # grad N is of degree d-1 in its own axis, d in the other; sigma_h of degree m: n >= (d + m + 1) / 2
        order = int(np.ceil((grid.definition.degree + degree + 1) / 2)) if order is None else order
        nodes, weights = np.polynomial.legendre.leggauss(order)
        gx, gy = np.meshgrid(nodes, nodes, indexing="ij")
        self.gauss_weights = (np.outer(weights, weights).ravel() * (0.5 * self.h) ** 2)
        self.n_gauss = order * order
        # local coordinates: the cell on [-1, 1]^2, where Legendre terms are nearly orthogonal
        self.gauss_terms = polynomial_terms(gx.ravel(), gy.ravel(), degree)  # (n_gauss, n_terms)
        self.centres = centres = self.cell_centres()
        points = (centres[:, None, :] + 0.5 * self.h * np.stack([gx.ravel(), gy.ravel()], axis=-1)[None]).reshape(-1, 2)
        N, dNdx, dNdy = grid.shape_functions(points)
        self.gauss_N = N.tocsr()
        self.gauss_dNdx, self.gauss_dNdy = dNdx.tocsr(), dNdy.tocsr()
        self.gauss_dNdx_t, self.gauss_dNdy_t = self.gauss_dNdx.T.tocsr(), self.gauss_dNdy.T.tocsr()

    @classmethod
    def of_scene(cls, grid, scene) -> "StressReconstruction":
        """The scene's: the polynomial the fewest points of a cell determine (it interpolates them)."""
        return cls(grid, min(body.points_per_cell for body in scene.bodies) - 1)

    def cell_centres(self) -> np.ndarray:
        """Centres of the lattice cells, shape (n_cells, 2), cell ``i * ny + j``."""
        nx, ny = self.cells
        i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
        return self.grid.lower + self.h * (np.column_stack([i.ravel(), j.ravel()]) + 0.5)

    def cell_of(self, x: np.ndarray) -> np.ndarray:
        """Lattice indices (i, j) of the cell holding each point, shape (n, 2)."""
        index = np.floor((x - self.grid.lower) / self.h).astype(np.int64)
        return np.clip(index, 0, np.array(self.cells) - 1)

    def fill(self, x: np.ndarray, volume: np.ndarray, body: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Which cells the points fill: (full mask (n_cells,), each cell's body, each point's cell)."""
        ij = self.cell_of(x)
        cell = ij[:, 0] * self.cells[1] + ij[:, 1]
        volume_in = np.bincount(cell, weights=volume, minlength=self.n_cells)
        lowest = np.full(self.n_cells, np.iinfo(np.int64).max)
        highest = np.full(self.n_cells, -1)
        np.minimum.at(lowest, cell, body)
        np.maximum.at(highest, cell, body)
        full = (volume_in >= FILL * self.h**2) & (lowest == highest)
        return full, highest, cell

    def fit(self, x: np.ndarray, volume: np.ndarray, values: np.ndarray, body: np.ndarray | None = None):
        """Each filled cell's polynomial: (coefficients (n_cells, n_terms, k), usable mask, point cells).

        ``values`` (n, k) are fitted component by component; ``usable`` marks the cells
        that are full, of one body, and whose points determine the polynomial."""
        body = np.zeros(len(x), dtype=np.int64) if body is None else np.asarray(body, dtype=np.int64)
        full, _, cell = self.fill(x, volume, body)
        m, k = self.n_terms, values.shape[1]
        points = np.flatnonzero(full[cell])
        rows = cell[points]
        local = (x[points] - self.centres[rows]) / (0.5 * self.h)  # the cell on [-1, 1]^2
        terms = polynomial_terms(local[:, 0], local[:, 1], self.degree)
        weighted = volume[points, None] * terms
        summing = sp.csr_matrix((np.ones(len(rows)), (rows, np.arange(len(rows)))), shape=(self.n_cells, len(rows)))
        normal = (summing @ (weighted[:, :, None] * terms[:, None, :]).reshape(len(rows), m * m)).reshape(-1, m, m)
        right = (summing @ (weighted[:, :, None] * values[points, None, :]).reshape(len(rows), m * k)).reshape(-1, m, k)
        usable = full.copy()
        candidates = np.flatnonzero(full)
        if len(candidates):
            eigenvalues = np.linalg.eigvalsh(normal[candidates])
            usable[candidates] = eigenvalues[:, 0] > SMALLEST_EIGENVALUE_RATIO * eigenvalues[:, -1]
        coefficients = np.zeros((self.n_cells, m, k))
        solved = np.flatnonzero(usable)
        if len(solved):
            coefficients[solved] = np.linalg.solve(normal[solved], right[solved])
        return coefficients, usable, cell

    def evaluate(self, coefficients: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The reconstructed field at points ``x`` (each in its own cell's polynomial), shape (n, k)."""
        ij = self.cell_of(x)
        cell = ij[:, 0] * self.cells[1] + ij[:, 1]
        local = (x - self.centres[cell]) / (0.5 * self.h)
        terms = polynomial_terms(local[:, 0], local[:, 1], self.degree)
        return np.einsum("nm,nmk->nk", terms, coefficients[cell])

    def force(self, x: np.ndarray, volume: np.ndarray, stress: np.ndarray, body: np.ndarray,
              point_gradients: Callable[[], tuple]) -> np.ndarray:
        """``-int grad N . sigma`` (n_nodes, 2): Gauss in the usable cells, the points' sum elsewhere.

        ``stress`` holds (xx, yy, xy) per point; ``point_gradients()`` returns the points'
        ``dNdx``, ``dNdy``, asked for only if some point is summed (the numba engine builds
        them on demand)."""
        coefficients, usable, cell = self.fit(x, volume, stress, body)
        at_gauss = np.einsum("gm,cmk->cgk", self.gauss_terms, coefficients)  # zero in the unusable cells
        weighted = (at_gauss * self.gauss_weights[None, :, None]).reshape(-1, 3)
        force = -(self.gauss_dNdx_t @ weighted[:, [0, 2]] + self.gauss_dNdy_t @ weighted[:, [2, 1]])
        summed = ~usable[cell]
        if summed.any():  # the points' own sum where no polynomial is integrated
            dNdx, dNdy = point_gradients()
            weighted_points = (summed * volume)[:, None] * stress
            force -= dNdx.T @ weighted_points[:, [0, 2]] + dNdy.T @ weighted_points[:, [2, 1]]
        return force

    def integration_rows(self, x: np.ndarray, volume: np.ndarray, body: np.ndarray, dNdx: sp.csr_matrix,
                         dNdy: sp.csr_matrix, moduli: np.ndarray) -> tuple:
        """The force's integration points as rows (gradients, weights, moduli of each row's body):
        the Gauss points of the usable cells and the points elsewhere, for the critical step's
        stiffness ``sum w B^T D B`` (:mod:`femgrid_mpm.stability`).  Where the fit holds the
        basis' strain that is the stiffness of the force; elsewhere its largest frequency was
        above the force's in every case measured (docs/accuracy.md), a safe estimate."""
        _, usable, cell = self.fit(x, volume, np.zeros((len(x), 1)), body)
        at_gauss = np.repeat(usable, self.n_gauss)
        summed = ~usable[cell]
        cells = np.flatnonzero(usable)
        weights = np.concatenate([volume[summed], np.tile(self.gauss_weights, len(cells))])
        # each Gauss point takes the moduli of its cell's body (those of any of its points)
        member = np.zeros(self.n_cells, dtype=np.int64)
        member[cell] = np.arange(len(x))
        gauss_moduli = np.repeat(moduli[member[cells]], self.n_gauss, axis=0)
        return (sp.vstack([dNdx[summed], self.gauss_dNdx[at_gauss]]).tocsr(),
                sp.vstack([dNdy[summed], self.gauss_dNdy[at_gauss]]).tocsr(),
                weights, np.concatenate([moduli[summed], gauss_moduli]))


class MassReconstruction:
    """The consistent mass and the momentum by Gauss quadrature over the filled cells.

    The points' sums ``N^T diag(m) N`` and ``N^T m v`` are midpoint rules too, with the
    same edge term as the force's: where a body ends the rows of the functions that reach
    past it err by ``(h_s^2 / 24) (N_a u)'`` at the edge, which leaves a layer of second-order
    error along a free edge (the free bar, docs/accuracy.md).  Here, in every cell the
    points fill (as for the stress, :meth:`StressReconstruction.fit`), the density is the
    cell's points' mass over its area and the velocity the polynomial of degree ``m`` fitted
    to the points' velocities, and ``rho N_a N_b`` and ``rho N_a v_h`` are integrated by the
    tensor Gauss rule of ``max(d + 1, ceil((d + m + 1) / 2))`` points per axis, exact for both
    (degrees ``2 d`` and ``d + m`` along each axis).  Other cells keep their points' sums.  Used with the force's
    reconstruction, both sides of ``M a = f`` are then exact integrals over the filled cells.
    """

    def __init__(self, grid, degree: int):
        d = grid.definition.degree
        self.cells = StressReconstruction(grid, degree, order=max(d + 1, int(np.ceil((d + degree + 1) / 2))))

    @classmethod
    def of_scene(cls, grid, scene) -> "MassReconstruction":
        return cls(grid, min(body.points_per_cell for body in scene.bodies) - 1)

    def rows(self, x: np.ndarray, volume: np.ndarray, mass: np.ndarray, body: np.ndarray, velocity: np.ndarray,
             point_rows: Callable[[np.ndarray], sp.csr_matrix]) -> tuple:
        """The integration points as rows ``(N, masses, volumes, velocities)``: the points of the
        cells integrated by their sums, then the Gauss points of the usable cells.
        ``point_rows(mask)`` returns the shape functions of the points in ``mask``."""
        cells = self.cells
        coefficients, usable, cell = cells.fit(x, volume, velocity, body)
        filled = np.flatnonzero(usable)
        summed = ~usable[cell]
        weights = np.tile(cells.gauss_weights, len(filled))
        density = np.bincount(cell, weights=mass, minlength=cells.n_cells)[filled] / cells.h**2
        at_gauss = np.einsum("gm,cmk->cgk", cells.gauss_terms, coefficients[filled]).reshape(-1, velocity.shape[1])
        rows = cells.gauss_N[np.repeat(usable, cells.n_gauss)]
        if summed.any():
            rows = sp.vstack([point_rows(summed), rows]).tocsr()
        return (rows, np.concatenate([mass[summed], np.repeat(density, cells.n_gauss) * weights]),
                np.concatenate([volume[summed], weights]), np.concatenate([velocity[summed], at_gauss]))
