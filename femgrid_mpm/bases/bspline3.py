"""Tensor-product cubic B-splines (paper Eq. 23) on the MPM lattice, two boundary treatments.

A cubic B-spline influences points up to two spacings away, so the 16
functions that are non-zero on a cell belong to the nodes one step below to
two steps above it in each direction; ``n`` cells carry ``n + 3`` functions
per direction.  The two variants differ in the functions near the boundary:

``bspline3`` (the paper's): uniform splines everywhere, with one extra column
(and row) of nodes beyond each side of the domain, at ``lower - spacing`` and
``upper + spacing``.  Every point inside the domain has its full 16-node
stencil; partition of unity and linear completeness hold up to the boundary.
A rigid wall fixes the boundary nodes *and* the extra column (``x <= 0``
selects both).  Fixing them is not exact: the third node's function is 1/6
on the wall, so the wall itself still moves with that node.

``bspline3_open``: an open ("clamped") knot vector, the first and last knots
repeated four times.  Interior cells (three or more from a boundary) have the
same functions as ``bspline3``; the cells next to a boundary have modified
ones, and on the boundary only the boundary node's function is non-zero
(equal to 1), so fixing the nodes on ``x <= 0`` holds the wall exactly.  The
nodes are the functions' Greville abscissae: on the lattice except the
second and second-to-last per direction, which sit a third of a spacing
from the boundary.  Linear functions are still reproduced exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

import numpy as np
import skfem

from .lattice import Discretization
from .pieces import TensorPieces
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


def open_knot_tables(n_cells: int) -> np.ndarray:
    """Per-cell monomial coefficients for an open knot vector, shape (n_cells, 4, 4).

    Knots ``0, 0, 0, 0, 1, ..., n - 1, n, n, n, n`` (in spacings); cell ``j``
    carries functions ``j .. j + 3``.  The pieces are sampled from scipy's
    B-spline evaluation at four points per cell and fitted (exact for cubics).
    """
    from scipy.interpolate import BSpline

    knots = np.concatenate([[0.0] * 3, np.arange(n_cells + 1.0), [float(n_cells)] * 3])
    samples = np.array([0.1, 0.4, 0.6, 0.9])  # inside the cell: each belongs to its piece
    vandermonde = np.vander(samples, 4, increasing=True)
    tables = np.empty((n_cells, 4, 4))
    for cell in range(n_cells):  # once per grid, at set-up
        design = BSpline.design_matrix(cell + samples, knots, 3).toarray()[:, cell : cell + 4]
        tables[cell] = np.linalg.solve(vandermonde, design)
    return tables


def greville_abscissae(n_cells: int, knots: str) -> np.ndarray:
    """Node positions in spacings from the lower boundary, shape (n_cells + 3,)."""
    if knots == "ghost":
        return np.arange(-1.0, n_cells + 2.0)
    positions = np.arange(-1.0, n_cells + 2.0)
    positions[[0, 1]] = [0.0, 1.0 / 3.0]
    positions[[-2, -1]] = [n_cells - 1.0 / 3.0, float(n_cells)]
    return positions


@dataclass(frozen=True)
class BSpline3Basis:
    """Cubic B-splines on the lattice; ``knots`` is ``"ghost"`` (the paper's) or ``"open"``."""

    name: str = "bspline3"
    knots: str = "ghost"
    degree: int = 3
    cells_per_element: int = 1
    support_width: int = 4
    nonnegative: bool = True
    critical_step_factors: Mapping[str, float] = field(
        default_factory=lambda: MappingProxyType({"lumped": 1.9, "consistent": 0.55}))
    #: uniform splines in the interior: the Gram matrix is a tensor product there
    tensor_gram: bool = True
    mass_threshold: bool = True
    sized: bool = False

    def build(self, lower: np.ndarray, n_elements: tuple[int, int], spacing: float,
              points_per_cell: int = 2) -> Discretization:
        element = ElementBSpline3()
        nx, ny = n_elements[0] + 3, n_elements[1] + 3  # functions per direction (node (i, j) is i * ny + j)
        positions = [greville_abscissae(n, self.knots) for n in n_elements]
        gx, gy = np.meshgrid(lower[0] + spacing * positions[0], lower[1] + spacing * positions[1], indexing="ij")
        nodes = np.column_stack([gx.ravel(), gy.ravel()])  # node (i, j) has index i * ny + j
        ix_nodes, iy_nodes = np.meshgrid(np.arange(nx) - 1, np.arange(ny) - 1, indexing="ij")
        ix, iy = np.meshgrid(np.arange(n_elements[0]), np.arange(n_elements[1]), indexing="ij")
        # cell (ix, iy) carries functions ix .. ix + 3 along x and iy .. iy + 3 along y
        offsets = element.node_offsets + 1
        connectivity = (ix.ravel()[:, None] + offsets[:, 0]) * ny + (iy.ravel()[:, None] + offsets[:, 1])
        if self.knots == "ghost":
            # every cell alike: the monomial form of the paper's element is fastest
            local_basis = LocalPolynomials.from_lbasis(element.lbasis, 16, self.degree, np.eye(2), np.zeros(2))
        else:
            local_basis = TensorPieces(tuple(open_knot_tables(n) for n in n_elements), n_elements[1])
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
            local_basis=local_basis,
            mesh=skfem.MeshQuad.init_tensor(x, y),
            element=element,
            nonnegative=self.nonnegative,
            # function (i, j) sits at lattice position (i - 1, j - 1), its Greville point rounded
            # (open knots move two nodes per direction off the lattice, a third of a spacing in)
            node_lattice=np.column_stack([ix_nodes.ravel(), iy_nodes.ravel()]),
        )


BSPLINE3 = BSpline3Basis()
BSPLINE3_OPEN = BSpline3Basis(name="bspline3_open", knots="open")
