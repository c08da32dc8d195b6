"""The numba engine: the step's transfers as compiled kernels over the points.

:class:`CompiledTransfer` runs the kernels of :mod:`femgrid_mpm.kernels` and
builds the matrices ``ctx.N``, ``ctx.dNdx``, ``ctx.dNdy`` only if an effect
reads them.  What P2G sums besides mass and momentum the mass model declares
(:class:`femgrid_mpm.mass.Assembly`): the nodal volumes, the consistent
matrix into the grid's fixed pattern, or the HRZ weights, which the kernels
compute point by point.
"""

from __future__ import annotations

import dataclasses

import numba
import numpy as np
import scipy.sparse as sp

from ..kernels import parallel
from ..kernels.families import FAMILIES
from ..kernels.mass_product import weighted_mass_product
from ..kernels.pattern import mass_pattern
from ..kernels.shape_matrices import evaluate_shape_functions
from ..kernels.tables import separated_tables
from ..mass import NodalSums
from ..materials import LinearElastic
from ..step import StepContext
from .engine import Engine


class CompiledTransfer(Engine):
    """The numba engine: fused kernels over the points, buffers reused from step to step."""

    name = "numba"

    def __init__(self, simulation):
        grid = simulation.grid
        self.grid = grid
        self.basis = separated_tables(grid)
        # tensor-product bases take the unrolled, sum-factorized kernels; serendipity (tensor
        # products plus a share of the centre one) the folded ones; the flat ones serve any basis
        if self.basis.tensor is not None:
            family, tables = "tensor", self.basis.tensor
        elif self.basis.folded is not None:
            family, tables = "folded", self.basis.folded
        else:
            family, tables = "flat", self.basis
        self.family = family
        self._arrays = tables.arrays()
        passes = FAMILIES["tensor" if family == "tensor" else "local"]  # the flat and folded forms share kernels
        self._p2g, self._p2g_sums, self._g2p = passes.p2g, passes.p2g_sums, passes.g2p
        self._stress_and_force = passes.stress_and_force
        self._point_weights = passes.point_weights
        self._velocity_gradient, self._internal_force = passes.velocity_gradient, passes.internal_force
        self.signed = not grid.nonnegative
        self.matrices = ShapeFunctionMatrices(grid, self.basis)
        n, n_nodes = simulation.particles.n, grid.n_nodes
        self._grid_shape = (n_nodes, 2)  # of the fields a step returns (a property call less per step)
        assembly = simulation.mass.assembly
        # HRZ: the kernels weigh momentum and velocity increments by W = N^2 / sum N^2
        self.hrz = assembly.hrz_weights
        self.grid_mass = np.zeros(n_nodes)
        # |N|.T @ m_p (signed bases), or the HRZ diagonal W.T @ m_p
        self.grid_absolute = np.zeros(n_nodes if self.signed or self.hrz else 1)
        # N.T @ V_p: consistent mass (weak nodes) and the lumped mass threshold
        self.want_volume = assembly.node_volume
        self.grid_volume = np.zeros(n_nodes if self.want_volume else 1)
        # per point, from the force pass to G2P: div v and N @ v_rel of the step's start
        self.start_motion = np.zeros((n, 3))
        self._relative = np.zeros((n_nodes, 2))
        self._strain_increment = self._gradient_increment = None
        self._stress_total = 0.0
        # consistent mass: assembled in the P2G pass into a pattern fixed per grid
        self.pattern = None
        if assembly.matrix:
            connectivity = tables.connectivity
            self.pattern = mass_pattern(grid, connectivity)
            self._ordered = family == "tensor" and _ordered_slots(self.pattern, len(tables.marker))
        # what P2G hands the mass model: these buffers, refilled every step
        self._sums = NodalSums(
            mass=self.grid_mass,
            absolute=self.grid_absolute if self.signed and not self.hrz else None,
            hrz=self.grid_absolute if self.hrz else None,
            volume=self.grid_volume if self.want_volume else None,
            pattern=self.pattern,
            product=self._mass_product if assembly.product else None,
        )
        self._points = simulation.particles  # the points of the last P2G, for the product
        if assembly.product:  # each point's values and nodes, recorded at the step's first product
            slots = tables.connectivity.shape[1] if family == "flat" else len(tables.marker) ** 2
            self._weights, self._nodes = np.empty((n, slots)), np.empty((n, slots), dtype=np.uint32)
            self._weights_recorded = False
        self._cells = simulation.cell_masses
        # threads: chunked variants of the tensor and folded kernels (lumped P2G, linear elastic stress,
        # G2P), whose serial kernel the basis' form picks (None: tensor)
        # the points are cut into `threads` chunks whatever the machine has (the sums' grouping, hence the
        # bits, depend on the count asked for only); numba runs them on as many threads as it has
        self.threads = simulation.scene.solver.threads if family in ("tensor", "folded") else 1
        # the threaded kernels' arguments: a form before the connectivity (the fold's place), None for tensor bases
        self._chunked_arrays = (*self._arrays[:-1], None, self._arrays[-1]) if family == "tensor" else self._arrays
        if self.threads > 1:
            numba.set_num_threads(min(self.threads, numba.config.NUMBA_NUM_THREADS))
            self._mass_parts = np.zeros((self.threads, n_nodes))
            self._absolute_parts = np.zeros((self.threads, n_nodes if self.signed or self.hrz else 1))
            self._momentum_parts = np.zeros((self.threads, n_nodes, 2))
            self._force_parts = np.zeros((self.threads, n_nodes, 2))
            self._relative_parts = np.zeros((self.threads, n_nodes, 2))
        self._lame = None
        materials = simulation.materials
        if all(type(material) is LinearElastic for material in materials):
            self._lame = np.array([[m.lame_lambda, 2.0 * m.shear_modulus] for m in materials])

    def context(self, simulation, dt: float) -> StepContext:
        return OnDemandContext(simulation, self.matrices, dt=dt)

    def to_grid(self, ctx: StepContext, mass) -> np.ndarray:
        p = ctx.particles
        self._points, self._weights_recorded = p, False
        self.matrices.invalidate()
        mass.points_moved()
        momentum = np.empty(self._grid_shape)
        pattern = self.pattern
        if self.threads > 1 and pattern is None and not self.want_volume:
            outside = parallel.parallel_p2g(
                p.x, p.v, p.mass, p.density, ctx.frame_velocity, self.signed, self.hrz, *self._chunked_arrays,
                self.grid_mass, self.grid_absolute, momentum, self._mass_parts, self._absolute_parts,
                self._momentum_parts)
        elif pattern is None:
            outside = self._p2g_sums(
                p.x, p.v, p.mass, p.density, ctx.frame_velocity, self.signed, self.want_volume, self.hrz,
                *self._arrays, self.grid_mass, self.grid_absolute, self.grid_volume, momentum)
        else:
            outside = self._p2g(
                p.x, p.v, p.mass, p.density, ctx.frame_velocity, self.signed, self.want_volume, True, self.hrz,
                *self._arrays, self.grid_mass, self.grid_absolute, self.grid_volume, momentum,
                pattern.indptr, pattern.rank, pattern.complete, pattern.slots, pattern.centre, self._ordered,
                pattern.mirror_target, pattern.mirror_source, pattern.data)
        if outside >= 0:
            self.grid.locate(p.x)  # raises the ValueError naming the points outside
            raise AssertionError(f"point {outside} is outside the grid")  # pragma: no cover
        sums = self._sums
        if self._cells.uniform is None:  # bodies of different densities: a full cell's mass at each node
            sums = dataclasses.replace(sums, scale=self._cells.at_nodes(ctx.N))
        mass.assemble_sums(sums)
        return momentum

    def _mass_product(self, field: np.ndarray) -> np.ndarray:
        """``N.T diag(m_p) N field`` at the points' places of the last P2G, serially."""
        points = self._points
        if not self._weights_recorded:
            self._point_weights(points.x, *self._arrays, self._weights, self._nodes)
            self._weights_recorded = True
        out = np.empty(self._grid_shape)
        weighted_mass_product(points.mass, self._weights, self._nodes, np.ascontiguousarray(field, dtype=float), out)
        return out

    def internal_force(self, ctx: StepContext, dt: float, materials, body_slices) -> np.ndarray:
        p = ctx.particles
        force = np.empty(self._grid_shape)
        if self._lame is not None and self.threads > 1:
            self._stress_total = parallel.parallel_stress_and_force(
                p.x, ctx.velocity, ctx.frame_velocity, self._relative, dt, p.mass, p.density, p.body, self._lame,
                *self._chunked_arrays, p.strain, p.stress, force, self.start_motion, self._force_parts,
                self._relative_parts,
            )
            return force
        if self._lame is not None:
            self._stress_total = self._stress_and_force(
                p.x, ctx.velocity, ctx.frame_velocity, self._relative, dt, p.mass, p.density, p.body, self._lame,
                *self._arrays, p.strain, p.stress, force, self.start_motion,
            )
            return force
        if self._strain_increment is None:
            self._strain_increment = np.empty((p.n, 3))
            self._gradient_increment = np.empty((p.n, 4))
        self._velocity_gradient(p.x, ctx.velocity, ctx.frame_velocity, self._relative, dt, *self._arrays, p.strain,
                                  self._strain_increment, self._gradient_increment, self.start_motion)
        for material, members in zip(materials, body_slices):
            material.update(p, members, self._strain_increment, self._gradient_increment)
        self._stress_total = self._internal_force(p.x, p.mass, p.density, p.stress, *self._arrays, force)
        return force

    def to_points(self, ctx: StepContext, dt: float) -> float:
        p = ctx.particles
        if self.threads > 1:
            total = parallel.parallel_g2p(p.x, p.v, p.density, ctx.acceleration, ctx.frame_velocity,
                                          dt, self.start_motion, self.hrz, *self._chunked_arrays, self.threads)
        else:
            total = self._g2p(p.x, p.v, p.density, ctx.acceleration, ctx.frame_velocity, dt,
                              self.start_motion, self.hrz, *self._arrays)
        self.matrices.invalidate()  # the points moved
        ctx.mass.points_moved()
        return total + self._stress_total


