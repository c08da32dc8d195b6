"""Uniform GIMP (Bardenhagen & Kober 2004): q1's hat functions averaged over each point's domain.

A point stands for a square of its initial spacing ``spacing / points_per_cell``
(half-width ``l``), and its weight of node ``i`` is the hat function ``N_i``
averaged over that square, ``S_i(x_p) = (1 / |Omega_p|) int_Omega_p N_i``: a
tensor product of the 1D

    S(r) = 1 - (r^2 + lam^2) / (2 lam)      |r| <= lam
         = 1 - |r|                          lam <= |r| <= 1 - lam
         = (1 + lam - |r|)^2 / (4 lam)      1 - lam <= |r| <= 1 + lam

with ``r = (x - x_i) / spacing`` and ``lam = l / spacing = 1 / (2 points_per_cell)``
("uniform": the domain keeps its initial size).  The weights are smooth
(C1), so a point crossing a cell boundary changes its stress-divergence
gradually: the cure for q1's cell-crossing noise.

Every breakpoint of ``S`` lies on a multiple of ``l`` from a node, so on a
lattice of pieces ``l`` wide (``2 points_per_cell`` per spacing) each weight is
one quadratic per piece, and a piece meets the three nodes nearest to it: the
basis is :class:`~.pieces.TensorPieces` on that finer lattice, and the
compiled kernels read it as they read open-knot splines.  As for the paper's
splines, one column (row) of nodes lies beyond each side of the domain, for
points whose domain reaches past the edge: partition of unity and linear
completeness hold up to the boundary, and ``x <= 0`` selects the ghost column
with the boundary's nodes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

import numpy as np
import skfem

from .lattice import Discretization
from .pieces import TensorPieces


def gimp_weight(r: np.ndarray, lam: float) -> tuple[np.ndarray, np.ndarray]:
    """``S(r)`` and ``dS/dr`` for distances ``r`` in spacings and the half-width ``lam``."""
    s = np.abs(r)
    inner = 1.0 - (s**2 + lam**2) / (2.0 * lam)
    middle = 1.0 - s
    outer = (1.0 + lam - s) ** 2 / (4.0 * lam)
    value = np.where(s <= lam, inner, np.where(s <= 1.0 - lam, middle, np.where(s < 1.0 + lam, outer, 0.0)))
    slope = np.where(s <= lam, -s / lam, np.where(s <= 1.0 - lam, -1.0,
                                                   np.where(s < 1.0 + lam, -(1.0 + lam - s) / (2.0 * lam), 0.0)))
    return value, slope * np.sign(r)


def piece_tables(n_cells: int, points_per_cell: int) -> tuple[np.ndarray, np.ndarray]:
    """The pieces along one direction of ``n_cells`` lattice cells: per piece, the monomial
    coefficients of its three weights (shape (pieces, 3 powers, 3 functions)) and the
    lattice index of its middle node, the node nearest to it."""
    per_cell = 2 * points_per_cell
    lam = 1.0 / per_cell
    piece = np.arange(n_cells * per_cell)
    nearest = np.floor((piece + 0.5) / per_cell + 0.5).astype(np.int64)
    samples = np.array([0.2, 0.5, 0.8])  # inside the piece: one quadratic there, fitted exactly
    vandermonde = np.vander(samples, 3, increasing=True)
    position = (piece[:, None] + samples[None, :]) / per_cell  # (pieces, samples), in spacings
    tables = np.empty((len(piece), 3, 3))
    for a in range(3):
        node = nearest - 1 + a
        values, _ = gimp_weight(position - node[:, None], lam)
        tables[:, :, a] = np.linalg.solve(vandermonde, values.T).T
    return tables, nearest


@dataclass(frozen=True)
class GimpBasis:
    """Uniform GIMP on q1's lattice, laid for the points' size."""

    name: str = "gimp"
    degree: int = 2
    cells_per_element: int = 1
    #: q1's hats (two spacings), widened by a point's half-width on each side
    support_width: int = 2
    nonnegative: bool = True
    #: q1's: as seeded, the points' squares tile the cells, where averaging a bilinear function
    #: over a square gives its value at the centre, so the weights are q1's (the library's
    #: estimate on a free 16 x 16 block: 1.733 lumped and 0.408 consistent spacings over c_p
    #: for both)
    critical_step_factors: Mapping[str, float] = field(
        default_factory=lambda: MappingProxyType({"lumped": 1.0, "consistent": 0.5}))
    tensor_gram: bool = False
    mass_threshold: bool = True
    sized: bool = True

    def build(self, lower: np.ndarray, n_elements: tuple[int, int], spacing: float,
              points_per_cell: int = 2) -> Discretization:
        (tables_x, nearest_x), (tables_y, nearest_y) = (piece_tables(n, points_per_cell) for n in n_elements)
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
            basis=self.name,
            spacing=spacing,
            element_width=spacing / (2 * points_per_cell),  # the pieces
            lower=lower,
            n_elements=(len(tables_x), len(tables_y)),
            nodes=np.ascontiguousarray(nodes, dtype=float),
            connectivity=np.ascontiguousarray(connectivity, dtype=np.int32),
            local_basis=TensorPieces((tables_x, tables_y), len(tables_y)),
            mesh=skfem.MeshQuad.init_tensor(x, y),
            element=None,
            nonnegative=self.nonnegative,
            node_lattice=np.column_stack([ix_nodes.ravel(), iy_nodes.ravel()]),
        )


GIMP = GimpBasis()
