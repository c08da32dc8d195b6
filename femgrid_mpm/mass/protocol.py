"""The mass model's interface: what the step, the engines, the guards and the critical time step call.

A mass model is built complete (supports and the time step known) by
:func:`femgrid_mpm.mass.build_mass_model`; it says what the particle-to-grid
pass must produce for it in :attr:`MassModel.assembly` and takes it in
:meth:`MassModel.assemble` (from the shape-function matrices, the scipy
engine) or :meth:`MassModel.assemble_sums` (from the compiled pass's sums).
Then the step asks it for the grid velocity (Eq. 17) and the acceleration
(Eq. 10), the effects for ``M v`` and the transfer weights, the negative-mass
monitor for the row sums, the critical time step for the inertia of the
iteration, and checkpoints for its history.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp


class SingularMassError(RuntimeError):
    """The consistent mass matrix could not be solved (singular or nearly).

    ``node``: where it is weakest, if known (the node of SuperLU's smallest
    pivot against its diagonal entry, or of CG's largest residual)."""

    def __init__(self, message: str, node: int | None = None):
        super().__init__(message)
        self.node = node


@dataclass(frozen=True)
class Assembly:
    """What the particle-to-grid pass must produce for a mass model, besides the row
    sums ``m_I = N.T @ m_p`` and the momentum (always made).

    Attributes
    ----------
    node_volume : bool
        ``V_I = N.T @ V_p`` (the weak-node test, the mass threshold).
    matrix : bool
        The consistent matrix ``M = N.T diag(m_p) N``, into the grid's fixed
        pattern (:mod:`femgrid_mpm.kernels.pattern`).
    hrz_weights : bool
        The HRZ weights ``W = N^2 / sum N^2`` carry momentum and the velocity
        increment in place of ``N``, and P2G sums the diagonal ``W.T @ m_p``.
    per_body : bool
        One grid field per body (frictional contact): every grid array has a
        leading body axis, and the step runs the per-body engine.
    product : bool
        The consistent matrix's product with nodal fields, ``N.T diag(m_p) N f``,
        as a function of ``f`` (:attr:`NodalSums.product`), not the matrix.
    """

    node_volume: bool = False
    matrix: bool = False
    hrz_weights: bool = False
    per_body: bool = False
    product: bool = False


@dataclass(frozen=True)
class NodalSums:
    """The sums a compiled particle-to-grid pass made, shape (n_nodes,) each; the
    arrays are the engine's buffers, refilled every step (a model may keep them).

    ``absolute`` is ``|N|.T @ m_p`` on signed bases (None on non-negative ones,
    where it is ``mass``); ``hrz`` the HRZ diagonal ``W.T @ m_p``, ``volume``
    ``N.T @ V_p`` and ``pattern`` the assembled matrix when the model's
    :class:`Assembly` asks for them (else None); ``scale`` a full cell's mass at
    each node when the bodies' differ (:meth:`femgrid_mpm.mass.CellMasses.at_nodes`;
    None: the one of all bodies); ``product`` the consistent matrix's product with a
    nodal field (n_nodes, 2) at the points' places of this pass, when asked for.
    """

    mass: np.ndarray
    absolute: np.ndarray | None = None
    hrz: np.ndarray | None = None
    volume: np.ndarray | None = None
    pattern: object | None = None
    scale: np.ndarray | None = None
    product: Callable[[np.ndarray], np.ndarray] | None = None


@dataclass(frozen=True)
class Inertia:
    """The mass the explicit iteration has, for the critical time step
    (:func:`femgrid_mpm.stability.critical_time_step`): a diagonal mass, given by
    its velocity and acceleration inverses and the weights that carry momentum
    between points and grid; or a coupled ``matrix``, with ``consistent``, the
    points' ``N.T diag(m) N``, where the matrix differs from it (weak rows lumped,
    a mixed mass): the iteration's inverse mass is then ``M^-1 M_C M^-1``.  With
    ``corrections`` k > 0 the matrix is solved by k Jacobi corrections of its lumped
    solution over ``row_sums`` (:mod:`.iterated`): ``A_k M_C A_k`` instead."""

    inverses: tuple[np.ndarray, np.ndarray] | None = None
    transfer: sp.csr_matrix | None = None
    matrix: sp.csr_matrix | None = None
    consistent: sp.csr_matrix | None = None
    row_sums: np.ndarray | None = None
    corrections: int = 0


class MassModel(abc.ABC):
    """The grid mass of the step (paper Eqs. 10, 15-17, 19).

    Attributes
    ----------
    kind : str
        The scene's ``[solver] mass``.
    assembly : Assembly
        What P2G must produce.
    divides_by_row_sums : bool
        The solves divide by row sums, so a negative one is a hazard and the
        scene's ``negative_mass`` policy applies (lumped mass).
    lumped : ndarray, shape (n_nodes,)
        The row sums ``N.T @ m_p`` of the last assembly (the total over the
        bodies with one field per body).
    active : ndarray of bool, shape (n_nodes,)
        Nodes whose solution is computed (zero elsewhere).
    nodes_below_threshold : int
        Nodes the mass threshold changed at the last assembly.
    scale : float or ndarray
        A full lattice cell's mass of the material at the nodes at the last
        assembly (kg), one for all or one per node
        (:meth:`femgrid_mpm.mass.CellMasses.at_nodes`): what "empty" and
        "negative" are measured against.
    """

    kind: str
    assembly: Assembly
    divides_by_row_sums: bool = False
    lumped: np.ndarray
    active: np.ndarray
    nodes_below_threshold: int = 0
    scale: float | np.ndarray = 0.0

    @abc.abstractmethod
    def assemble(self, N: sp.csr_matrix, m_p: np.ndarray, volume_p: np.ndarray | None = None) -> None:
        """The grid mass of points with shape functions ``N`` (the scipy engine's way)."""

    @abc.abstractmethod
    def assemble_sums(self, sums: NodalSums) -> None:
        """The same from the sums of the compiled particle-to-grid pass."""

    @abc.abstractmethod
    def grid_velocity(self, relative_momentum: np.ndarray, frame_velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 17 in the frame moving with ``frame_velocity``: ``(p, v)``, the momentum
        ``p_rel + m v_ref`` and the velocity ``M^-1 p_rel + v_ref``."""

    @abc.abstractmethod
    def solve(self, rhs: np.ndarray, kind: str = "velocity") -> np.ndarray:
        """``M^-1 rhs`` on the active nodes, zero elsewhere; ``kind``: ``"velocity"`` or
        ``"acceleration"`` (a model with a history keys it by kind)."""

    @abc.abstractmethod
    def apply(self, vector: np.ndarray) -> np.ndarray:
        """``M @ vector`` (damping, the grid's kinetic energy)."""

    @abc.abstractmethod
    def inertia(self, N: sp.csr_matrix) -> Inertia:
        """The iteration's mass after :meth:`assemble` with these ``N``."""

    def field_inertias(self, N: sp.csr_matrix) -> list[tuple[slice, np.ndarray, Inertia]]:
        """The iteration's mass field by field: ``(points, active nodes, inertia)`` of
        each, the points' rows of ``N`` carrying it.  One field by default."""
        return [(slice(None), self.active, self.inertia(N))]

    def transfer_weights(self, N: sp.csr_matrix) -> sp.csr_matrix:
        """What carries mass, momentum and point forces between points and grid: ``N``
        (models with weights of their own replace it)."""
        return N

    def points_moved(self) -> None:
        """The points moved: anything derived from their places is stale."""

    def row_sums(self) -> list[tuple[np.ndarray, float | None, float | np.ndarray]]:
        """The row sums the negative-mass monitor checks, one array per field, each
        with its minimum if already known (else None) and its field's :attr:`scale`."""
        return [(self.lumped, None, self.scale)]

    def nodal_masses(self) -> np.ndarray:
        """The diagonal masses that weigh grid speeds (the rest test)."""
        return self.lumped

    def state(self) -> tuple[dict, dict] | None:
        """What carries from step to step, ``(arrays, values)``, or None: nothing does."""
        return None

    def restore(self, arrays: dict, values: dict) -> None:
        """Take back :meth:`state`."""

    def summary(self) -> dict:
        """Entries of the run's summary that belong to this model (none by default)."""
        return {}