def _ordered_slots(pattern, n1: int) -> bool:
    """Whether the stencil slots in tensor order are what :func:`~femgrid_mpm.kernels.p2g.tensor_p2g`'s
    fast path assumes: those of ``b = (k, l)`` seen from ``a = (i, j)`` consecutive in
    ``l``, and at least the centre exactly when ``(k, l) >= (i, j)``."""
    i, j, k, l = np.meshgrid(*(np.arange(n1),) * 4, indexing="ij")
    slots = pattern.slots.reshape(n1, n1, n1, n1)
    upper = (k > i) | ((k == i) & (l >= j))
    return bool(np.array_equal(slots, slots[..., :1] + l) and np.array_equal(slots >= pattern.centre, upper))


class ShapeFunctionMatrices:
    """``N, dNdx, dNdy`` as scipy CSR matrices over buffers the kernel fills, on demand.

    The matrices are created once and refilled in place when asked for after
    the points moved (each owns its index arrays, as
    :meth:`femgrid_mpm.Grid.shape_functions` promises).  Whatever an effect
    did to them (scipy sorts indices in place in some operations) is undone
    by the next refill.
    """

    def __init__(self, grid, basis):
        self.grid = grid
        self.basis = basis
        self._fresh = False
        self._matrices = None
        self._n = -1

    def invalidate(self) -> None:
        self._fresh = False

    def get(self, x: np.ndarray) -> tuple:
        if self._fresh:
            return self._matrices
        n, n_local = len(x), self.basis.n_local
        if n != self._n or not self._intact():
            self._allocate(n, n_local)
        data, nodes = self._data, self._nodes
        outside = evaluate_shape_functions(self.basis, x, data[0], data[1], data[2], nodes)
        if outside >= 0:
            self.grid.locate(x)  # raises
        for matrix, own in zip(self._matrices, self._indices):
            np.copyto(own, nodes.reshape(-1))
            matrix.has_sorted_indices = False
            matrix.has_canonical_format = False
        self._fresh = True
        return self._matrices

    def _allocate(self, n: int, n_local: int) -> None:
        self._n = n
        self._data = [np.zeros((n, n_local)) for _ in range(3)]
        self._nodes = np.zeros((n, n_local), dtype=np.int32)
        self._indices = [np.zeros(n * n_local, dtype=np.int32) for _ in range(3)]
        indptr = np.arange(0, n * n_local + 1, n_local, dtype=np.int32)
        shape = (n, self.grid.n_nodes)
        self._matrices = tuple(
            sp.csr_matrix((data.reshape(-1), indices, indptr.copy()), shape=shape, copy=False)
            for data, indices in zip(self._data, self._indices)
        )
        self._views = [(m.data, m.indices) for m in self._matrices]

    def _intact(self) -> bool:
        """The matrices still use our buffers (no operation replaced their arrays)."""
        return all(m.data is data and m.indices is indices for m, (data, indices) in zip(self._matrices, self._views))


class OnDemandContext(StepContext):
    """A :class:`StepContext` whose ``N``, ``dNdx``, ``dNdy`` are built when first read in a step."""

    def __init__(self, simulation, matrices: ShapeFunctionMatrices, **fields):
        self._shape_functions = matrices
        super().__init__(simulation, **fields)

    def _matrix(index: int):  # noqa: N805 - a property factory used in the class body
        def get(self):
            return self._shape_functions.get(self.simulation.particles.x)[index]

        def set_(self, value):
            if value is not None:
                raise AttributeError("the numba engine computes N, dNdx and dNdy from the points")

        return property(get, set_)

    N = _matrix(0)
    dNdx = _matrix(1)
    dNdy = _matrix(2)
    del _matrix

