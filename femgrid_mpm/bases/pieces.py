"""Tensor products of 1D polynomial pieces that differ from cell to cell.

Some bases are not one polynomial on every cell: open-knot splines change
their pieces in the cells next to a boundary, and a basis whose pieces are
finer than the node lattice (GIMP: the hat functions averaged over a point's
width) repeats a few different pieces along each direction.  Such a basis
gives, per direction, one table of monomial coefficients per cell, and a
point's ``n1 x n1`` functions are the products of the ``n1`` functions of its
cell along x and along y.  The compiled kernels read the same tables
(:func:`femgrid_mpm.kernels.tables.separated_tables`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TensorPieces:
    """Per-cell 1D pieces, multiplied.

    Attributes
    ----------
    tables : (ndarray, ndarray)
        Per-cell monomial coefficients along x and along y, each shape
        (n_cells, n1 powers, n1 functions): the cell's function ``a`` is
        ``sum_k tables[cell, k, a] s**k`` in the cell coordinate ``s``.
    n_cells_y : int
        Cells along y, to split an element index ``ix * n_cells_y + iy``.
    """

    tables: tuple[np.ndarray, np.ndarray]
    n_cells_y: int

    @property
    def n1(self) -> int:
        """Functions per direction on a cell (4 for cubic splines, 3 for GIMP)."""
        return self.tables[0].shape[2]

    @property
    def n_local(self) -> int:
        return self.n1 * self.n1

    @functools.cached_property
    def _pieces(self) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...]:
        """Per direction: the middle cell's piece (the interior's, for open knots), the other
        distinct pieces, and which of those each cell has (-1: the middle cell's).

        Cells whose coefficients are within 1e-14 of the middle cell's take its piece: the
        fitted tables of equal pieces differ in the last bits from cell to cell.
        """
        result = []
        for table in self.tables:
            common = np.ascontiguousarray(table[len(table) // 2])
            special = np.flatnonzero(np.any(np.abs(table - common) > 1e-14, axis=(1, 2)))
            index = np.full(len(table), -1, dtype=np.int64)
            others = np.empty((0, *common.shape))
            if len(special):
                others, which = np.unique(table[special].reshape(len(special), -1), axis=0, return_inverse=True)
                others = others.reshape(-1, *common.shape)
                index[special] = which.reshape(-1)
            result.append((common, others, index))
        return tuple(result)

    def evaluate(self, cell_points: np.ndarray, element: np.ndarray):
        """Values and cell-coordinate derivatives, each shape (n, n1 * n1), function ``n1 a + b``."""
        ix, iy = np.divmod(element, self.n_cells_y)
        fx, dfx = self._one_direction(0, ix, cell_points[:, 0])
        fy, dfy = self._one_direction(1, iy, cell_points[:, 1])
        n, n_local = len(cell_points), self.n_local
        values = (fx[:, :, None] * fy[:, None, :]).reshape(n, n_local)
        d_xi = (dfx[:, :, None] * fy[:, None, :]).reshape(n, n_local)
        d_eta = (fx[:, :, None] * dfy[:, None, :]).reshape(n, n_local)
        return values, d_xi, d_eta

    def _one_direction(self, axis: int, cell: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """1D values and derivatives of the ``n1`` functions of each point's cell.

        All points get the most common piece by one matrix product; only the
        points in cells with another piece are redone, piece by piece.
        """
        common, others, index = self._pieces[axis]
        n1 = self.n1
        powers = np.empty((len(s), n1))
        slopes = np.empty((len(s), n1))
        powers[:, 0] = 1.0
        slopes[:, 0] = 0.0
        powers[:, 1] = s
        slopes[:, 1] = 1.0
        for k in range(2, n1):
            np.multiply(powers[:, k - 1], s, out=powers[:, k])
            np.multiply(powers[:, k - 1], float(k), out=slopes[:, k])
        values = powers @ common
        derivatives = slopes @ common
        if len(others):
            piece = index[cell]
            rows = np.flatnonzero(piece >= 0)
            for position in np.unique(piece[rows]):
                sub = rows[piece[rows] == position]
                values[sub] = powers[sub] @ others[position]
                derivatives[sub] = slopes[sub] @ others[position]
        return values, derivatives


#: node entries of all pieces (nine each) a basis on pieces may lay out: about 45 bytes each at
#: the peak of the set-up (1.1 GB for 200 x 200 cells of gimp at 4 points per cell, 2.6e6 pieces)
MAX_PIECE_ENTRIES = 25_000_000


def nearest_node_pieces(n_cells: int, per_spacing: int, weight) -> tuple[np.ndarray, np.ndarray]:
    """Pieces ``1 / per_spacing`` of a spacing wide along one direction of ``n_cells`` lattice
    cells, for a basis whose 1D function ``weight(r)`` (``r`` in spacings from its node) is one
    quadratic on each piece and meets only the three nodes nearest to it.

    Returns the monomial coefficients of each piece's three functions, shape (pieces, 3 powers,
    3 functions), and the lattice index of each piece's middle (nearest) node.
    """
    piece = np.arange(n_cells * per_spacing)
    nearest = np.floor((piece + 0.5) / per_spacing + 0.5).astype(np.int64)
    samples = np.array([0.2, 0.5, 0.8])  # inside the piece: one quadratic there, fitted exactly
    vandermonde = np.vander(samples, 3, increasing=True)
    position = (piece[:, None] + samples[None, :]) / per_spacing  # (pieces, samples), in spacings
    tables = np.empty((len(piece), 3, 3))
    for a in range(3):
        values = weight(position - (nearest - 1 + a)[:, None])
        tables[:, :, a] = np.linalg.solve(vandermonde, values.T).T
    return tables, nearest


def nearest_node_discretization(name: str, lower: np.ndarray, n_elements: tuple[int, int], spacing: float,
                                per_spacing: int, weight, nonnegative: bool):
    """A tensor-product basis of :func:`nearest_node_pieces` on the node lattice, with one
    column (row) of nodes beyond each side of the domain (a point near the edge meets it)."""
    import skfem

    from .lattice import Discretization

    pieces = n_elements[0] * n_elements[1] * per_spacing**2
    if pieces * 9 > MAX_PIECE_ENTRIES:  # each piece stores its nine nodes (the flat kernels read them)
        raise ValueError(
            f"{name}: {n_elements[0]} x {n_elements[1]} cells cut into {per_spacing} x {per_spacing} pieces each "
            f"({pieces:.3g} pieces) need about {pieces * 9 * 45 / 1e9:.2g} GB to lay out, more than the "
            f"{MAX_PIECE_ENTRIES * 45 / 1e9:.2g} GB allowed: a coarser grid"
            + (" or fewer points per cell" if per_spacing > 2 else ""))
    (tables_x, nearest_x), (tables_y, nearest_y) = (nearest_node_pieces(n, per_spacing, weight) for n in n_elements)
    nx, ny = n_elements[0] + 3, n_elements[1] + 3  # nodes per direction, with the ghost columns
    ix_nodes, iy_nodes = np.meshgrid(np.arange(nx) - 1, np.arange(ny) - 1, indexing="ij")
    nodes = np.column_stack([lower[0] + spacing * ix_nodes.ravel(), lower[1] + spacing * iy_nodes.ravel()])
    # piece (px, py), function 3 a + b: the node nearest_x[px] - 1 + a, nearest_y[py] - 1 + b
    # (node (i, j) of the lattice has index (i + 1) * ny + j + 1)
    px, py = np.meshgrid(np.arange(len(tables_x)), np.arange(len(tables_y)), indexing="ij")
    a, b = np.divmod(np.arange(9), 3)
    connectivity = (nearest_x[px.ravel()][:, None] + a) * ny + (nearest_y[py.ravel()][:, None] + b)
    x = lower[0] + spacing * np.arange(n_elements[0] + 1)
    y = lower[1] + spacing * np.arange(n_elements[1] + 1)
    return Discretization(
        basis=name,
        spacing=spacing,
        element_width=spacing / per_spacing,  # the pieces
        lower=lower,
        n_elements=(len(tables_x), len(tables_y)),
        nodes=np.ascontiguousarray(nodes, dtype=float),
        connectivity=np.ascontiguousarray(connectivity, dtype=np.int32),
        local_basis=TensorPieces((tables_x, tables_y), len(tables_y)),
        mesh=skfem.MeshQuad.init_tensor(x, y),
        element=None,
        nonnegative=nonnegative,
        node_lattice=np.column_stack([ix_nodes.ravel(), iy_nodes.ravel()]),
    )
