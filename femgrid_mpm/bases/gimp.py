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

from .lattice import Discretization
from .pieces import nearest_node_discretization


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
        lam = 1.0 / (2 * points_per_cell)
        return nearest_node_discretization(self.name, lower, n_elements, spacing, 2 * points_per_cell,
                                           lambda r: gimp_weight(r, lam)[0], self.nonnegative)


GIMP = GimpBasis()
