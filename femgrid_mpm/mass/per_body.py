"""Lumped masses per body: the grid fields of frictional contact (multi-field MPM).

With ``[contact] kind = "frictional"`` every body keeps its own grid field: its
own lumped mass, momentum, force, velocity and acceleration on every node
(grid arrays carry a leading body axis, shape (n_bodies, n_nodes, 2)); the
contact effect (:mod:`femgrid_mpm.effects.contact`) couples the fields where
bodies meet.  Points are stored body by body, so each body's rows of ``N``
are a contiguous slice.  Assembled from the matrices, by the per-body scipy
engine (:class:`femgrid_mpm.engines.scipy.PerBodyTransfer`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .diagonal import _active
from .protocol import Assembly, Inertia, MassModel, NodalSums
from .scale import CellMasses


@dataclass
class FieldLumpedMass(MassModel):
    """Lumped masses per body, shape (n_bodies, n_nodes); solves are divisions.

    ``lumped`` is the total over bodies (what a single field would have), for
    the energy bookkeeping and diagnostics; ``field_lumped`` is per body.  Each
    field is empty or negative relative to its own body's full cell.
    """

    n_nodes: int
    cells: CellMasses
    kind = "lumped"
    divides_by_row_sums = True
    assembly = Assembly(per_body=True)
    field_lumped: np.ndarray = field(init=False, repr=False)

    def assemble(self, N: sp.csr_matrix, m_p: np.ndarray, volume_p: np.ndarray | None = None) -> None:
        slices = self.cells.body_slices
        self.field_lumped = np.stack([N[members].T @ m_p[members] for members in slices])
        self.field_active = np.stack([
            _active(N[members], m_p[members], lumped, cell)
            for members, lumped, cell in zip(slices, self.field_lumped, self.cells.per_body)
        ])
        self.scale = self.cells.at_nodes(N)
        self._inverse = np.divide(1.0, self.field_lumped, out=np.zeros_like(self.field_lumped), where=self.field_active)
        self.lumped = self.field_lumped.sum(axis=0)
        self.active = self.field_active.any(axis=0)

    def assemble_sums(self, sums: NodalSums) -> None:
        raise NotImplementedError("one field per body is assembled from the shape-function matrices")

    def solve(self, rhs: np.ndarray, kind: str = "velocity") -> np.ndarray:
        """``rhs / m`` per field on active nodes, zero elsewhere; rhs (n_bodies, n_nodes, 2)."""
        return rhs * self._inverse[:, :, None]

    def grid_velocity(self, relative_momentum: np.ndarray, frame_velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        momentum = relative_momentum + self.field_lumped[:, :, None] * frame_velocity
        return momentum, self.solve(relative_momentum) + frame_velocity

    def apply(self, vector: np.ndarray) -> np.ndarray:
        """``M @ vector`` per field."""
        return vector * self.field_lumped[:, :, None]

    def row_sums(self) -> list[tuple[np.ndarray, float | None]]:
        """Each field divides by its own, measured against its own body's full cell."""
        return [(lumped, None, float(cell)) for lumped, cell in zip(self.field_lumped, self.cells.per_body)]

    def field_inertias(self, N: sp.csr_matrix) -> list[tuple[slice, np.ndarray, Inertia]]:
        """Each body's own field: its points move with its own masses only (a light body
        beside a heavy one has its own, shorter, critical step)."""
        return [(members, active, Inertia(inverses=(inverse, inverse), transfer=N[members]))
                for members, active, inverse in zip(self.cells.body_slices, self.field_active, self._inverse)]

    def inertia(self, N: sp.csr_matrix) -> Inertia:
        """The shared field's: the bodies' total mass, where any body has some."""
        inverse = np.divide(1.0, self.lumped, out=np.zeros(self.n_nodes), where=self.active)
        return Inertia(inverses=(inverse, inverse), transfer=N)
