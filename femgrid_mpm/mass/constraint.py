"""Mirrored ghost nodes: the grid velocity ``v = T w`` of a reduced velocity ``w``, and the
mass ``T.T M T`` that goes with it.

The ghost-column splines (``bspline3``, ``bspline2``) carry one column of nodes beyond
each edge of the grid.  Holding the normal velocity at zero on the edge and ghost nodes
is not a roller: the ghost node's function is not zero on the edge, and the splines'
field there is not the mirror image the wall implies.  A wall at a lattice line ``k`` is
a plane of symmetry instead: the normal component of the velocity is odd about it, the
tangential one even.  The uniform splines are symmetric, ``B_(k-d)(x_k - r) = B_(k+d)(x_k
+ r)``, so the field is odd (even) about the line exactly when the coefficients are:
the line's node holds zero (is free), and the ghost node ``k - 1`` takes minus (plus)
the value of its mirror ``k + 1``.  A roller fixes the normal component, and the even
tangential component gives a zero shear strain rate on the wall (no shear traction); a
clamp makes both components odd.

Each degree of freedom ``(n, c)`` is then ``v[n, c] = sign[n, c] * w[image[n, c], c]``
with ``sign`` in {-1, 0, 1}: free nodes are their own image (sign 1), held ones have
sign 0, ghost nodes point at their mirror.  ``T.T`` folds a nodal vector onto the free
nodes (:meth:`NodeConstraint.fold`), ``T`` unfolds it (:meth:`NodeConstraint.unfold`);
``T.T M T`` is diagonal for a diagonal ``M`` (the ghost's mass added to its mirror's)
and keeps the consistent matrix's stencil (a ghost couples only to nodes its mirror
couples to).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .protocol import Assembly, Inertia, MassModel, NodalSums, SingularMassError


@dataclass(frozen=True)
class NodeConstraint:
    """``v[n, c] = sign[n, c] * w[image[n, c], c]``.

    Attributes
    ----------
    image : ndarray of int, shape (n_nodes, 2)
        The free node each degree of freedom follows (itself if free).
    sign : ndarray of float, shape (n_nodes, 2)
        1 (free, or an even ghost), -1 (an odd ghost) or 0 (held at zero).
    """

    image: np.ndarray
    sign: np.ndarray

    @classmethod
    def combine(cls, n_nodes: int, fixed: np.ndarray | None, mirrors: list[tuple[np.ndarray, np.ndarray]]) -> "NodeConstraint":
        """The constraint of held degrees of freedom and of mirror maps (each ``(image,
        sign)`` of one wall), composed until every image is a free node: a corner's
        ghost follows its mirror across one wall, then that node's across the other."""
        image = np.repeat(np.arange(n_nodes)[:, None], 2, axis=1)
        sign = np.ones((n_nodes, 2))
        columns = np.arange(2)[None, :]
        for _ in range(len(mirrors) + 1):  # each pass follows one more wall
            before = image.copy()
            for wall_image, wall_sign in mirrors:
                sign = sign * wall_sign[image, columns]
                image = wall_image[image, columns]
            if np.array_equal(image, before):
                break
        if fixed is not None:
            sign = np.where(fixed | fixed[image, columns], 0.0, sign)
        image = np.where(sign == 0.0, np.arange(n_nodes)[:, None], image)
        return cls(image=image, sign=sign)

    @property
    def free(self) -> np.ndarray:
        """(n_nodes, 2) bool: the reduced degrees of freedom."""
        return (self.image == np.arange(len(self.image))[:, None]) & (self.sign != 0.0)

    def fold(self, vector: np.ndarray) -> np.ndarray:
        """``T.T @ vector`` on the full node numbering (zero off the free degrees of freedom)."""
        folded = np.zeros_like(vector)
        for c in range(2):
            np.add.at(folded[:, c], self.image[:, c], self.sign[:, c] * vector[:, c])
        return folded

    def unfold(self, reduced: np.ndarray) -> np.ndarray:
        """``T @ reduced``: every degree of freedom from its image."""
        return self.sign * np.take_along_axis(reduced, self.image, axis=0)

    def matrix(self, component: int) -> sp.csr_matrix:
        """``T`` of one component, (n_nodes, n_nodes)."""
        n = len(self.image)
        return sp.csr_matrix((self.sign[:, component], (np.arange(n), self.image[:, component])), shape=(n, n))


