"""One linear system of the consistent mass: the matrix for some of the two components with
its excluded degrees of freedom as identity rows, its factors or CG's boundary layer, and
the blend that replaces it where it is singular."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .direct import _factor, _smallest_pivot_node
from .ldl import NumericLDL, SymbolicLDL
from .exclusion import _exclude_in_place
from .preconditioners import BoundaryLayer, layout_of
from .reused import ReusedFactors
from .sparse import _CompiledCSR


@dataclass
class _System:
    """The consistent matrix for some of the two components, with the excluded
    degrees of freedom (empty or fixed) replaced by identity rows."""

    columns: list
    excluded: np.ndarray
    matrix: sp.csr_matrix
    inverse_diagonal: np.ndarray
    factors: object
    blended: bool = False
    _layer: "BoundaryLayer | None | bool" = False  # False: not built yet
    #: CG on a signed basis: whether the block near the edges is singular (None: not checked
    #: yet this step) and the node of its smallest pivot (:meth:`ConsistentMass._singular_near_edges`)
    singular: bool | None = None
    weakest: int | None = None
    #: "auto" below the direct limit: an earlier step's factors that precondition CG on this
    #: system (:mod:`.reused`), instead of its own ``factors``
    kept: "ReusedFactors | None" = None
    #: "auto" on a small system factored this step: its layout's ordering and structure
    #: (:mod:`.ldl`) and the factors on them (None where a pivot said singular), instead of ``factors``
    layout: "SymbolicLDL | None" = None
    ldl: "NumericLDL | None" = None

    def boundary_layer(self, lattice_shape: tuple, weak: np.ndarray,
                       layouts: dict | None = None) -> "BoundaryLayer | None":
        """CG's boundary layer (:class:`BoundaryLayer`), built at the first solve of the
        step and shared by the velocity and acceleration solves.  ``layouts``, kept by the
        caller over the steps, holds each system's last layer layout
        (:class:`.preconditioners.LayerLayout`), taken again where it fits."""
        if self._layer is False:
            # a blended system's matrix is another: its layout is kept apart, and a layout whose
            # block is singular too (the next step's may not be)
            key = (tuple(self.columns), self.blended)
            layout = layout_of(self.matrix, self.excluded, weak, lattice_shape,
                               None if layouts is None else layouts.get(key))
            if layouts is not None and layout is not None:
                layouts[key] = layout
            self._layer = BoundaryLayer.on(layout, self.matrix)
        return self._layer

    @classmethod
    def build(cls, matrix: sp.csr_matrix, columns: list, excluded: np.ndarray, direct: bool,
              diagonal_index: np.ndarray | None = None, in_place: bool = False) -> "_System":
        """``in_place``: ``matrix`` has already been reduced in place (its data is the system's)."""
        if diagonal_index is None:
            keep = sp.diags((~excluded).astype(float))
            reduced = (keep @ matrix @ keep + sp.diags(excluded.astype(float))).tocsr()
            reduced.sort_indices()  # every diagonal stored: symmetric Gauss-Seidel sweeps it (.gauss_seidel)
            inverse_diagonal = 1.0 / reduced.diagonal()
        else:  # the same on a structure with every diagonal entry: zero rows and columns, unit diagonal
            data = matrix.data
            if not in_place:  # on a copy: the other component's system needs the assembled entries too
                data = data.copy()
                _exclude_in_place(matrix.indptr, matrix.indices, data, diagonal_index, excluded)
            # the index arrays are shared with the (internal) assembled matrix: nothing sorts them;
            # made in place, the system is that matrix itself (a new scipy object cost ~25 us)
            reduced = matrix if in_place and isinstance(matrix, _CompiledCSR) else \
                _CompiledCSR((data, matrix.indices, matrix.indptr), shape=matrix.shape, copy=False)
            reduced.upper_start = diagonal_index  # exclusion and lumping keep the symmetry and the order
            reduced.upper_ordered = isinstance(matrix, _CompiledCSR) and matrix.upper_ordered
            inverse_diagonal = 1.0 / data[diagonal_index]
        return cls(columns, excluded, reduced, inverse_diagonal, _factor(reduced) if direct else None)

    def factor_now(self, symbolic: "SymbolicLDL", data: np.ndarray) -> None:
        """This step's ``L D L^T`` on its layout (:mod:`.ldl`) of the matrix whose entries are
        ``data`` (the assembled one: its free rows and columns are this system's)."""
        self.layout = symbolic
        self.ldl, self.weakest = symbolic.factor(data)
        self.singular = self.ldl is None  # its weakest node, for the stop's message

    def weakest_node(self, rhs: np.ndarray, solution: np.ndarray, direct: bool) -> int | None:
        """Where a failed solve finds the matrix weakest (for the stop's message): the node of the
        smallest pivot against its diagonal entry (direct, or CG's check near the edges), or
        of the largest residual (CG)."""
        if self.singular:
            return self.weakest
        if direct:
            return _smallest_pivot_node(self.matrix)
        residual = np.linalg.norm(rhs - self.matrix @ solution, axis=1)
        return int(np.argmax(residual)) if np.all(np.isfinite(residual)) else None

    def blend_with(self, target: np.ndarray, weight: float, direct: bool) -> None:
        """The fallback: ``(1 - weight) M + weight diag(target)`` on the kept rows."""
        if self.blended:
            return
        kept_target = np.where(self.excluded, 1.0, target)
        self.matrix = ((1.0 - weight) * self.matrix + weight * sp.diags(kept_target)).tocsr()
        self.matrix.sort_indices()
        self.inverse_diagonal = 1.0 / self.matrix.diagonal()
        self.factors = _factor(self.matrix) if direct else None
        self.ldl = None
        self.blended = True
        self.kept = None
        self._layer = False
