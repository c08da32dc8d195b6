"""The mass scale of "empty": a full lattice cell of the material at each node.

A node whose mass is below ``1e-12`` of a full cell's counts as empty (its
velocity and acceleration are zero), and a row sum below ``-1e-12`` of it as
negative.  A full cell is ``density * spacing^2`` of *the material there*:
with one scale for the whole scene (the heaviest body's), a body 1e12 times
lighter than another is empty everywhere and never moves.  Each node's scale
is therefore the largest full-cell mass among the bodies whose points touch
it (``N_ip != 0``), and every body's own where it alone is.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True)
class CellMasses:
    """``density_b * spacing^2`` of each body (kg per unit thickness), and its points.

    Parameters
    ----------
    per_body : ndarray, shape (n_bodies,)
    body_slices : list of slice
        Each body's points (stored body by body).
    """

    per_body: np.ndarray
    body_slices: list = field(repr=False)

    @classmethod
    def of(cls, densities, spacing: float, body_slices: list) -> "CellMasses":
        return cls(np.array([density * spacing**2 for density in densities], dtype=float), body_slices)

    @functools.cached_property
    def uniform(self) -> float | None:
        """The one scale when every body has the same (then no node needs its own), else None
        (read twice a step: computed once)."""
        if len(self.per_body) and np.all(self.per_body == self.per_body[0]):
            return float(self.per_body[0])
        return None

    @property
    def smallest(self) -> float:
        """The lightest body's full cell (kg)."""
        return float(self.per_body.min()) if len(self.per_body) else 0.0

    def at_nodes(self, N: sp.csr_matrix) -> float | np.ndarray:
        """The scale at each node for points with shape functions ``N``: the uniform one
        (a float), or per node the heaviest full cell among the bodies touching it
        (0 where none does), shape (n_nodes,)."""
        uniform = self.uniform
        if uniform is not None:
            return uniform
        scale = np.zeros(N.shape[1])
        for body in np.argsort(self.per_body, kind="stable"):  # the heaviest written last
            members = self.body_slices[body]
            entries = slice(N.indptr[members.start], N.indptr[members.stop])
            touched = N.indices[entries][N.data[entries] != 0.0]
            scale[touched] = self.per_body[body]
        return scale


def scale_arguments(scale: float | np.ndarray) -> tuple[float, np.ndarray]:
    """``(uniform, per_node)`` for a compiled pass over the nodes: one of them in use, the
    other 0 or empty (one compiled signature for both)."""
    if not isinstance(scale, np.ndarray):  # a float (one scale); np.ndim costs ~1 us a step
        return float(scale), NO_SCALES
    return 0.0, scale


NO_SCALES = np.zeros(0)
