"""The consistent mass matrix's fixed sparsity pattern, for assembly inside the P2G pass.

On a lattice the nodes two points' functions couple are known before any
point exists: node ``j`` couples to node ``i`` when both belong to one
element, and the lattice offset ``L_j - L_i`` depends only on the two local
functions ``(a, b)``.  So the pattern is built once per grid (every node's
row lists its neighbours in stencil order, its diagonal included), and the
P2G kernel adds ``m_p N_a N_b`` straight into the CSR data at
``indptr[i] + rank[i, slots[a, b]]``: no SpGEMM, no sorting, no
allocation per step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp


@dataclass
class MassPattern:
    """CSR structure of ``N.T diag(m) N`` on the whole grid.

    Attributes
    ----------
    indptr, indices : ndarray of int32
        The structure (columns of a row in stencil order, not sorted).
    data : ndarray, shape (nnz,)
        Filled by the P2G kernel each step.
    rank : ndarray of int32, shape (n_nodes, n_slots)
        Position of each stencil slot within its row (-1: not coupled).
    complete : ndarray of bool, shape (n_nodes,)
        Rows coupled to every stencil slot (the interior): there the rank
        of slot s is s, and the kernels skip the lookup in ``rank`` (a
        table of 5 MB for cubic splines at 1e5 nodes, read 256 times per
        point: skipping it made the assembling P2G 1.8x faster).
    slots : ndarray of int32, shape (n_local, n_local)
        Stencil slot of local function b seen from local function a, in the
        kernels' local order.
    diagonal : ndarray of int64, shape (n_nodes,)
        Position of each row's diagonal entry in ``data``.
    centre : int
        The stencil slot of a node seen from itself.  The stencil is sorted
        and symmetric, so slot ``s`` seen from the other node is
        ``2 * centre - s``.
    mirror_target, mirror_source : ndarray of int32, shape (nnz - n_nodes) / 2
        The kernels assemble only the entries with slot >= centre (the
        upper half in stencil order: 136 of a cubic point's 256 products)
        and copy each other entry from its transpose,
        ``data[mirror_target] = data[mirror_source]``: fewer scattered
        additions, and a matrix symmetric bit for bit.
    """

    indptr: np.ndarray
    indices: np.ndarray
    data: np.ndarray
    rank: np.ndarray
    slots: np.ndarray
    diagonal: np.ndarray
    complete: np.ndarray
    centre: int
    mirror_target: np.ndarray
    mirror_source: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return (len(self.indptr) - 1,) * 2

    def matrix(self) -> sp.csr_matrix:
        """The assembled matrix over ``data`` (no copy), with its own index arrays."""
        return sp.csr_matrix((self.data, self.indices.copy(), self.indptr.copy()), shape=self.shape, copy=False)


def lattice_coordinates(grid) -> np.ndarray:
    """Integer lattice position of every node, shape (n_nodes, 2).

    Nodes sit on the lattice ``lower + i * spacing`` for the finite elements
    and the paper's splines; open-knot splines move two nodes per direction
    to their Greville abscissae, so there the function index is used.
    """
    d = grid.discretization
    if d.node_lattice is not None:
        return np.asarray(d.node_lattice, dtype=np.int64)
    return np.rint((grid.nodes - grid.lower) / grid.spacing).astype(np.int64)


def mass_pattern(grid, connectivity: np.ndarray) -> MassPattern:
    """The pattern for the kernels' ``connectivity`` (n_elements, n_local), any local order."""
    lattice = lattice_coordinates(grid)
    n_nodes, n_local = grid.n_nodes, connectivity.shape[1]
    offsets = lattice[connectivity] - lattice[connectivity[:, :1]]  # (n_elements, n_local, 2)
    if np.any(offsets != offsets[:1]):
        raise AssertionError("elements are not translates of each other on the lattice")
    offsets = offsets[0]
    pairs = (offsets[None, :, :] - offsets[:, None, :]).reshape(-1, 2)  # b seen from a
    stencil, slots = np.unique(pairs, axis=0, return_inverse=True)
    slots = slots.reshape(n_local, n_local).astype(np.int32)
    present = np.zeros((n_nodes, len(stencil)), dtype=bool)
    for a in range(n_local):
        present[connectivity[:, a][:, None], slots[a][None, :]] = True
    counts = present.sum(axis=1)
    indptr = np.zeros(n_nodes + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    if indptr[-1] >= 2**31:
        raise ValueError("the mass matrix is too large for 32-bit indices")
    rank = np.cumsum(present, axis=1, dtype=np.int32) - 1
    rank[~present] = -1
    # column of each present slot: the node at lattice position L_i + offset (slot by slot: little memory)
    reach = np.abs(stencil).max()
    low = lattice.min(axis=0) - reach
    node_at = np.full(tuple(lattice.max(axis=0) + reach - low + 1), -1, dtype=np.int32)
    node_at[tuple((lattice - low).T)] = np.arange(n_nodes, dtype=np.int32)
    neighbour = np.empty((n_nodes, len(stencil)), dtype=np.int32)
    for slot, offset in enumerate(stencil):
        neighbour[:, slot] = node_at[lattice[:, 0] - low[0] + offset[0], lattice[:, 1] - low[1] + offset[1]]
    columns = neighbour[present]  # row-major: each row's slots in stencil order
    if np.any(columns < 0):
        raise AssertionError("a coupled node is missing from the lattice")
    centre = int(np.flatnonzero((stencil == 0).all(axis=1))[0])
    diagonal = indptr[:-1] + rank[:, centre]
    complete = counts == len(stencil)
    assert np.array_equal(rank[complete], np.broadcast_to(np.arange(len(stencil)), rank[complete].shape))
    if not np.array_equal(stencil[::-1], -stencil):
        raise AssertionError("the stencil is not symmetric")
    # the lower half in stencil order, and where each entry's transpose sits
    rows, lower = np.nonzero(present[:, :centre])
    mirror_target = indptr[rows] + rank[rows, lower]
    transposed = neighbour[rows, lower]
    mirror_source = indptr[transposed] + rank[transposed, 2 * centre - lower]
    if np.any(rank[transposed, 2 * centre - lower] < 0):
        raise AssertionError("the pattern is not symmetric")
    return MassPattern(indptr.astype(np.int32), columns, np.zeros(int(indptr[-1])), rank, slots, diagonal, complete,
                       centre, mirror_target.astype(np.int32), mirror_source.astype(np.int32))
