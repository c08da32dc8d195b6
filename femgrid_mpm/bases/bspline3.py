"""Tensor-product uniform cubic B-splines (paper Eq. 23) on the MPM lattice.

Boundary treatment (the paper's): a cubic B-spline node influences points up
to two spacings away, so a point in a cell next to the domain boundary needs
one node outside the domain.  The grid therefore carries one extra column
(and row) of nodes beyond each side of the domain, at ``lower - spacing`` and
``upper + spacing``.  Every point inside the domain then has its full
16-node stencil, partition of unity and linear completeness hold up to the
boundary, and a rigid wall is imposed by fixing the velocities of the
boundary nodes *and* of the extra column beyond it (a support written as
``x <= 0`` selects both, since the extra column lies at ``x = -spacing``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import skfem

from .lattice import Discretization
from .polynomial import LocalPolynomials


def cubic_spline(r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Paper Eq. 23, ``S3(r)`` and ``dS3/dr``, for distances in spacings."""
    s = np.abs(r)
    inner = 2.0 / 3.0 - s**2 + 0.5 * s**3
    outer = (2.0 - s) ** 3 / 6.0
    value = np.where(s < 1.0, inner, np.where(s < 2.0, outer, 0.0))
    slope = np.where(s < 1.0, -2.0 * s + 1.5 * s**2, np.where(s < 2.0, -0.5 * (2.0 - s) ** 2, 0.0))
    return value, slope * np.sign(r)


class ElementBSpline3:
    """Cubic B-spline "element": the 16 functions that are non-zero on one cell.

    Follows scikit-fem's element shape: ``lbasis(X, i) -> (phi, dphi)`` on the
    unit square, with ``X[0]`` along x and ``X[1]`` along y.  Function
    ``i = 4 * a + b`` belongs to the node ``node_offsets[i] = (a - 1, b - 1)``
    lattice steps from the cell's lower-left node: the paper's N1..N16.
    """

    degree = 3
    node_offsets = np.array([(a - 1, b - 1) for a in range(4) for b in range(4)])

    def lbasis(self, X: np.ndarray, i: int) -> tuple[np.ndarray, np.ndarray]:
        a, b = self.node_offsets[i]
        fx, dfx = cubic_spline(X[0] - a)
        fy, dfy = cubic_spline(X[1] - b)
        return fx * fy, np.array([dfx * fy, fx * dfy])


@dataclass(frozen=True)
class BSpline3Basis:
    """Cubic B-splines with one extra column of nodes beyond each boundary."""

    name: str = "bspline3"
    degree: int = 3
    cells_per_element: int = 1
    nonnegative: bool = True

    def build(self, lower: np.ndarray, n_elements: tuple[int, int], spacing: float) -> Discretization:
        element = ElementBSpline3()
        nx, ny = n_elements[0] + 3, n_elements[1] + 3  # nodes per direction, ghosts included
        i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
        # node (i, j) sits at lower + (i - 1, j - 1) * spacing; index i * ny + j
        nodes = lower + (np.column_stack([i.ravel(), j.ravel()]) - 1) * spacing
        ix, iy = np.meshgrid(np.arange(n_elements[0]), np.arange(n_elements[1]), indexing="ij")
        # cell (ix, iy)'s lower-left node has lattice index (ix + 1, iy + 1)
        offsets = element.node_offsets + 1
        connectivity = (ix.ravel()[:, None] + offsets[:, 0]) * ny + (iy.ravel()[:, None] + offsets[:, 1])
        polynomials = LocalPolynomials.from_lbasis(
            element.lbasis, 16, self.degree, np.eye(2), np.zeros(2)
        )
        x = lower[0] + spacing * np.arange(n_elements[0] + 1)
        y = lower[1] + spacing * np.arange(n_elements[1] + 1)
        return Discretization(
            basis=self.name,
            spacing=spacing,
            element_width=spacing,
            lower=lower,
            n_elements=n_elements,
            nodes=np.ascontiguousarray(nodes, dtype=float),
            connectivity=np.ascontiguousarray(connectivity, dtype=np.int32),
            polynomials=polynomials,
            mesh=skfem.MeshQuad.init_tensor(x, y),
            element=element,
            nonnegative=self.nonnegative,
        )


BSPLINE3 = BSpline3Basis()
