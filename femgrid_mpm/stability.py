"""Critical time step: the largest eigenvalue of ``M^-1 K`` for the actual points and grid.

The explicit step (symplectic Euler in the paper's update order) is stable
while ``omega_max dt < 2``, with ``omega_max^2`` the largest eigenvalue of
``K u = omega^2 M u`` on the free degrees of freedom.  ``K`` is the MPM
stiffness the points integrate, ``sum_p V_p B_p^T D B_p`` (small-strain
tangent of each body's material), and ``M`` the mass the iteration actually
has (see :func:`critical_time_step`), with supports and empty nodes removed.

:func:`critical_time_step` computes it at set-up (once; points that move
far change it, see the stress suite).  The bases' ``critical_step_factors``
gives the classic full-grid values in units of node spacing over p-wave
speed, for comparison only: near supports and partly filled cells the true
limit can be far smaller (the cantilever with consistent cubic B-splines:
a mode with 1e-4 of the lumped mass, unstable at the table's step).  Each basis
declares its own factors (``critical_step_factors``, see
:class:`femgrid_mpm.bases.BasisDefinition`).
A singular consistent mass (a mode without inertia; the run then relies on
``consistent_fallback``) admits no stable step: the estimate is then 0.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .bases import BASES
from .quadrature import MassReconstruction, StressReconstruction
from .mass.direct import symmetric_lu
from .mass.iterated import corrected_inverse
from .schemes import SCHEMES

def bloch_time_step(basis: str, mass: str, spacing: float, wave_speed: float) -> float:
    """The basis' classic estimate (s) for ``"lumped"`` or ``"consistent"`` mass on a grid of
    node ``spacing`` (m); 0 if no step is stable."""
    factor = BASES[basis].critical_step_factors[mass]
    return factor * spacing / wave_speed if wave_speed > 0 else math.inf


def stiffness_matrix(dNdx: sp.csr_matrix, dNdy: sp.csr_matrix, volume: np.ndarray, moduli: np.ndarray) -> sp.csr_matrix:
    """MPM stiffness ``sum_p V_p B_p^T D B_p``, shape (2 n_nodes, 2 n_nodes).

    Parameters
    ----------
    dNdx, dNdy : csr_matrix, shape (n_points, n_nodes)
    volume : ndarray, shape (n_points,)
        Point volumes (m^2).
    moduli : ndarray, shape (n_points, 4)
        ``D_11, D_12, D_22, G`` per point (Pa): the in-plane elasticity
        matrix with engineering shear.

    Degrees of freedom are ordered node by node, (x, y), as ``field.ravel()``
    of a (n_nodes, 2) array.
    """
    def weighted(a, b, w):
        return (a.T @ a.__class__(b.multiply((volume * w)[:, None]))).tocsr()

    d11, d12, d22, shear = moduli.T
    k_xx = weighted(dNdx, dNdx, d11) + weighted(dNdy, dNdy, shear)
    k_yy = weighted(dNdy, dNdy, d22) + weighted(dNdx, dNdx, shear)
    k_xy = weighted(dNdx, dNdy, d12) + weighted(dNdy, dNdx, shear)
    n = dNdx.shape[1]
    # interleave (x, y) per node
    order = np.empty(2 * n, dtype=np.int64)
    order[0::2] = np.arange(n)
    order[1::2] = np.arange(n) + n
    blocks = sp.bmat([[k_xx, k_xy], [k_xy.T, k_yy]], format="csr")
    return blocks[order][:, order].tocsr()


#: up to this many degrees of freedom the eigenvalue problem is dense and exact; above it ARPACK's,
#: whose solves with a consistent mass go through :class:`_ComponentSolve` (scipy's own SuperLU of
#: the interleaved ``kron(M, I2)``, in its default order, ran cubic splines at 1e6 points out of
#: 24 GB, and at 1e4 points took 1.7 of the estimate's 2.0 s against 0.6)
DENSE_LIMIT = 1500
#: ARPACK's relative residual for the largest eigenvalue.  The run takes ``time.safety`` (0.5)
#: of the step, so the estimate need not be exact: at 1e-3 the steps of the benchmark's blocks
#: (1e4 and 1e5 points, every basis, consistent and lumped) are within 2e-4 of 1e-4's, and
#: within 9e-4 of dense solves' on blocks off the node lines (the general product of
#: :func:`largest_eigenvalue_of_product` can err either way; the symmetric problem of
#: :func:`largest_frequency_squared` gives a value below the eigenvalue); the products a
#: solve takes fall most where they are dear: cubic splines at 1e5 points, consistent mass
#: (weak nodes lumped: the general product, two solves a product), 15.0 -> 3.7 s
ARPACK_TOLERANCE = 1e-3


def arpack_start(n: int) -> np.ndarray:
    """ARPACK's first vector, the same at every call: left to itself, ARPACK draws it from a
    generator whose state carries over from call to call in a process, so the critical step of
    one scene differed in its 11th digit from one Simulation to the next (cubic splines,
    consistent mass, 3,154 degrees of freedom), and a resumed run refused its checkpoint."""
    return np.random.default_rng(0).standard_normal(n)


def largest_frequency_squared(stiffness: sp.csr_matrix, mass: sp.spmatrix, solve=None) -> float:
    """Largest ``omega^2`` of ``K u = omega^2 M u`` (M symmetric positive definite);
    ``solve``: ``M^-1`` as a linear operator, for a problem above :data:`DENSE_LIMIT`."""
    n = stiffness.shape[0]
    if n == 0:
        return 0.0
    if n <= DENSE_LIMIT:  # small problems: dense and exact
        import scipy.linalg as sla

        return float(sla.eigh(stiffness.toarray(), mass.toarray(), eigvals_only=True, subset_by_index=[n - 1, n - 1])[0])
    value = spla.eigsh(stiffness, k=1, M=mass.tocsc(), Minv=solve, which="LA", tol=ARPACK_TOLERANCE, v0=arpack_start(n),
                       return_eigenvectors=False)
    return float(value[0])


class _ComponentSolve(spla.LinearOperator):
    """``kron(M, I2)[free][:, free]^-1`` by SuperLU factors of each component's block of the
    nodal ``M`` in minimum-degree order (one when the components are free alike)."""

    def __init__(self, nodal: sp.csr_matrix, free: np.ndarray):
        free = free.reshape(-1, 2)
        reduced = np.cumsum(free.ravel()).reshape(-1, 2) - 1  # each free dof's place in the reduced vector
        self.parts = []
        for c in (0, 1):
            nodes = np.flatnonzero(free[:, c])
            if nodes.size == 0:  # the component held everywhere
                continue
            if c == 1 and np.array_equal(free[:, 0], free[:, 1]):
                factors = self.parts[0][1]
            else:
                factors = symmetric_lu(nodal[nodes][:, nodes])
            self.parts.append((reduced[nodes, c], factors))
        n = int(free.sum())
        super().__init__(float, (n, n))

    def _matvec(self, vector):
        vector = np.asarray(vector, dtype=float).ravel()
        out = np.empty_like(vector)
        if len(self.parts) == 2 and self.parts[0][1] is self.parts[1][1]:
            # one solve of two columns, in 0.6-0.8 of the time of two of one (SuperLU's sweeps
            # read the factors once for both); the same numbers with this machine's OpenBLAS
            # (a BLAS whose one-column products take another path could differ in the last bit)
            (first, factors), (second, _) = self.parts
            both = factors.solve(np.column_stack([vector[first], vector[second]]))
            out[first], out[second] = both[:, 0], both[:, 1]
            return out
        for places, factors in self.parts:
            out[places] = factors.solve(vector[places])
        return out


def largest_eigenvalue_of_product(inverse_mass, stiffness: sp.csr_matrix, symmetric: bool = False) -> float:
    """Largest modulus of the eigenvalues of ``B K``.

    For symmetric positive semi-definite B and K the eigenvalues are real
    and non-negative (the product is similar to ``K^1/2 B K^1/2``), so this
    is the largest.  A B that is not symmetric (velocity and acceleration
    divided by different masses) can have complex ones; their modulus is
    what bounds the step.  ``symmetric``: B is symmetric up to round-off (the
    caller knows it from its form), which small problems use.
    """
    n = stiffness.shape[0]
    if n == 0:
        return 0.0
    if n <= DENSE_LIMIT:
        dense = inverse_mass.toarray()
        if symmetric:
            largest = _largest_symmetric_eigenvalue(dense, stiffness)
            if largest is not None:
                return largest
        return float(np.max(np.abs(np.linalg.eigvals(dense @ stiffness.toarray()))))
    operator = spla.LinearOperator((n, n), matvec=lambda x: inverse_mass @ (stiffness @ x), dtype=float)
    return float(np.max(np.abs(spla.eigs(operator, k=1, which="LM", tol=ARPACK_TOLERANCE, v0=arpack_start(n),
                                         return_eigenvectors=False))))


def _largest_symmetric_eigenvalue(inverse_mass: np.ndarray, stiffness: sp.csr_matrix) -> float | None:
    """Largest eigenvalue of ``B K`` as that of ``L^T K L`` (``B = L L^T``, its Cholesky factor),
    a symmetric problem: a fifth of the general one's time (578 unknowns: 21 against 100 ms),
    the same value to 6e-15.  None where B has no such factor (a mode of the grid without mass;
    a B singular only to round-off may factor, and then gives the same value: serendipity with
    HRZ, 3 points a cell, 1.7e-15), or where anything is not finite: the general problem answers."""
    import scipy.linalg as sla
    from scipy.linalg import blas

    try:
        factor = sla.cholesky(0.5 * (inverse_mass + inverse_mass.T), lower=True, check_finite=False)
        reduced = blas.dtrmm(1.0, factor, stiffness @ factor, side=0, lower=1, trans_a=1)  # L^T (K L)
        if not np.isfinite(reduced).all():
            return None
        n = reduced.shape[0]
        return float(sla.eigh(0.5 * (reduced + reduced.T), eigvals_only=True, subset_by_index=[n - 1, n - 1],
                              overwrite_a=True, check_finite=False)[0])
    except np.linalg.LinAlgError:
        return None


def critical_time_step(simulation) -> float:
    """``2 / omega_max`` (s) for the simulation's points, grid, supports and mass model (as it
    will be assembled, weak nodes lumped), or the scheme's ``stability_limit / omega_max``
    (:mod:`femgrid_mpm.schemes`); 0 if no step is stable.

    Lumped mass with FLIP: the grid velocity is projected afresh from the
    points every step, ``v <- M_L^-1 N^T m (v_p + dt N a)``, so an increment
    ``a = M_L^-1 f`` reaches the grid as ``M_L^-1 M_C M_L^-1 f``: that, not
    ``M_L^-1``, is the inverse mass of the iteration (measured: the plain
    ``M_L^-1 K`` estimate is 1.3 to 1.6 times too small).  It is positive
    semi-definite even where lumped masses are negative, which is why the
    serendipity element with row-sum lumping, whose corner masses are
    negative, runs at all (the paper's "self-restoration").  Consistent mass:
    ``M_C^-1 M_C M_C^-1 = M_C^-1``, the textbook case; with its weak rows treated or
    mixed (:mod:`femgrid_mpm.mass.weak_rows`) it is ``M^-1 M_C M^-1``.

    The same holds for any diagonal mass with its own transfer weights W
    (HRZ, :class:`femgrid_mpm.mass.HrzMass`): ``M^-1 W^T diag(m) W M^-1``,
    and for the mass threshold, whose diagonal holds absolute masses at the
    nodes below it.  (A mass model whose velocity and acceleration divided
    by different diagonals would give ``D_v^-1 M_C D_a^-1``, not symmetric:
    :class:`~femgrid_mpm.mass.Inertia` holds both.)  The estimate assembles a mass
    model of its own (:meth:`femgrid_mpm.solver.Simulation.mass_model`), so it may be
    asked for at any time without touching the run's.

    With one field per body (frictional contact) each body moves with its own
    field's masses, so the step is the smallest of the bodies' own.
    """
    grid, p, mass_model = simulation.grid, simulation.particles, simulation.mass_model()
    N, dNdx, dNdy = grid.shape_functions(p.x)
    moduli = np.empty((p.n, 4))
    for material, members in zip(simulation.materials, simulation.body_slices):
        lam, mu = material.lame_lambda, material.shear_modulus
        moduli[members] = [lam + 2 * mu, lam, lam + 2 * mu, mu]
    if simulation.scene.solver.mass_quadrature == "reconstructed":  # the mass the run assembles
        rows, masses, volumes, _ = MassReconstruction.of_scene(grid, simulation.scene).rows(
            p.x, p.volume, p.mass, p.body, np.zeros((p.n, 1)), lambda summed: N[summed])
        mass_model.assemble(rows, masses, volumes)
    else:
        mass_model.assemble(N, p.mass, p.volume)
    volume = p.volume
    if simulation.scene.solver.force_quadrature == "reconstructed":  # its Gauss points where it integrates
        dNdx, dNdy, volume, moduli = StressReconstruction.of_scene(grid, simulation.scene).integration_rows(
            p.x, p.volume, p.body, dNdx, dNdy, moduli)
    omega_squared = 0.0
    try:
        for members, active, inertia in mass_model.field_inertias(N):
            free = np.repeat(active, 2)
            if simulation.fixed is not None:
                free &= ~simulation.fixed.ravel()
            whole = members == slice(None)
            stiffness = stiffness_matrix(dNdx if whole else dNdx[members], dNdy if whole else dNdy[members],
                                         volume[members], moduli[members])[free][:, free]
            omega_squared = max(omega_squared, _largest_frequency_squared(inertia, p.mass[members], free, stiffness))
    except (np.linalg.LinAlgError, spla.ArpackError, RuntimeError):
        return 0.0  # a singular consistent mass: some mode has no inertia
    limit = SCHEMES[simulation.scene.solver.scheme].stability_limit  # 2: the central difference
    # a largest omega^2 far below the stiffest deformable body's scale (c_p / h)^2 is the round-off of
    # a zero: the grid cannot deform a body of one point (its grid velocity, projected afresh, is
    # uniform), whose estimate was 4.8e11 s at c_p = 3.7 m/s, h = 1 m.  A body of one point sets no
    # floor beside bodies of more (a stiff one refused a soft body's real step), but with bodies of one
    # point alone the stiffest does (the softest's let the stiff point's round-off, ~1e-16 of its
    # scale, through as a step of 889 s)
    sizes = [len(range(p.n)[members]) for members in simulation.body_slices]
    deformable = [m for m, size in zip(simulation.materials, sizes) if size > 1] or list(simulation.materials)
    with np.errstate(over="ignore"):  # a scale beyond floating point (moduli of 1e300) tests nothing
        floor = 1e-12 * max(np.float64(m.lame_lambda + 2.0 * m.shear_modulus) / m.density
                            for m in deformable) / grid.spacing**2
    floor = floor if math.isfinite(floor) else 0.0
    return limit / math.sqrt(omega_squared) if omega_squared > floor else math.inf


def _largest_frequency_squared(inertia, point_mass: np.ndarray, free: np.ndarray, stiffness: sp.csr_matrix) -> float:
    """``omega_max^2`` of one field's iteration (see :func:`critical_time_step`)."""
    if inertia.matrix is None:  # diagonal: row sums (and the threshold's), HRZ, or per body
        velocity_inverse, acceleration_inverse = (sp.diags(inverse) for inverse in inertia.inverses)
        transfer = inertia.transfer
        consistent = (transfer.T @ transfer.multiply(point_mass[:, None]).tocsr()).tocsr()
        effective = velocity_inverse @ consistent @ acceleration_inverse
        effective = sp.kron(effective, sp.identity(2), format="csr")[free][:, free]
        # one diagonal for velocity and acceleration (every model but one that divides them by
        # different masses): B = D^-1 C D^-1 is symmetric
        return largest_eigenvalue_of_product(effective, stiffness, symmetric=np.array_equal(*inertia.inverses))
    mass = sp.kron(inertia.matrix, sp.identity(2), format="csr")[free][:, free]
    if inertia.corrections:  # solved by k Jacobi corrections of the lumped solution (.mass.iterated)
        consistent = mass if inertia.consistent is None else \
            sp.kron(inertia.consistent, sp.identity(2), format="csr")[free][:, free]
        sandwich = _CorrectedSandwich(mass, consistent, np.repeat(inertia.row_sums, 2)[free], inertia.corrections)
        return largest_eigenvalue_of_product(sandwich, stiffness, symmetric=True)
    if inertia.consistent is None:
        solve = _ComponentSolve(inertia.matrix, free) if mass.shape[0] > DENSE_LIMIT else None
        return largest_frequency_squared(stiffness, mass, solve)
    # a mass M other than N.T diag(m) N (weak rows lumped, a mixed mass): the grid velocity is
    # projected afresh from the points, v <- M^-1 N.T m (v_p + dt N a), so the increment
    # a = M^-1 f reaches the grid as M^-1 M_C M^-1 f
    consistent = sp.kron(inertia.consistent, sp.identity(2), format="csr")[free][:, free]
    sandwich = _InverseSandwich(mass, consistent, inertia.matrix, free)
    return largest_eigenvalue_of_product(sandwich, stiffness, symmetric=True)


class _InverseSandwich:
    """``M^-1 C M^-1`` (M symmetric positive definite), applied through M's factors, and
    made dense for the small problems of :func:`largest_eigenvalue_of_product`; above
    :data:`DENSE_LIMIT` M's factors are each component's of the nodal ``M`` (``nodal``, ``free``)."""

    def __init__(self, mass: sp.csr_matrix, consistent: sp.csr_matrix, nodal: sp.csr_matrix, free: np.ndarray):
        self.shape, self._consistent = mass.shape, consistent
        # M^-1 of a vector (and, small, of the identity for toarray)
        self._solve = spla.splu(mass.tocsc()).solve if mass.shape[0] <= DENSE_LIMIT else _ComponentSolve(nodal, free).matvec

    def __matmul__(self, vector: np.ndarray) -> np.ndarray:
        return self._solve(self._consistent @ self._solve(vector))

    def toarray(self) -> np.ndarray:
        inverse = self._solve(np.eye(self.shape[0]))
        return inverse @ self._consistent.toarray() @ inverse


class _CorrectedSandwich:
    """``A_k C A_k``, ``A_k`` the inverse of M by k Jacobi corrections of the lumped solution
    over the row sums (:func:`femgrid_mpm.mass.iterated.corrected_inverse`), on the free
    degrees of freedom; made dense for the small problems of :func:`largest_eigenvalue_of_product`."""

    def __init__(self, mass: sp.csr_matrix, consistent: sp.csr_matrix, row_sums: np.ndarray, corrections: int):
        self.shape, self._mass, self._consistent, self._corrections = mass.shape, mass, consistent, corrections
        positive = row_sums > 0
        self._inverse_rows = np.where(positive, 1.0 / np.where(positive, row_sums, 1.0), 0.0)

    def _corrected(self, columns: np.ndarray) -> np.ndarray:
        return corrected_inverse(self._mass.__matmul__, columns, self._inverse_rows[:, None], self._corrections)

    def __matmul__(self, vector: np.ndarray) -> np.ndarray:
        columns = vector.reshape(len(vector), -1)
        return self._corrected(self._consistent @ self._corrected(columns)).reshape(vector.shape)

    def toarray(self) -> np.ndarray:
        return self @ np.eye(self.shape[0])
