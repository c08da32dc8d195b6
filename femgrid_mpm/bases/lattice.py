"""What every basis hands to the grid: nodes, connectivity and local polynomials."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np



@dataclass(frozen=True)
class Discretization:
    """A basis laid on a rectangular lattice of elements.

    Attributes
    ----------
    basis : str
        Registry name of the basis.
    spacing : float
        Distance between neighbouring nodes (m).
    element_width : float
        Width of one element (m): ``spacing`` for q1 and bspline3,
        ``2 * spacing`` for q2 and serendipity.
    lower : ndarray, shape (2,)
        Lower-left corner of the element lattice (m).
    n_elements : (int, int)
        Elements along x and y.
    nodes : ndarray, shape (n_nodes, 2)
        Node coordinates (m), exactly ``lower + i * spacing``, numbered along
        the lattice: by x index, then by y index.
    connectivity : ndarray, shape (n_elements_x * n_elements_y, n_local), int32
        Node indices of the local functions of element ``ix * n_elements_y + iy``.
    local_basis : LocalPolynomials or TensorPieces
        Local functions in cell coordinates (xi along x, eta along y):
        ``local_basis.evaluate(cell_points, element) -> (phi, dphi_dxi,
        dphi_deta)``, each (n, n_local).
    mesh : skfem.MeshQuad
        The elements as a scikit-fem mesh (for plotting and output).
    element : object
        The element that defines the local functions.
    nonnegative : bool
        Whether every shape function is >= 0 (q1, bspline3), so that grid
        masses can never be negative.
    dofs : ndarray of int64, shape (n_nodes,), or None
        scikit-fem's number of each node's degree of freedom in ``mesh``'s
        basis (None for bases that scikit-fem does not define).
    node_lattice : ndarray of int64, shape (n_nodes, 2), or None
        Each node's position on the lattice in spacings from ``lower``, where
        rounding its coordinates would not give it (open-knot splines); None:
        ``rint((nodes - lower) / spacing)``.
    """

    basis: str
    spacing: float
    element_width: float
    lower: np.ndarray
    n_elements: tuple[int, int]
    nodes: np.ndarray
    connectivity: np.ndarray
    local_basis: Any
    mesh: Any
    element: Any
    nonnegative: bool
    dofs: Any = None
    node_lattice: Any = None
