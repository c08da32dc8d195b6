"""Diagonal grid masses: lumped (row sums, paper Eqs. 15-16) and HRZ.

Negative and tiny lumped masses (q2, serendipity) have two remedies here:
the threshold of :class:`LumpedMass` (the absolute mass below a fraction of
a node's full share) and :class:`HrzMass` (a positive diagonal for every
basis, with transfers to match); docs/hard_cases.md has
what they measure.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..kernels.compiled import compiled
from .protocol import Assembly, Inertia, MassModel, NodalSums
from .scale import CellMasses, scale_arguments


@dataclass
class LumpedMass(MassModel):
    """Row-sum (lumped) nodal masses, Eq. 15; the solve is a division, Eq. 16.

    Parameters
    ----------
    n_nodes : int
    cells : CellMasses
        A full lattice cell's mass of each body (kg); masses with ``|m_i|`` below
        ``1e-12`` of the node's (:meth:`CellMasses.at_nodes`) count as empty.
    threshold : float, optional
        The ``negative_mass = "threshold"`` remedy: at a node whose volume
        fraction ``(N.T @ V_p)_i / integral(phi_i)`` is below this (every
        negative mass among them) both solves divide by the absolute mass
        ``sum_p m_p |N_ip|`` instead of the row sum (see :meth:`_replace`).
        None: no remedy.
    node_integrals : ndarray, shape (n_nodes,), optional
        ``integral(phi_i)`` (m^2), the full share of each node; needed with
        ``threshold`` and must be positive (not serendipity's corners).
    """

    n_nodes: int
    cells: CellMasses
    threshold: float | None = None
    node_integrals: np.ndarray | None = field(default=None, repr=False)
    kind = "lumped"
    divides_by_row_sums = True
    lumped: np.ndarray = field(init=False, repr=False)
    active: np.ndarray = field(init=False, repr=False)
    #: nodes below the threshold at the last assembly
    nodes_below_threshold: int = field(default=0, init=False)
    #: the smallest of ``lumped`` when the compiled sums were assembled, else None
    smallest: float | None = field(default=None, init=False, repr=False)
    #: a full cell's mass at the nodes at the last assembly: one float, or one per node
    scale: float | np.ndarray = field(default=0.0, init=False, repr=False)
    #: ``1 / m_i`` on the active nodes (zero elsewhere), reused from step to step
    _inverse: np.ndarray | None = field(default=None, init=False, repr=False)

    def __post_init__(self):
        if self.threshold is not None:
            if self.node_integrals is None or not np.all(self.node_integrals > 0):
                raise ValueError(
                    "the mass threshold needs a positive full share integral(phi_i) at every node; "
                    "serendipity's corner functions integrate to -1/12 of each element, so no relative "
                    "threshold applies (use solver.mass = 'hrz')"
                )

    @property
    def assembly(self) -> Assembly:
        """The row sums; ``N.T @ V_p`` too for the threshold."""
        return Assembly(node_volume=self.threshold is not None)

    def assemble(self, N: sp.csr_matrix, m_p: np.ndarray, volume_p: np.ndarray | None = None) -> None:
        self.lumped = N.T @ m_p
        self.smallest = None
        self.scale = self.cells.at_nodes(N)
        absolute = _absolute_mass(N, m_p, self.lumped)
        self.active = (np.abs(self.lumped) > 1e-6 * absolute) & (absolute > 1e-12 * self.scale)
        self._inverse = np.divide(1.0, self.lumped, out=np.zeros(self.n_nodes), where=self.active)
        self._replace(absolute, None if volume_p is None or self.threshold is None else N.T @ volume_p)

    def assemble_sums(self, sums: NodalSums) -> None:
        """The same from sums the compiled P2G made: ``N.T @ m_p``, (signed
        bases) ``|N|.T @ m_p``, (threshold) ``N.T @ V_p`` and (bodies of
        different densities) the scale at the nodes.  The arrays are kept, not copied."""
        lumped, absolute, volume = sums.mass, sums.absolute, sums.volume
        if self._inverse is None or len(self._inverse) != len(lumped):
            self._inverse = np.zeros(len(lumped))
            self.active = np.zeros(len(lumped), dtype=bool)
        self.lumped = lumped
        absolute = lumped if absolute is None else absolute
        self.scale = self.cells.uniform if sums.scale is None else sums.scale
        self.smallest = _lumped_inverse(lumped, absolute, *scale_arguments(self.scale), self._inverse, self.active)
        self._replace(absolute, volume)

    def _replace(self, absolute: np.ndarray, volume: np.ndarray | None) -> None:
        """The threshold: below it, divide by the absolute mass ``sum_p m_p |N_ip|``.

        That is the mass the node would have if no shape function were
        negative: positive, and never smaller than the share of any point.
        Velocity and acceleration divide by the same mass, which keeps the
        step's energy balance: the power the points' kinetic energy gains,
        ``sum_i a_i . p_i``, equals the power of the internal forces,
        ``sum_i f_i . v_i``, only if ``a_i = f_i / d_i`` and ``v_i = p_i /
        d_i`` with one ``d_i`` (zeroing the acceleration at a node whose
        velocity still strains the points injects ``-f_i . v_i``: measured,
        the q2 bar ending inside an element gained 85% of its energy in 1 s,
        at any time step).  Momentum is not exact there:
        ``sum_i m_i a_i - sum_i f_i = sum (m_i / d_i - 1) f_i`` over these
        nodes.  For q1 and splines ``|N| = N``: nothing changes.
        """
        self.nodes_below_threshold = 0
        if self.threshold is None:
            return
        if volume is None:
            raise ValueError("the mass threshold needs the nodal volumes N.T @ V_p")
        below = (absolute > 1e-12 * self.scale) & (volume < self.threshold * self.node_integrals)
        self.nodes_below_threshold = int(np.count_nonzero(below))
        if self.nodes_below_threshold:
            self._inverse[below] = 1.0 / absolute[below]
            self.active |= below

    def solve(self, rhs: np.ndarray, kind: str = "velocity") -> np.ndarray:
        """``rhs / m_i`` on active nodes, zero elsewhere; rhs shape (n_nodes, 2)."""
        return _scaled_rows(rhs, self._inverse)

    def inverses(self) -> tuple[np.ndarray, np.ndarray]:
        """The diagonal inverses ``(velocity, acceleration)`` of the last assembly."""
        return self._inverse, self._inverse

    def inertia(self, N: sp.csr_matrix) -> Inertia:
        return Inertia(inverses=self.inverses(), transfer=N)

    def row_sums(self) -> list[tuple[np.ndarray, float | None, float | np.ndarray]]:
        return [(self.lumped, self.smallest, self.scale)]

    def grid_velocity(self, relative_momentum: np.ndarray, frame_velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 17 in the frame moving with ``frame_velocity``: ``(p, v)``, the momentum
        ``p_rel + m v_ref`` and the velocity ``M^-1 p_rel + v_ref`` (one pass)."""
        momentum, velocity = np.empty_like(relative_momentum), np.empty_like(relative_momentum)
        _lumped_velocity(relative_momentum, self._inverse, self.lumped, frame_velocity, momentum, velocity)
        return momentum, velocity

    def apply(self, vector: np.ndarray) -> np.ndarray:
        """``M @ vector`` with the lumped matrix."""
        return vector * self.lumped[:, None]


def positive_weights(N: sp.csr_matrix) -> sp.csr_matrix:
    """``W_ip = N_ip^2 / sum_j N_jp^2``: each point's HRZ weights.

    Non-negative and a partition of unity (each row sums to one), on N's
    structure.  They lump each point's own mass matrix ``m_p N_p N_p^T``
    by HRZ (its diagonal, scaled to the point's mass), the way FEM lumps an
    element's.
    """
    squares = N.data * N.data
    rows = np.repeat(np.arange(N.shape[0]), np.diff(N.indptr))
    totals = np.bincount(rows, weights=squares, minlength=N.shape[0])
    return sp.csr_matrix((squares / totals[rows], N.indices.copy(), N.indptr.copy()), shape=N.shape)


@dataclass
class HrzMass(MassModel):
    """HRZ (Hinton-Rock-Zienkiewicz) lumping per point: a positive diagonal mass
    for every basis, and the transfers that go with it.

    Row sums of q2 and serendipity functions can be negative (serendipity's
    corners always are), and dividing by them breaks the run.  HRZ lumps
    each point's rank-one mass matrix ``m_p N_p N_p^T`` to its diagonal
    scaled to ``m_p``: the weights ``W_ip = N_ip^2 / sum_j N_jp^2``
    (:func:`positive_weights`) are non-negative and sum to one at every
    point, and ``m_i = sum_p m_p W_ip > 0``.

    One diagonal mass must go with one transfer, or momentum and uniform
    motion are lost: with ``m_i = M_ii sum m / sum M_jj`` (HRZ over the whole
    grid) and the usual ``v_p += dt N @ a``, momentum changes by
    ``dt sum_i (m_i^L / m_i) f_i != 0`` and a body in free fall does not
    fall at ``g`` where ``m^L`` and ``m`` differ.  So ``W`` carries
    everything that goes between points and grid as mass or momentum: P2G
    momentum ``W.T @ (m_p v_p)`` (``v_i`` a weighted average of the points,
    rigid motion exact), point forces (gravity and point loads,
    :meth:`femgrid_mpm.step.StepContext.add_point_forces`) and the
    G2P velocity increment ``v_p += dt W @ a``.  Gradients (strain rate,
    internal force) and positions keep the basis's own ``N``: the material
    still deforms with the element's interpolation.  Then momentum is exact
    (``sum_i m_i a_i = sum_i f_i``), internal forces do no net work on
    rigid motion, and free fall is exact.

    ``lumped`` keeps the row sums ``N.T @ m_p`` for the negative-mass
    record; ``diagonal`` is the mass used.
    """

    n_nodes: int
    cells: CellMasses
    kind = "hrz"
    assembly = Assembly(hrz_weights=True)
    #: W as a matrix: set by :meth:`assemble`; after :meth:`assemble_hrz` built
    #: from N when first asked for (:meth:`weights_for`: only effects that
    #: move point forces to the grid need it)
    weights: sp.csr_matrix | None = field(default=None, init=False, repr=False)

    def assemble(self, N: sp.csr_matrix, m_p: np.ndarray, volume_p: np.ndarray | None = None) -> None:
        self.weights = positive_weights(N)
        self.scale = self.cells.at_nodes(N)
        self.assemble_hrz(N.T @ m_p, self.weights.T @ m_p)

    def assemble_sums(self, sums: NodalSums) -> None:
        """The same from the sums the compiled P2G made: the row sums ``N.T @ m_p``
        and the diagonal ``W.T @ m_p`` (kept, not copied); ``weights`` then waits
        for :meth:`weights_for`."""
        self.scale = self.cells.uniform if sums.scale is None else sums.scale
        self.assemble_hrz(sums.mass, sums.hrz)

    def assemble_hrz(self, lumped: np.ndarray, diagonal: np.ndarray) -> None:
        """The row sums ``N.T @ m_p`` and the diagonal ``W.T @ m_p`` (kept, not copied)."""
        if self.weights is not None and self.weights.shape[1] != len(lumped):  # pragma: no cover - defensive
            self.weights = None
        self.lumped, self.diagonal = lumped, diagonal
        # no cancellation here (W >= 0): every node a point touches can be divided by.  A
        # cut-off like the row sums' 1e-12 would drop forces where W = N^2 is tiny and
        # grad N is not (cubic splines: a momentum leak of 1e-8 over the drifting bar)
        self.active = self.diagonal > 0.0
        self._inverse = np.divide(1.0, self.diagonal, out=np.zeros(self.n_nodes), where=self.active)

    def weights_for(self, N: sp.csr_matrix) -> sp.csr_matrix:
        """``W`` of this step's points, from their ``N`` if the P2G did not build it."""
        if self.weights is None:
            self.weights = positive_weights(N)
        return self.weights

    def transfer_weights(self, N: sp.csr_matrix) -> sp.csr_matrix:
        """``W`` carries mass, momentum and point forces (see the class's notes)."""
        return self.weights_for(N)

    def points_moved(self) -> None:
        """The next request rebuilds ``W``."""
        self.weights = None

    def nodal_masses(self) -> np.ndarray:
        """The HRZ diagonal, the mass used."""
        return self.diagonal

    def solve(self, rhs: np.ndarray, kind: str = "velocity") -> np.ndarray:
        """``rhs / m_i`` on active nodes, zero elsewhere."""
        return rhs * self._inverse[:, None]

    def inverses(self) -> tuple[np.ndarray, np.ndarray]:
        """The diagonal inverses ``(velocity, acceleration)`` (equal)."""
        return self._inverse, self._inverse

    def inertia(self, N: sp.csr_matrix) -> Inertia:
        return Inertia(inverses=self.inverses(), transfer=self.weights_for(N))

    def grid_velocity(self, relative_momentum: np.ndarray, frame_velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 17 with the HRZ mass, in the frame of ``frame_velocity``."""
        momentum, velocity = np.empty_like(relative_momentum), np.empty_like(relative_momentum)
        _lumped_velocity(relative_momentum, self._inverse, self.diagonal, frame_velocity, momentum, velocity)
        return momentum, velocity

    def apply(self, vector: np.ndarray) -> np.ndarray:
        """``M @ vector`` with the HRZ diagonal."""
        return vector * self.diagonal[:, None]


def _active(N: sp.csr_matrix, m_p: np.ndarray, lumped: np.ndarray, scale: float | np.ndarray) -> np.ndarray:
    """Nodes whose lumped mass can be divided by.

    Empty nodes are not.  With negative shape functions (q2, serendipity) a
    node's mass can also pass through zero by cancellation while points
    still touch it; there ``p_i / m_i`` is round-off over round-off, so a
    node whose mass is below 1e-6 of its absolute mass ``sum m_p |N_ip|``
    is not active either (its solution is zero, as for empty nodes).  ``scale``: a full
    cell's mass (kg), one or per node.
    """
    absolute = _absolute_mass(N, m_p, lumped)
    return (np.abs(lumped) > 1e-6 * absolute) & (absolute > 1e-12 * scale)


def _absolute_mass(N: sp.csr_matrix, m_p: np.ndarray, lumped: np.ndarray) -> np.ndarray:
    """``|N|.T @ m_p``: the lumped mass itself for non-negative bases."""
    if N.data.min(initial=0.0) >= 0.0:
        return lumped
    # a matrix of |N| on N's index arrays, for a transposed product only
    return sp.csr_matrix((np.abs(N.data), N.indices, N.indptr), shape=N.shape).T @ m_p


@compiled()
def _lumped_inverse(lumped, absolute, uniform, per_node, inverse, active):
    """:func:`_active` and ``1 / m_i`` on the active nodes, from the sums; returns the
    smallest ``m_i`` (for the negative-mass check, which would otherwise pass over them again).
    A full cell's mass is ``per_node[i]``, or ``uniform`` if ``per_node`` is empty."""
    smallest = np.inf
    per_node_scales = per_node.shape[0] > 0
    for i in range(len(lumped)):
        scale = per_node[i] if per_node_scales else uniform
        active[i] = abs(lumped[i]) > 1e-6 * absolute[i] and absolute[i] > 1e-12 * scale
        inverse[i] = 1.0 / lumped[i] if active[i] else 0.0
        smallest = min(smallest, lumped[i])
    return smallest


@compiled()
def _scaled_rows(rhs, inverse):
    """``rhs * inverse[:, None]`` into a new array (numpy's broadcasting cost ~1 us a step)."""
    out = np.empty_like(rhs)
    for i in range(rhs.shape[0]):
        for c in range(rhs.shape[1]):
            out[i, c] = rhs[i, c] * inverse[i]
    return out


@compiled()
def _lumped_velocity(relative_momentum, inverse, lumped, frame_velocity, momentum, velocity):
    """``p_rel + m v_ref`` and ``p_rel / m + v_ref``, as numpy would compute them."""
    for i in range(len(inverse)):
        for c in range(2):
            momentum[i, c] = relative_momentum[i, c] + lumped[i] * frame_velocity[c]
            velocity[i, c] = relative_momentum[i, c] * inverse[i] + frame_velocity[c]
