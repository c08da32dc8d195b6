"""Iterated mass: the consistent mass's inverse approximated by ``k`` Jacobi corrections of the lumped one.

Each solve of ``M x = b`` takes the lumped solution and corrects it ``k`` times by the
residual over the row sums ``L``::

    x_0 = L^-1 b,    x_(j+1) = x_j + L^-1 (b - M x_j),    i.e.  x_k = A_k b,
    A_k = sum_(j=0..k) (I - L^-1 M)^j L^-1

the Neumann series of ``M^-1`` cut after ``k + 1`` terms, a fixed linear map (no tolerance).
On a mode where ``M`` has the share ``mu`` of the row sums (``L^-1 M v = mu v``, ``mu`` in
``(0, 1]`` for a non-negative basis), ``A_k`` divides by ``mu L (1 - (1 - mu)^(k+1))^-1``:
the smooth modes, where ``1 - mu`` is of order ``h^2``, get the consistent mass to ``(1 -
mu)^(k+1)``, and the rough ones, whose ``mu`` is small (a node that the points see through its
function's tail, a checkerboard), keep about ``k + 1`` times their lumped mass.  Consistent mass
divides those by ``mu``: they set its critical step (cubic B-splines: 13.8x lumped mass's steps
on the bar, docs/time_step.md); here they do not.

The iteration projects the velocity afresh from the points each step, so its inverse mass is
``A_k M_C A_k`` (:func:`femgrid_mpm.stability.critical_time_step`), on a mode ``(1 - (1 -
mu)^(k+1))^2 / mu`` of lumped mass's ``mu``: the largest over ``mu`` grows with ``k`` (1.19 at
``k = 1``, 1.55 at 2), so the critical step is somewhat below lumped mass's and shrinks as ``k``
grows.  Constant fields are exact for every ``k`` (``L^-1 M 1 = 1`` away from supports): a rigid
translation is projected unchanged.

Each correction takes a product of ``M = N.T diag(m_p) N`` with the last solution: from the
points (``assembled`` False: :mod:`femgrid_mpm.kernels.mass_product`, a gather and a scatter a
point, the ``s x s`` couplings of a point's ``s`` functions never formed) or from the matrix the
P2G pass assembles into the grid's pattern.  A product from the points costs ~2.5x one from the
matrix (cubic splines, 2 x 2 points a cell), the assembly about three from the points: the points win while
``8 k <= s + 4`` (the rule of :func:`femgrid_mpm.mass.build_mass_model`; measured, docs/performance.md).
The nodes are lumped mass's (empty ones out); supports hold their degrees of freedom at zero and
out of ``M``'s rows.  Row sums must be positive: non-negative bases only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.sparse as sp

from .diagonal import LumpedMass
from .protocol import Assembly, Inertia, NodalSums
from .sparse import _CompiledCSR


def corrected_inverse(product: Callable, rhs: np.ndarray, inverse_rows: np.ndarray, corrections: int) -> np.ndarray:
    """``A_k rhs`` (rhs (n, columns)): ``corrections`` Jacobi corrections of ``rhs / L`` with
    ``product(x) = M x`` (``inverse_rows``: ``1 / L`` on the solved rows, zero elsewhere, of the
    shape of rhs or (n, 1))."""
    x = rhs * inverse_rows
    for _ in range(corrections):
        x += (rhs - product(x)) * inverse_rows
    return x


@dataclass
class IteratedMass(LumpedMass):
    """The consistent mass solved by ``corrections`` Jacobi corrections of the lumped solution.

    Parameters as :class:`.diagonal.LumpedMass` (no threshold), and ``corrections`` (``k >= 1``),
    the terms after the first of the truncated Neumann series of ``M^-1``; ``fixed`` (n_nodes,
    2), the degrees of freedom the supports hold at zero: left out of the corrections' rows and
    columns (zeroing them afterwards, exact for a diagonal mass, is not for ``A_k``); ``assembled``:
    the products from the assembled matrix (else from the points).
    """

    corrections: int = 2
    fixed: np.ndarray | None = field(default=None, repr=False)
    assembled: bool = True
    kind = "iterated"
    _product: Callable | None = field(default=None, init=False, repr=False)
    _point_mass: np.ndarray | None = field(default=None, init=False, repr=False)
    _over: tuple | None = field(default=None, init=False, repr=False)  # (pattern, its matrix)

    @property
    def assembly(self) -> Assembly:
        """The row sums and the consistent matrix's product."""
        return Assembly(matrix=True) if self.assembled else Assembly(product=True)

    def assemble(self, N: sp.csr_matrix, m_p: np.ndarray, volume_p: np.ndarray | None = None) -> None:
        super().assemble(N, m_p, volume_p)
        self._point_mass = m_p
        if self.assembled:
            self._product = (N.T @ N.multiply(m_p[:, None])).tocsr().__matmul__
        else:
            self._product = lambda values: N.T @ (m_p[:, None] * (N @ values))

    def assemble_sums(self, sums: NodalSums) -> None:
        super().assemble_sums(sums)
        if sums.pattern is None:
            self._product = sums.product
            return
        if self._over is None or self._over[0] is not sums.pattern:  # a view of the pattern's entries
            matrix = _CompiledCSR(sums.pattern.matrix(), copy=False)
            matrix.upper_start = sums.pattern.diagonal
            self._over = (sums.pattern, matrix)
        self._product = self._over[1].__matmul__

    def _column_inverse(self) -> np.ndarray:
        """``1 / L`` on each component's solved rows: the active nodes the supports leave free."""
        inverse = self._inverse[:, None]
        return inverse if self.fixed is None else np.where(self.fixed, 0.0, inverse)

    def solve(self, rhs: np.ndarray, kind: str = "velocity") -> np.ndarray:
        """``A_k rhs`` on each component's free active nodes, zero elsewhere."""
        return corrected_inverse(self._product, rhs, self._column_inverse(), self.corrections)

    def grid_velocity(self, relative_momentum: np.ndarray, frame_velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 17 in the frame moving with ``frame_velocity``: the velocity is the absolute solve's,
        ``A_k p``.  ``A_k`` is not the inverse: ``A_k L 1 = 1 + sum_(j=1..k) E^j 1`` (``E = I -
        L^-1 M``), whose sum is zero but next to supports, so there the relative momentum's solve
        plus the frame would depend on the frame (the first point's velocity): with supports the
        absolute momentum is solved (its round-off then scales with the frame's speed, as lumped
        mass's does), without them the relative one."""
        frame = np.asarray(frame_velocity, dtype=float)
        momentum = relative_momentum + self.lumped[:, None] * frame
        inverse = self._column_inverse()
        if self.fixed is not None and self.fixed.any() and frame.any():  # the rows not solved keep v_ref, as lumped mass's
            return momentum, np.where(inverse > 0, corrected_inverse(self._product, momentum, inverse, self.corrections), frame)
        return momentum, corrected_inverse(self._product, relative_momentum, inverse, self.corrections) + frame

    def apply(self, vector: np.ndarray) -> np.ndarray:
        """``M @ vector`` with the consistent matrix."""
        return self._product(vector)

    def inertia(self, N: sp.csr_matrix) -> Inertia:
        """The consistent matrix and the row sums: the iteration's inverse mass is ``A_k M_C A_k``."""
        matrix = (N.T @ N.multiply(self._point_mass[:, None])).tocsr()
        return Inertia(matrix=matrix, row_sums=np.where(self.active, self.lumped, 0.0), corrections=self.corrections)
