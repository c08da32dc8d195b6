"""The two engines of the step's transfers: scipy (the reference) and numba (the default).

:meth:`femgrid_mpm.solver.Simulation.advance` is written once against this
interface (``[solver] engine`` picks the implementation):

``to_grid(ctx, mass) -> relative momentum``
    P2G: shape functions at the points, the grid mass (``mass`` is
    assembled), ``N.T @ (m_p (v_p - v_ref))``.
``internal_force(ctx, dt, materials, body_slices) -> force``
    Strain increment from the grid velocity (Eq. 18), each body's material
    update (Eq. 6), ``-(dNdx.T @ V sigma_x + dNdy.T @ V sigma_y)`` (Eq. 11).
``to_points(ctx, dt) -> checksum``
    G2P: ``v += dt N @ a``, ``x += dt (N @ v_rel + v_ref)``, density (Eqs.
    19-21); returns ``sum(v) + sum(x) + sum(stress)`` for the finiteness check.

A mass model with its own transfer weights (``mass.weights``, HRZ: see
:class:`femgrid_mpm.mass.HrzMass`) has them replace ``N`` in the P2G
momentum and the G2P velocity increment; gradients and positions keep
``N``.  The compiled kernels compute the HRZ weights point by point; a
model that needs the matrices themselves (``needs_matrices``) is assembled
from them.

:class:`ScipyTransfer` spells the paper's sparse linear algebra out with
``scipy.sparse`` matrices; :class:`CompiledTransfer` runs the kernels of
:mod:`.transfer` and builds the matrices ``ctx.N``, ``ctx.dNdx``,
``ctx.dNdy`` only if an effect reads them.
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp

from ..effects.base import StepContext
from ..materials import LinearElastic
from . import parallel
from .families import FAMILIES
from .pattern import mass_pattern
from .shape_matrices import evaluate_shape_functions
from .tables import separated_tables


class ScipyTransfer:
    """The reference engine: shape-function matrices and scipy.sparse products."""

    name = "scipy"

    def __init__(self, simulation):
        self.grid = simulation.grid
        self._divergence = None

    def context(self, simulation, dt: float) -> StepContext:
        return StepContext(simulation, dt=dt)

    def to_grid(self, ctx: StepContext, mass) -> np.ndarray:
        p = ctx.particles
        ctx.N, ctx.dNdx, ctx.dNdy = self.grid.shape_functions(p.x)  # ValueError if a point left the grid
        mass.assemble(ctx.N, p.mass, p.volume)
        return ctx.transfer_weights.T @ (p.mass[:, None] * (p.v - ctx.frame_velocity))

    def internal_force(self, ctx: StepContext, dt: float, materials, body_slices) -> np.ndarray:
        p = ctx.particles
        relative_velocity = ctx.velocity - ctx.frame_velocity  # gradients sum to zero: same gradient
        dv_dx = ctx.dNdx @ relative_velocity  # (n, 2): d(vx)/dx, d(vy)/dx
        dv_dy = ctx.dNdy @ relative_velocity  # (n, 2): d(vx)/dy, d(vy)/dy
        strain_increment = dt * np.column_stack([dv_dx[:, 0], dv_dy[:, 1], 0.5 * (dv_dy[:, 0] + dv_dx[:, 1])])
        gradient_increment = dt * np.column_stack([dv_dx[:, 0], dv_dy[:, 0], dv_dx[:, 1], dv_dy[:, 1]])  # dt L
        p.strain += strain_increment
        for material, members in zip(materials, body_slices):
            material.update(p, members, strain_increment, gradient_increment)
        self._divergence = dv_dx[:, 0] + dv_dy[:, 1]
        weighted_stress = p.volume[:, None] * p.stress  # volumes of time t
        return -(ctx.dNdx.T @ weighted_stress[:, [0, 2]] + ctx.dNdy.T @ weighted_stress[:, [2, 1]])

    def to_points(self, ctx: StepContext, dt: float) -> float:
        p = ctx.particles
        relative_velocity = ctx.velocity - ctx.frame_velocity
        p.v += dt * (ctx.transfer_weights @ ctx.acceleration)
        p.x += dt * (ctx.N @ relative_velocity + ctx.frame_velocity)
        p.density *= np.exp(-dt * self._divergence)
        return p.v.sum() + p.x.sum() + p.stress.sum()


class CompiledTransfer:
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
        self._velocity_gradient, self._internal_force = passes.velocity_gradient, passes.internal_force
        self.signed = not grid.nonnegative
        self.matrices = ShapeFunctionMatrices(grid, self.basis)
        n, n_nodes = simulation.particles.n, grid.n_nodes
        self._grid_shape = (n_nodes, 2)  # of the fields a step returns (a property call less per step)
        # HRZ: the kernels weigh momentum and velocity increments by W = N^2 / sum N^2
        self.hrz = hasattr(simulation.mass, "assemble_hrz")
        self.grid_mass = np.zeros(n_nodes)
        # |N|.T @ m_p (signed bases), or the HRZ diagonal W.T @ m_p
        self.grid_absolute = np.zeros(n_nodes if self.signed or self.hrz else 1)
        # N.T @ V_p: consistent mass (weak nodes) and the lumped mass threshold
        self.want_volume = bool(getattr(simulation.mass, "needs_volume", False))
        self.grid_volume = np.zeros(n_nodes if self.want_volume else 1)
        # a mass model that needs N itself is assembled from the matrices
        self.from_matrices = bool(getattr(simulation.mass, "needs_matrices", False))
        self._no_acceleration = np.zeros((n_nodes, 2))
        # per point, from the force pass to G2P: div v and N @ v_rel of the step's start
        self.start_motion = np.zeros((n, 3))
        self._relative = np.zeros((n_nodes, 2))
        self._strain_increment = self._gradient_increment = None
        self._stress_total = 0.0
        # consistent mass: assembled in the P2G pass into a pattern fixed per grid
        self.pattern = None
        if hasattr(simulation.mass, "assemble_pattern"):
            connectivity = tables.connectivity
            self.pattern = mass_pattern(grid, connectivity)
            self._ordered = family == "tensor" and _ordered_slots(self.pattern, len(tables.marker))
            self.want_volume = True
            self.grid_volume = np.zeros(n_nodes)
        # threads: chunked variants of the tensor and folded kernels (lumped P2G, linear elastic stress,
        # G2P), whose serial kernel the basis' form picks (None: tensor)
        threads = int(getattr(simulation.scene.solver, "threads", 1))
        self.threads = min(threads, numba.config.NUMBA_NUM_THREADS) if family in ("tensor", "folded") else 1
        # the threaded kernels' arguments: a form before the connectivity (the fold's place), None for tensor bases
        self._chunked_arrays = (*self._arrays[:-1], None, self._arrays[-1]) if family == "tensor" else self._arrays
        if self.threads > 1:
            numba.set_num_threads(self.threads)
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
        self.matrices.invalidate()
        if self.hrz:
            mass.forget_weights()
        if self.from_matrices:  # N built by the kernel (ValueError if a point left the grid), then scipy products
            mass.assemble(ctx.N, p.mass, p.volume)
            return ctx.transfer_weights.T @ (p.mass[:, None] * (p.v - ctx.frame_velocity))
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
        if pattern is not None:  # consistent: M assembled into the pattern
            mass.assemble_pattern(pattern, self.grid_mass, self.grid_volume)
        elif self.hrz:
            mass.assemble_hrz(self.grid_mass, self.grid_absolute)
        elif hasattr(mass, "assemble_sums"):
            mass.assemble_sums(self.grid_mass, self.grid_absolute if self.signed else None,
                               self.grid_volume if self.want_volume else None)
        else:  # a mass model that needs the matrices
            mass.assemble(ctx.N, p.mass, p.volume)
        return momentum

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
        # a model assembled from the matrices: the kernel moves the points (N) with no acceleration,
        # its transfer weights carry the acceleration after
        acceleration = self._no_acceleration if self.from_matrices else ctx.acceleration
        increment = dt * (ctx.transfer_weights @ ctx.acceleration) if self.from_matrices else None
        if self.threads > 1:
            total = parallel.parallel_g2p(p.x, p.v, p.density, acceleration, ctx.frame_velocity,
                                          dt, self.start_motion, self.hrz, *self._chunked_arrays, self.threads)
        else:
            total = self._g2p(p.x, p.v, p.density, acceleration, ctx.frame_velocity, dt,
                              self.start_motion, self.hrz, *self._arrays)
        self.matrices.invalidate()  # the points moved
        if self.hrz:
            ctx.mass.forget_weights()
        if increment is not None:
            p.v += increment
            total += float(increment.sum())
        return total + self._stress_total


def _ordered_slots(pattern, n1: int) -> bool:
    """Whether the stencil slots in tensor order are what :func:`~.transfer.tensor_p2g`'s
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


TRANSFERS = {"scipy": ScipyTransfer, "numba": CompiledTransfer}
