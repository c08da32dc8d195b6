"""Tensor-product quadratic B-splines on the MPM lattice, with the paper-style extra column.

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
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

import numpy as np

from .lattice import Discretization
from .pieces import nearest_node_discretization


def quadratic_spline(r: np.ndarray) -> np.ndarray:
    """``S2(r)`` for distances ``r`` in spacings."""
    s = np.abs(r)
    return np.where(s <= 0.5, 0.75 - s**2, np.where(s < 1.5, 0.5 * (1.5 - s) ** 2, 0.0))


@dataclass(frozen=True)
class BSpline2Basis:
    """Uniform quadratic B-splines on the lattice."""

    name: str = "bspline2"
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
        return nearest_node_discretization(self.name, lower, n_elements, spacing, 2, quadratic_spline,
                                           self.nonnegative)


BSPLINE2 = BSpline2Basis()
