"""Tensor-product quadratic B-splines on the MPM lattice: with the paper-style extra column, or open knots.

The quadratic B-spline of node ``i``,

    S2(r) = 3/4 - r^2               |r| <= 1/2
          = (3/2 - |r|)^2 / 2       1/2 <= |r| <= 3/2,      r = (x - x_i) / spacing,

is the default of most current MPM codes: like q2 a point meets 3 x 3 nodes, but the
functions are never negative (no negative grid mass) and their gradients are continuous
(no cell-crossing noise).  Its breakpoints lie halfway between nodes, so each half cell
is one quadratic piece meeting the three nodes nearest to it
(:func:`~.pieces.nearest_node_pieces`); as for the paper's cubic splines, one column
(row) of nodes lies beyond each side of the domain, so partition of unity and linear
completeness hold up to the boundary, and ``x <= 0`` selects the extra column with the
boundary's nodes.

``bspline2_open``: an open ("clamped") knot vector on the lattice lines, the first
and last knots repeated three times.  Each lattice cell is one piece meeting three
functions (so the compiled kernels run it by sum factorization, as the cubic ones);
the nodes are the functions' Greville abscissae, at the cells' centres except the
first and last per direction, which lie on the boundary, where only their function
is non-zero (equal to 1): fixing the nodes on ``x <= 0`` holds the wall exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

import numpy as np

from .lattice import Discretization
from .pieces import TensorPieces, nearest_node_discretization


def quadratic_spline(r: np.ndarray) -> np.ndarray:
    """``S2(r)`` for distances ``r`` in spacings."""
    s = np.abs(r)
    return np.where(s <= 0.5, 0.75 - s**2, np.where(s < 1.5, 0.5 * (1.5 - s) ** 2, 0.0))


def open_knot_tables(n_cells: int) -> np.ndarray:
    """Per-cell monomial coefficients for an open knot vector, shape (n_cells, 3 powers, 3 functions).

    Knots ``0, 0, 0, 1, ..., n - 1, n, n, n`` (in spacings); cell ``j`` carries functions
    ``j .. j + 2``, sampled from scipy's B-spline evaluation at three points and fitted (exact).
    """
    from scipy.interpolate import BSpline

    knots = np.concatenate([[0.0] * 2, np.arange(n_cells + 1.0), [float(n_cells)] * 2])
    samples = np.array([0.2, 0.5, 0.8])  # inside the cell: each belongs to its piece
    vandermonde = np.vander(samples, 3, increasing=True)
    tables = np.empty((n_cells, 3, 3))
    for cell in range(n_cells):  # once per grid, at set-up
        design = BSpline.design_matrix(cell + samples, knots, 2).toarray()[:, cell : cell + 3]
        tables[cell] = np.linalg.solve(vandermonde, design)
    # the coefficients are halves and quarters (e.g. (1 - s)^2, 2 s - 3 s^2 / 2): rounded to
    # them, the pieces vanish exactly where they should (the fit leaves ~1e-15 there)
    exact = np.round(tables * 64.0) / 64.0
    if np.abs(exact - tables).max() > 1e-12:  # pragma: no cover - a fit that went wrong
        raise AssertionError("open-knot quadratic pieces are not multiples of 1/64")
    return exact


def open_knot_discretization(name: str, lower: np.ndarray, n_elements: tuple[int, int], spacing: float) -> Discretization:
    """Open-knot quadratic B-splines: ``n + 2`` functions per direction of ``n`` cells."""
    import skfem

    nx, ny = n_elements[0] + 2, n_elements[1] + 2
    # Greville abscissae (t_(i+1) + t_(i+2)) / 2: 0, 1/2, 3/2, ..., n - 1/2, n
    positions = [np.concatenate([[0.0], np.arange(n) + 0.5, [float(n)]]) for n in n_elements]
    gx, gy = np.meshgrid(lower[0] + spacing * positions[0], lower[1] + spacing * positions[1], indexing="ij")
    index_x, index_y = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    ix, iy = np.meshgrid(np.arange(n_elements[0]), np.arange(n_elements[1]), indexing="ij")
    a, b = np.divmod(np.arange(9), 3)
    # cell (ix, iy), function 3 a + b: node (ix + a, iy + b), index (ix + a) * ny + iy + b
    connectivity = (ix.ravel()[:, None] + a) * ny + (iy.ravel()[:, None] + b)
    x = lower[0] + spacing * np.arange(n_elements[0] + 1)
    y = lower[1] + spacing * np.arange(n_elements[1] + 1)
    return Discretization(
        basis=name,
        spacing=spacing,
        element_width=spacing,
        lower=lower,
        n_elements=n_elements,
        nodes=np.ascontiguousarray(np.column_stack([gx.ravel(), gy.ravel()]), dtype=float),
        connectivity=np.ascontiguousarray(connectivity, dtype=np.int32),
        local_basis=TensorPieces(tuple(open_knot_tables(n) for n in n_elements), n_elements[1]),
        mesh=skfem.MeshQuad.init_tensor(x, y),
        element=None,
        nonnegative=True,
        # the functions' indices: their Greville points are no lattice points
        node_lattice=np.column_stack([index_x.ravel(), index_y.ravel()]),
    )


@dataclass(frozen=True)
class BSpline2Basis:
    """Quadratic B-splines on the lattice; ``knots`` is ``"ghost"`` (uniform, the extra column)
    or ``"open"``."""

    name: str = "bspline2"
    knots: str = "ghost"
    degree: int = 2
    cells_per_element: int = 1
    support_width: int = 3
    nonnegative: bool = True
    #: the library's own estimate on a free 16 x 16 block, 2 x 2 points a cell, in spacings
    #: over c_p (no Bloch analysis here; the same set-up gives q1 1.733 and 0.408, cubic
    #: splines 2.609 and 0.136: the free edges' modes set the consistent values)
    critical_step_factors: Mapping[str, float] = field(
        default_factory=lambda: MappingProxyType({"lumped": 2.31, "consistent": 0.058}))
    tensor_gram: bool = False
    mass_threshold: bool = True
    sized: bool = False

    def build(self, lower: np.ndarray, n_elements: tuple[int, int], spacing: float,
              points_per_cell: int = 2) -> Discretization:
        if self.knots == "open":
            return open_knot_discretization(self.name, lower, n_elements, spacing)
        return nearest_node_discretization(self.name, lower, n_elements, spacing, 2, quadratic_spline,
                                           self.nonnegative)


BSPLINE2 = BSpline2Basis()
#: its factors by the same estimate: 1.559 lumped, 0.288 consistent
BSPLINE2_OPEN = BSpline2Basis(name="bspline2_open", knots="open", critical_step_factors=MappingProxyType(
    {"lumped": 1.56, "consistent": 0.29}))