class ConstrainedMass(MassModel):
    """A mass model solved on ``v = T w``: ``w = (T.T M T)^-1 T.T rhs``.

    Wraps the scene's lumped, HRZ or consistent model, which assembles ``M`` as
    without the constraint (a consistent model built with ``solves = False``: its own
    systems would be factored for nothing).  Diagonal masses fold into a diagonal;
    the consistent one is reduced per component and factored by SuperLU each step.
    """

    def __init__(self, inner: MassModel, constraint: NodeConstraint, diagonal: bool):
        self.inner, self.constraint, self.diagonal = inner, constraint, diagonal
        self.kind = inner.kind
        self.divides_by_row_sums = inner.divides_by_row_sums
        self._free = constraint.free
        self._factors: list | None = None

    # what the step and the monitors read: the wrapped model's
    @property
    def assembly(self) -> Assembly:
        return self.inner.assembly

    @property
    def lumped(self) -> np.ndarray:
        return self.inner.lumped

    @property
    def active(self) -> np.ndarray:
        return self.inner.active

    @property
    def scale(self):
        return self.inner.scale

    @property
    def nodes_below_threshold(self) -> int:
        return self.inner.nodes_below_threshold

    def assemble(self, N: sp.csr_matrix, m_p: np.ndarray, volume_p: np.ndarray | None = None) -> None:
        self.inner.assemble(N, m_p, volume_p)
        self._reduce()

    def assemble_sums(self, sums: NodalSums) -> None:
        self.inner.assemble_sums(sums)
        self._reduce()

    def _reduce(self) -> None:
        """``T.T M T``: a diagonal now, or (consistent) factored at the step's first solve,
        where a singular matrix stops the run as the unconstrained solve does."""
        self._factors = None
        if self.diagonal:
            masses = np.where(self.inner.active, self.inner.nodal_masses(), 0.0)
            folded = self.constraint.fold(np.repeat(masses[:, None], 2, axis=1))
            keep = self._free & (folded > 0.0)
            self._inverse = np.divide(1.0, folded, out=np.zeros_like(folded), where=keep)

    def _factor(self) -> list:
        """Per component: the kept (free, non-empty) degrees of freedom, their block of
        ``T.T M T`` and its SuperLU factors."""
        matrix = sp.csr_matrix(self.inner.inertia(None).matrix)
        factors = []
        for c in range(2):
            T = self.constraint.matrix(c)
            reduced = (T.T @ matrix @ T).tocsc()
            diagonal = reduced.diagonal()
            keep = np.flatnonzero(self._free[:, c] & (diagonal > 1e-24 * np.max(diagonal, initial=0.0)))
            block = reduced[keep][:, keep].tocsc()
            try:
                factors.append((keep, block, spla.splu(block) if keep.size else None))
            except RuntimeError as error:  # exactly singular
                raise SingularMassError(f"the consistent mass matrix with mirrored ghost nodes is singular ({error})",
                                        int(keep[0])) from None
        return factors

    def _reduced_solve(self, folded: np.ndarray) -> np.ndarray:
        if self.diagonal:
            return folded * self._inverse
        if self._factors is None:
            self._factors = self._factor()
        solution = np.zeros_like(folded)
        for c, (keep, block, factors) in enumerate(self._factors):
            if not keep.size:
                continue
            rhs = np.ascontiguousarray(folded[keep, c])
            solution[keep, c] = x = factors.solve(rhs)
            # SuperLU returns garbage without warning on a nearly singular matrix: check the residual
            if not np.all(np.isfinite(x)) or np.linalg.norm(block @ x - rhs) > 1e-8 * max(np.linalg.norm(rhs), 1e-300):
                raise SingularMassError("the consistent mass matrix with mirrored ghost nodes is singular or nearly "
                                        "so (too few points per cell for the basis, or weakly supported nodes)")
        return solution

    def solve(self, rhs: np.ndarray, kind: str = "velocity") -> np.ndarray:
        """``T (T.T M T)^-1 T.T rhs``."""
        return self.constraint.unfold(self._reduced_solve(self.constraint.fold(rhs)))

    def grid_velocity(self, relative_momentum: np.ndarray, frame_velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 17 on ``v = T w`` in the frame of ``v_ref``.  ``T`` holds the uniform ``v_ref``
        but for ``e = (1 - sign) v_ref`` (held and odd degrees of freedom), so with
        ``p = p_rel + M 1 v_ref``: ``v = T (T.T M T)^-1 T.T (p_rel + M e) + sign v_ref``,
        and a uniform motion the constraint allows (along a roller wall) has ``p_rel = 0``,
        ``e = 0`` and stays exact."""
        frame = np.asarray(frame_velocity, dtype=float)
        momentum = relative_momentum + self.inner.nodal_masses()[:, None] * frame
        excess = (1.0 - self.constraint.sign) * frame
        rhs = relative_momentum + self.apply(excess) if np.any(excess) else relative_momentum
        velocity = self.constraint.unfold(self._reduced_solve(self.constraint.fold(rhs))) + self.constraint.sign * frame
        return momentum, velocity

    def apply(self, vector: np.ndarray) -> np.ndarray:
        return self.inner.apply(vector)

    def inertia(self, N: sp.csr_matrix) -> Inertia:
        return self.inner.inertia(N)

    def transfer_weights(self, N: sp.csr_matrix) -> sp.csr_matrix:
        return self.inner.transfer_weights(N)

    def points_moved(self) -> None:
        self.inner.points_moved()

    def row_sums(self):
        return self.inner.row_sums()

    def nodal_masses(self) -> np.ndarray:
        return self.inner.nodal_masses()

    def state(self):
        return self.inner.state()

    def restore(self, arrays: dict, values: dict) -> None:
        self.inner.restore(arrays, values)

    def summary(self) -> dict:
        return self.inner.summary()
