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
divides those by ``mu``: they set its critical step (cubic B-splines: 13.6x lumped mass's steps
on the bar, see docs/time_step.md); here they do not.

The iteration projects the velocity afresh from the points each step, so its inverse mass is
``A_k M_C A_k`` (:func:`femgrid_mpm.stability.critical_time_step`), on a mode ``(1 - (1 -
mu)^(k+1))^2 / mu`` of lumped mass's ``mu``: the largest over ``mu`` grows with ``k`` (1.19 at
``k = 1``, 1.55 at 2), so the critical step is somewhat below lumped mass's and shrinks as ``k``
grows.  Constant fields are exact for every ``k`` (``L^-1 M 1 = 1`` away from supports): a rigid
translation is projected unchanged.

The systems (supports, empty and weak nodes) are the consistent mass's (:mod:`.consistent`);
only their solve differs.  Row sums must be positive: non-negative bases only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .consistent import ConsistentMass
from .protocol import Inertia


def corrected_inverse(matrix, rhs: np.ndarray, inverse_rows: np.ndarray, corrections: int) -> np.ndarray:
    """``A_k rhs`` (rhs (n, columns)): ``corrections`` Jacobi corrections of ``rhs / L`` on
    ``matrix`` (``inverse_rows``: ``1 / L`` on the solved rows, zero elsewhere)."""
    scale = inverse_rows[:, None]
    x = rhs * scale
    for _ in range(corrections):
        x += (rhs - matrix @ x) * scale
    return x


@dataclass
class IteratedMass(ConsistentMass):
    """The consistent mass solved by ``corrections`` Jacobi corrections of the lumped solution.

    Parameters as :class:`.consistent.ConsistentMass`, and ``corrections`` (``k >= 1``), the
    terms after the first of the truncated Neumann series of ``M^-1``.
    """

    corrections: int = 2
    kind = "iterated"

    @property
    def _keeps_history(self) -> bool:
        return False  # a fixed map of the right-hand side: no first guess to make

    def inertia(self, N) -> Inertia:
        """The matrix and the row sums: the iteration's inverse mass is ``A_k M_C A_k``."""
        return Inertia(matrix=self.matrix, consistent=self._consistent, row_sums=self.lumped,
                       corrections=self.corrections)

    def _solve_system(self, system, part: np.ndarray, kind: str, coupled: np.ndarray | None = None,
                      frame: np.ndarray | None = None) -> np.ndarray:
        """``A_k`` of the free rows' ``part``.  In a frame moving at ``v_ref`` with supports
        (``coupled`` given) the velocity is the absolute one's, ``A_k p - v_ref``: ``A_k`` is not
        the inverse, so the exact solve's ``A_k (p_rel + M_fc v_ref)`` would differ from it by
        ``E^(k+1) 1 v_ref`` (``E = I - L^-1 M_ff``) next to the supports, and the result would
        depend on the frame (the first point's velocity).  ``A_k L 1 - 1 = sum_(j=1..k) E^j 1``
        is what the frame adds; it is zero away from the supports, so without them the frame
        adds nothing and is left out."""
        inverse_rows = np.zeros(len(self.lumped))
        rows = ~system.excluded & (self.lumped > 0)
        inverse_rows[rows] = 1.0 / self.lumped[rows]
        solution = corrected_inverse(system.matrix, part, inverse_rows, self.corrections)
        if coupled is not None and frame is not None:
            solution += frame_share(system.matrix, inverse_rows, self.corrections) * frame[None, :]
        return solution


def frame_share(matrix, inverse_rows: np.ndarray, corrections: int) -> np.ndarray:
    """``sum_(j=1..k) E^j 1`` on the solved rows (``E = I - L^-1 M``), (n, 1): what ``A_k``
    makes of a uniform velocity's momentum beyond the velocity itself."""
    term = (inverse_rows > 0).astype(float)[:, None]  # 2-D: the half-stored matrix's product
    share = np.zeros_like(term)
    for _ in range(corrections):
        term = term - inverse_rows[:, None] * (matrix @ term)
        share += term
    return share
