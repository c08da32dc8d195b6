"""Grid mass: lumped (paper Eqs. 15-16), HRZ and consistent (Eqs. 10, 17, 19, 20).

The models share one interface: ``assemble(N, m_p)`` once per step, then
``solve(rhs)`` for the nodal velocities (rhs = momentum, Eq. 17) and for the
nodal accelerations (rhs = force, Eq. 10).  Nodes that no point touches are
*inactive*: their solution is zero.  ``lumped`` (the row sums, Eq. 15) is
always available for diagnostics.  What a model needs from the compiled
P2G it says with ``assemble_sums`` (the sums; ``needs_volume`` adds
``N.T @ V_p``), ``assemble_pattern`` (the consistent matrix) or
``needs_matrices`` (N itself); a model with its own transfer weights
exposes them as ``weights`` (:class:`HrzMass`, whose sums the compiled P2G
also makes: ``assemble_hrz``).

Negative and tiny lumped masses (q2, serendipity) have two remedies here:
the threshold of :class:`LumpedMass` (the absolute mass below a fraction of
a node's full share) and :class:`HrzMass` (a positive diagonal for every
basis, with transfers to match); the README's "Hard cases" has what they
measure.

Consistent mass and its singularities
-------------------------------------
``M = N.T @ diag(m_p) @ N`` is positive semi-definite.  It is singular when
a node's function is seen by too few points to fix its value, e.g. a node
touched only by the far edge of a body, or, globally, a body with fewer
points across than basis functions span it (cubic B-splines with 2 points
per cell in a body 2 cells thick).  Momentum always lies in the range of
``M`` (so velocities *at the points* are right), but internal forces in
general do not, and velocity *gradients* there are arbitrary.  We treat it
in three layers:

1. *Empty nodes* (``M_ii = 0``) are removed: identity rows, zero solution.
2. *Weak nodes* of non-negative bases (q1, bspline3), whose material volume
   fraction ``(N.T @ V_p)_i / integral(phi_i)`` is below ``weak_fraction``,
   are lumped: each coupling ``M_ij`` to a weak node is moved onto both
   diagonals.  This keeps every row sum (so rigid motion and momentum stay
   exact) and only adds positive semi-definite terms, so it never makes the
   matrix less definite.
3. What remains singular is *detected*: a SuperLU pivot falls below
   ``1e-8`` of its own diagonal entry (the node's function is reproduced by
   the others), or preconditioned CG fails to converge on the force system.  The ``fallback`` policy decides:
   ``"error"`` raises :class:`SingularMassError`; ``"blend"`` solves with
   ``(1 - blend) M + blend * diag(lumped)`` for that step, counts the event
   and goes on (where row sums are not all positive, q2 and serendipity,
   the HRZ diagonal, ``M_ii`` scaled to the total mass, replaces them).

Linear solver: ``"direct"`` factors the matrix once per step with SuperLU
(both solves of the step reuse the factors) and checks every solution's
residual, because SuperLU returns garbage without warning on a singular
matrix.  ``"cg"`` is preconditioned CG (Jacobi; for cubic splines a tensor
Gram preconditioner completed by an exact solve in a layer along the
bodies' edges, :class:`BoundaryLayer`), warm-started from the last step.
``"auto"`` takes direct up to 5000 active nodes (exact, and its pivots
detect a singular matrix; the paper's problems), and CG above.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .kernels.arithmetic import fused
from .kernels.compiled import compiled

#: largest number of active nodes for which "auto" factors the matrix
DIRECT_LIMIT = 5000


class SingularMassError(RuntimeError):
    """The consistent mass matrix could not be solved (singular or nearly).

    ``node``: where it is weakest, if known (the node of SuperLU's smallest
    pivot against its diagonal entry, or of CG's largest residual)."""

    def __init__(self, message: str, node: int | None = None):
        super().__init__(message)
        self.node = node


@dataclass
class LumpedMass:
    """Row-sum (lumped) nodal masses, Eq. 15; the solve is a division, Eq. 16.

    Parameters
    ----------
    n_nodes : int
    reference_mass : float
        Mass of one full lattice cell (kg); masses with ``|m_i|`` below
        ``1e-12 * reference_mass`` count as empty.
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
    reference_mass: float
    threshold: float | None = None
    node_integrals: np.ndarray | None = field(default=None, repr=False)
    kind = "lumped"
    lumped: np.ndarray = field(init=False, repr=False)
    active: np.ndarray = field(init=False, repr=False)
    #: nodes below the threshold at the last assembly
    nodes_below_threshold: int = field(default=0, init=False)
    #: the smallest of ``lumped`` when the compiled sums were assembled, else None
    smallest: float | None = field(default=None, init=False, repr=False)

    def __post_init__(self):
        if self.threshold is not None:
            if self.node_integrals is None or not np.all(self.node_integrals > 0):
                raise ValueError(
                    "the mass threshold needs a positive full share integral(phi_i) at every node; "
                    "serendipity's corner functions integrate to -1/12 of each element, so no relative "
                    "threshold applies (use solver.mass = 'hrz')"
                )

    @property
    def needs_volume(self) -> bool:
        """Whether :meth:`assemble_sums` wants ``N.T @ V_p`` (the threshold does)."""
        return self.threshold is not None

    def assemble(self, N: sp.csr_matrix, m_p: np.ndarray, volume_p: np.ndarray | None = None) -> None:
        self.lumped = N.T @ m_p
        self.smallest = None
        absolute = _absolute_mass(N, m_p, self.lumped)
        self.active = (np.abs(self.lumped) > 1e-6 * absolute) & (absolute > 1e-12 * self.reference_mass)
        self._inverse = np.divide(1.0, self.lumped, out=np.zeros(self.n_nodes), where=self.active)
        self._replace(absolute, None if volume_p is None or self.threshold is None else N.T @ volume_p)

    def assemble_sums(self, lumped: np.ndarray, absolute: np.ndarray | None, volume: np.ndarray | None = None) -> None:
        """The same from sums the compiled P2G made: ``N.T @ m_p``, (signed
        bases) ``|N|.T @ m_p`` and (threshold) ``N.T @ V_p``.  The arrays are
        kept, not copied."""
        if getattr(self, "_inverse", None) is None or len(self._inverse) != len(lumped):
            self._inverse = np.zeros(len(lumped))
            self.active = np.zeros(len(lumped), dtype=bool)
        self.lumped = lumped
        absolute = lumped if absolute is None else absolute
        self.smallest = _lumped_inverse(lumped, absolute, self.reference_mass, self._inverse, self.active)
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
        below = (absolute > 1e-12 * self.reference_mass) & (volume < self.threshold * self.node_integrals)
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
class HrzMass:
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
    :meth:`femgrid_mpm.effects.base.StepContext.add_point_forces`) and the
    G2P velocity increment ``v_p += dt W @ a``.  Gradients (strain rate,
    internal force) and positions keep the basis's own ``N``: the material
    still deforms with the element's interpolation.  Then momentum is exact
    (``sum_i m_i a_i = sum_i f_i``), internal forces do no net work on
    rigid motion, and free fall is exact.

    ``lumped`` keeps the row sums ``N.T @ m_p`` for the negative-mass
    record; ``diagonal`` is the mass used.
    """

    n_nodes: int
    reference_mass: float
    kind = "hrz"
    #: W as a matrix: set by :meth:`assemble`; after :meth:`assemble_hrz` built
    #: from N when first asked for (:meth:`weights_for`: only effects that
    #: move point forces to the grid need it)
    weights: sp.csr_matrix | None = field(default=None, init=False, repr=False)

    def assemble(self, N: sp.csr_matrix, m_p: np.ndarray, volume_p: np.ndarray | None = None) -> None:
        self.weights = positive_weights(N)
        self.assemble_hrz(N.T @ m_p, self.weights.T @ m_p)

    def assemble_hrz(self, lumped: np.ndarray, diagonal: np.ndarray) -> None:
        """The same from the sums the compiled P2G made: the row sums ``N.T @ m_p``
        and the diagonal ``W.T @ m_p`` (kept, not copied); ``weights`` then waits
        for :meth:`weights_for`."""
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

    def forget_weights(self) -> None:
        """The points moved: the next request rebuilds ``W``."""
        self.weights = None

    def solve(self, rhs: np.ndarray, kind: str = "velocity") -> np.ndarray:
        """``rhs / m_i`` on active nodes, zero elsewhere."""
        return rhs * self._inverse[:, None]

    def inverses(self) -> tuple[np.ndarray, np.ndarray]:
        """The diagonal inverses ``(velocity, acceleration)`` (equal)."""
        return self._inverse, self._inverse

    def grid_velocity(self, relative_momentum: np.ndarray, frame_velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 17 with the HRZ mass, in the frame of ``frame_velocity``."""
        momentum, velocity = np.empty_like(relative_momentum), np.empty_like(relative_momentum)
        _lumped_velocity(relative_momentum, self._inverse, self.diagonal, frame_velocity, momentum, velocity)
        return momentum, velocity

    def apply(self, vector: np.ndarray) -> np.ndarray:
        """``M @ vector`` with the HRZ diagonal."""
        return vector * self.diagonal[:, None]


@dataclass
class ConsistentMass:
    """Consistent mass ``N.T diag(m_p) N``, solved directly or by CG.

    Parameters
    ----------
    n_nodes : int
    reference_mass : float
        Mass of one full lattice cell (kg), the scale for "empty".
    node_integrals : ndarray, shape (n_nodes,)
        ``integral(phi_i)`` over the grid (m^2), for the weak-node test.
    nonnegative : bool
        Whether the basis is non-negative (weak-node lumping applies).
    weak_fraction : float
        Volume fraction below which a node is weak.
    tolerance : float
        Relative residual at which CG stops.
    linear_solver : {"auto", "direct", "cg"}
    fallback : {"error", "blend"}
        What to do when the matrix is found singular.
    blend : float
        Weight of the lumped mass in the fallback.
    """

    n_nodes: int
    reference_mass: float
    node_integrals: np.ndarray = field(repr=False)
    nonnegative: bool = True
    weak_fraction: float = 0.01
    tolerance: float = 1e-6
    linear_solver: str = "auto"
    fallback: str = "error"
    blend: float = 0.1
    #: (n_nodes, 2) bool, degrees of freedom held at zero by supports; set by
    #: the simulation.  A coupled matrix must leave them out of the solve
    #: (zeroing them afterwards, exact for a diagonal mass, is wrong here).
    fixed: np.ndarray | None = field(default=None, repr=False)
    #: CG's preconditioner for cubic B-splines (see :func:`tensor_preconditioner`);
    #: None: Jacobi
    preconditioner: "TensorPreconditioner | None" = field(default=None, repr=False)
    #: (n_nodes, 2) int, each node's place on the lattice (x and y index), and the width
    #: of an element in lattice spacings: where CG looks for a singular block (signed bases)
    lattice: np.ndarray | None = field(default=None, repr=False)
    layer_width: int = 2
    #: the time step (s), set by the simulation: CG's first guess of the velocity
    #: is the last step's grid velocity advanced by its acceleration
    time_step: float | None = None
    kind = "consistent"
    iterations: int = 0
    weak_nodes: int = 0
    blended_steps: int = 0

    def __post_init__(self):
        self._previous: dict[str, tuple] = {}
        self._frame = None  # the frame of the velocity being solved for (set by grid_velocity)
        # the assembled M (or, made into the solve's system in place, that system R and the
        # entries it overwrote), and M rebuilt from them on demand (:attr:`matrix`)
        self._assembled, self._correction, self._full = None, None, None
        self.max_iterations = int(200 + 20 * np.sqrt(self.n_nodes))

    def state(self) -> tuple[dict, dict]:
        """What carries from step to step, ``(arrays, values)``: CG's warm-start
        history (the last two solutions of each kind) and the counters."""
        arrays = {f"previous.{kind}.{index}": solution
                  for kind, history in self._previous.items() for index, solution in enumerate(history)}
        values = {"iterations": self.iterations, "weak_nodes": self.weak_nodes, "blended_steps": self.blended_steps,
                  "previous": {kind: len(history) for kind, history in self._previous.items()}}
        return arrays, values

    def restore(self, arrays: dict, values: dict) -> None:
        """Take back :meth:`state`."""
        self.iterations, self.weak_nodes = int(values["iterations"]), int(values["weak_nodes"])
        self.blended_steps = int(values["blended_steps"])
        self._previous = {kind: tuple(np.array(arrays[f"previous.{kind}.{index}"]) for index in range(count))
                          for kind, count in values["previous"].items()}

    def assemble(self, N: sp.csr_matrix, m_p: np.ndarray, volume_p: np.ndarray | None = None) -> None:
        weighted = N.multiply(m_p[:, None]).tocsr()
        matrix = (N.T @ weighted).tocsr()
        self.lumped = N.T @ m_p
        self._prepare(matrix, None if volume_p is None else N.T @ volume_p)

    def assemble_pattern(self, pattern, lumped: np.ndarray, node_volume: np.ndarray) -> None:
        """The same from the compiled P2G, which added ``m_p N_a N_b`` into ``pattern``
        (:class:`femgrid_mpm.kernels.pattern.MassPattern`, a structure fixed per
        grid with every diagonal entry), ``N.T @ m_p`` and ``N.T @ V_p``.  The
        weak-node lumping and the systems keep that structure (no SpGEMM)."""
        self.lumped = lumped
        matrix = _CompiledCSR(pattern.matrix())
        matrix.upper_start = pattern.diagonal  # symmetric bit for bit, in stencil order
        self._prepare(matrix, node_volume, pattern.diagonal)

    def _prepare(self, matrix: sp.csr_matrix, node_volume: np.ndarray | None, diagonal_index=None) -> None:
        diagonal = matrix.diagonal() if diagonal_index is None else matrix.data[diagonal_index]
        self.active = diagonal > 1e-24 * self.reference_mass
        self._weak = np.zeros(self.n_nodes, dtype=bool)
        if self.nonnegative and node_volume is not None:
            fraction = np.divide(node_volume, self.node_integrals, out=np.ones(self.n_nodes), where=self.active)
            weak = self.active & (fraction < self.weak_fraction)
            self.weak_nodes = int(weak.sum())
            self._weak = weak
            if self.weak_nodes:
                if diagonal_index is None:
                    matrix = _lump_couplings(matrix, weak)
                else:  # in place, keeping the structure
                    _lump_couplings_in_place(matrix.indptr, matrix.indices, matrix.data, diagonal_index, weak)
        self._assembled, self._correction, self._full = matrix, None, None
        # empty and fixed degrees of freedom leave the system (identity rows);
        # one system for both components when they are fixed alike
        excluded = ~self.active[:, None] if self.fixed is None else (~self.active[:, None] | self.fixed)
        excluded = np.broadcast_to(excluded, (self.n_nodes, 2))
        groups = [(0, 1)] if np.array_equal(excluded[:, 0], excluded[:, 1]) else [(0,), (1,)]
        self._direct = self.linear_solver == "direct" or (
            self.linear_solver == "auto" and np.count_nonzero(self.active) <= DIRECT_LIMIT
        )
        if diagonal_index is not None and len(groups) == 1:
            # the one system is made from the assembled matrix in place (a copy of its data was
            # ~25 ns per point-step for cubic splines at 1e5 points); M is R with the entries the
            # exclusion overwrote put back
            self._correction = _exclude_in_place(matrix.indptr, matrix.indices, matrix.data, diagonal_index,
                                                 excluded[:, 0])
            self._systems = [_System.build(matrix, [0, 1], excluded[:, 0], self._direct, diagonal_index,
                                           in_place=True)]
        else:
            self._systems = [_System.build(matrix, list(columns), excluded[:, columns[0]], self._direct,
                                           diagonal_index) for columns in groups]

    @property
    def matrix(self) -> sp.csr_matrix:
        """``M`` (n_nodes, n_nodes), after the weak-node lumping.  Where the solve's system
        was made from it in place, it is rebuilt on first use in the step (same structure)."""
        if self._correction is None:
            return self._assembled
        if self._full is None:
            positions, _, old = self._correction
            data = self._assembled.data.copy()
            data[positions] = old  # the entries themselves, not a difference: exact at any scale
            # its own index arrays: scipy sorts indices in place (e.g. in abs()), which must not
            # scramble the system's
            self._full = _CompiledCSR((data, self._assembled.indices.copy(), self._assembled.indptr.copy()),
                                      shape=self._assembled.shape, copy=False)
            self._full.upper_start = self._assembled.upper_start
        return self._full

    def grid_velocity(self, relative_momentum: np.ndarray, frame_velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 17 in the frame moving with ``frame_velocity``: ``(p, v)``, the momentum
        ``p_rel + m v_ref`` and the velocity ``M^-1 p_rel + v_ref``."""
        momentum = relative_momentum + self.lumped[:, None] * frame_velocity
        self._frame = np.asarray(frame_velocity, dtype=float)
        velocity = self.solve(relative_momentum, "velocity", frame=self._frame) + frame_velocity
        if not self._direct:  # the frame of the velocities in the history, for the next guess
            self._previous["frame"] = (self._frame.reshape(1, 2).copy(),)
        return momentum, velocity

    def apply(self, vector: np.ndarray) -> np.ndarray:
        """``M @ vector`` with the consistent matrix (empty rows zero)."""
        if self._correction is None:
            return self._assembled @ vector
        positions, rows, old = self._correction  # from R @ vector and what the exclusion overwrote
        columns_of = np.ascontiguousarray(np.reshape(vector, (vector.shape[0], -1)), dtype=float)
        product = _unexcluded_product(np.reshape(self._assembled @ columns_of, columns_of.shape),
                                      self._systems[0].excluded, self._assembled.indices, positions, rows, old,
                                      columns_of)
        return product.reshape(vector.shape)

    def solve(self, rhs: np.ndarray, kind: str = "velocity", frame: np.ndarray | None = None) -> np.ndarray:
        """Solve ``M x = rhs`` for the two columns of rhs (n_nodes, 2) on the free
        degrees of freedom; the solution is zero on the fixed and empty ones.

        ``kind`` ("velocity" or "acceleration") keys CG's warm start: the
        last two solutions of the same kind are extrapolated.

        ``frame`` (2,), optional: rhs is a momentum relative to this velocity,
        ``p - L v_ref`` (L the row sums), and the solution is the velocity
        relative to it, equal to the absolute solve minus ``v_ref``.  Two
        terms make it so.  Supports hold the velocity at zero, which is
        ``-v_ref`` in the frame, so their couplings ``M_fc v_ref`` belong on
        the free rows' right-hand side: left out, the free velocities next to
        a support depended on one point's velocity, a feedback that made the
        cantilever with consistent open-knot splines grow exponentially from
        the clamp.  And a blend whose diagonal D is not the row sums (HRZ:
        q2, serendipity) has ``B 1 != L``, which adds ``blend (L - D) v_ref``.
        """
        solution = np.zeros_like(rhs)
        moving = frame is not None and bool(np.any(frame))
        coupling = None  # M_fc v_ref on the free rows
        if moving and self.fixed is not None:
            coupling = self.apply(np.where(self.fixed, frame, 0.0))
        for system in self._systems:
            part = np.where(system.excluded[:, None], 0.0, rhs[:, system.columns])
            coupled = None if coupling is None else np.where(system.excluded[:, None], 0.0, coupling[:, system.columns])
            if not part.any() and (coupled is None or not coupled.any()):  # e.g. the relative momentum of a rigid motion
                continue
            solution[:, system.columns] = self._solve_system(system, part, kind, coupled,
                                                             frame[system.columns] if moving else None)
        if not self._direct:
            self._previous[kind] = (*self._previous.get(kind, ())[-1:], solution)
        return solution

    def _solve_system(self, system: "_System", part: np.ndarray, kind: str, coupled: np.ndarray | None = None,
                      frame: np.ndarray | None = None) -> np.ndarray:
        """One system's solve, blended if it is singular and the fallback says so;
        ``coupled`` is ``M_fc v_ref`` on its free rows (blending scales it by
        ``1 - blend``: the blend's diagonal couples nothing), ``frame`` v_ref on
        its columns (see :meth:`solve`)."""
        def right_hand_side():
            total = part
            if coupled is not None:
                total = total + ((1.0 - self.blend) if system.blended else 1.0) * coupled
            if system.blended and frame is not None:
                excess = np.where(system.excluded, 0.0, self.lumped - self._blend_target())
                total = total + self.blend * excess[:, None] * frame[None, :]
            return total

        if self._singular_near_edges(system):  # CG would not see it (see the method)
            solution, converged = np.zeros_like(part), False
        else:
            solution, converged = self._solve(system, right_hand_side(), kind)
        if not converged:
            if self.fallback != "blend":
                how = ("the direct solve left a large residual" if self._direct else
                       "its block near the bodies' edges has a singular pivot" if system.singular else
                       "CG did not converge")
                raise SingularMassError(
                    f"the consistent mass matrix is singular or nearly so: {how} on the {kind} system "
                    f"(too few points per cell for the basis, or weakly supported nodes); use more points "
                    f"per cell, lumped mass, or solver.consistent_fallback = 'blend'",
                    self._weakest_node(system, right_hand_side(), solution))
            if not system.blended:
                self.blended_steps += 1
            system.blend_with(self._blend_target(), self.blend, self._direct)
            solution, converged = self._solve(system, right_hand_side(), kind)
            if not converged:
                raise SingularMassError(f"the blended mass matrix could not be solved either ({kind} system)",
                                        self._weakest_node(system, right_hand_side(), solution))
        return solution

    def _singular_near_edges(self, system: "_System") -> bool:
        """Whether CG's system is singular, decided as the direct solver decides, for a
        signed basis (q2, serendipity): by SuperLU's pivots (:data:`PIVOT_RATIO`) of its
        block on the kept nodes within one element of an empty node or of the grid's
        edge, once per step.

        CG alone does not see it.  A momentum ``N.T (m v)`` (and gravity's
        ``N.T (m g)``) lies in the range of ``M = N.T diag(m) N``, so CG solves
        such a system even where M is singular, and the solution keeps whatever
        its first guess held in M's null space: that moves no point but changes
        the velocity gradient.  Where q2 and serendipity elements were partly
        filled, CG's stresses differed from the direct solver's by O(1) after
        one step (it blended the acceleration solve only, when the force had a
        part in the null space).  A null vector vanishes on the nodes of every
        element whose points determine its polynomials, so it lives on partly
        filled elements, next to empty nodes or the grid's edge; and M being positive
        semi-definite, M is singular along a vector of the block exactly when
        the block is.  (A body too sparse everywhere, fewer points per element
        than functions, is singular in its interior: only the direct solver
        finds that.)  Non-negative bases lump their weakly supported nodes
        instead (:meth:`_prepare`) and are not checked.
        """
        if self._direct or self.nonnegative or system.blended or self.lattice is None:
            return False
        if system.singular is None:
            system.singular, system.weakest = False, None
            layer = _near_empty_nodes(self.lattice, ~self.active, self.layer_width) & ~system.excluded
            nodes = np.flatnonzero(layer)
            if nodes.size:
                pivots = _pivots(_rows_and_block(system.matrix, nodes)[1])
                if pivots is None:
                    system.singular = True
                elif np.min(pivots[1]) < PIVOT_RATIO:
                    system.singular, system.weakest = True, int(nodes[pivots[2][np.argmin(pivots[1])]])
        return system.singular

    def _weakest_node(self, system: "_System", rhs: np.ndarray, solution: np.ndarray) -> int | None:
        """Where a failed solve's matrix is weakest (for the stop's message): the node of the
        smallest pivot against its diagonal entry (direct, or CG's check near the edges), or
        of the largest residual (CG)."""
        if system.singular:
            return system.weakest
        if self._direct:
            return _smallest_pivot_node(system.matrix)
        residual = np.linalg.norm(rhs - system.matrix @ solution, axis=1)
        return int(np.argmax(residual)) if np.all(np.isfinite(residual)) else None

    def _solve(self, system: "_System", rhs: np.ndarray, kind: str) -> tuple[np.ndarray, bool]:
        if self._direct:
            return _direct_solve(system.factors, system.matrix, rhs)
        guess = self._initial_guess(rhs, kind, system)
        tensor = None if self.preconditioner is None else self.preconditioner.scaled(system)
        layer = None if tensor is None else system.boundary_layer(self.preconditioner.lattice_shape, self._weak)
        solution, converged, iterations = _preconditioned_cg(
            system.matrix, rhs, guess, system.inverse_diagonal, self.tolerance, self.max_iterations, tensor, layer
        )
        self.iterations += iterations
        if converged is None:
            # r.z < 0: the layer's factors were not accurate enough to keep the sweep
            # positive definite (it is whenever they are); the tensor preconditioner alone
            solution, converged, iterations = _preconditioned_cg(
                system.matrix, rhs, guess, system.inverse_diagonal, self.tolerance, self.max_iterations, tensor
            )
            self.iterations += iterations
        return solution, converged

    def _initial_guess(self, rhs: np.ndarray, kind: str, system: "_System") -> np.ndarray:
        """The velocity: the last step's grid velocity advanced by its acceleration,
        ``v + dt a`` (in this step's frame), which the points' own update makes
        exact while the points keep their places (at 1e5 points CG then takes
        2 iterations instead of ~11 for q1 and q2, 9 instead of ~12 for cubic
        splines, whose weakly supported nodes are lumped).  Otherwise linear extrapolation of
        the last two solutions where they exist; the lumped solution elsewhere
        (for a rigid motion that is already exact)."""
        history = self._previous.get(kind, ())
        accelerations = self._previous.get("acceleration", ())
        columns = np.asarray(system.columns, dtype=np.int64)
        none = np.zeros((0, 2))
        if (kind == "velocity" and history and accelerations and "frame" in self._previous and self.time_step
                and self._frame is not None):
            mode, first, second = GUESS_ADVANCED, history[-1], accelerations[-1]
            shift = (self._previous["frame"][0][0] - self._frame)[columns]
        elif len(history) == 2:
            (mode, first, second), shift = (GUESS_EXTRAPOLATED, history[1], history[0]), np.zeros(len(columns))
        elif len(history) == 1:
            (mode, first, second), shift = (GUESS_LAST, history[0], none), np.zeros(len(columns))
        else:
            (mode, first, second), shift = (GUESS_LUMPED, none, none), np.zeros(len(columns))
        return _guess(mode, rhs, self.lumped, 1e-12 * self.reference_mass, system.inverse_diagonal, first, second,
                      float(self.time_step or 0.0), shift, columns, system.excluded)

    def _blend_target(self) -> np.ndarray:
        """Positive diagonal to blend with: the lumped masses, or where row sums
        are not all positive (q2, serendipity) the HRZ diagonal, ``M_ii`` scaled
        to the total mass."""
        if np.all(self.lumped[self.active] > 0):
            return np.where(self.active, self.lumped, 1.0)
        diagonal = self.matrix.diagonal()
        scale = self.lumped[self.active].sum() / diagonal[self.active].sum()
        return np.where(self.active, scale * diagonal, 1.0)


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

    def boundary_layer(self, lattice_shape: tuple, weak: np.ndarray) -> "BoundaryLayer | None":
        """CG's boundary layer (:class:`BoundaryLayer`), built at the first solve of the
        step and shared by the velocity and acceleration solves."""
        if self._layer is False:
            self._layer = BoundaryLayer.build(self.matrix, self.excluded, weak, lattice_shape)
        return self._layer

    @classmethod
    def build(cls, matrix: sp.csr_matrix, columns: list, excluded: np.ndarray, direct: bool,
              diagonal_index: np.ndarray | None = None, in_place: bool = False) -> "_System":
        """``in_place``: ``matrix`` has already been reduced in place (its data is the system's)."""
        if diagonal_index is None:
            keep = sp.diags((~excluded).astype(float))
            reduced = (keep @ matrix @ keep + sp.diags(excluded.astype(float))).tocsr()
            inverse_diagonal = 1.0 / reduced.diagonal()
        else:  # the same on a structure with every diagonal entry: zero rows and columns, unit diagonal
            data = matrix.data
            if not in_place:  # on a copy: the other component's system needs the assembled entries too
                data = data.copy()
                _exclude_in_place(matrix.indptr, matrix.indices, data, diagonal_index, excluded)
            # the index arrays are shared with the (internal) assembled matrix: nothing sorts them
            reduced = _CompiledCSR((data, matrix.indices, matrix.indptr), shape=matrix.shape, copy=False)
            reduced.upper_start = diagonal_index  # exclusion and lumping keep the symmetry and the order
            inverse_diagonal = 1.0 / data[diagonal_index]
        return cls(columns, excluded, reduced, inverse_diagonal, _factor(reduced) if direct else None)

    def blend_with(self, target: np.ndarray, weight: float, direct: bool) -> None:
        """The fallback: ``(1 - weight) M + weight diag(target)`` on the kept rows."""
        if self.blended:
            return
        kept_target = np.where(self.excluded, 1.0, target)
        self.matrix = ((1.0 - weight) * self.matrix + weight * sp.diags(kept_target)).tocsr()
        self.inverse_diagonal = 1.0 / self.matrix.diagonal()
        self.factors = _factor(self.matrix) if direct else None
        self.blended = True
        self._layer = False


#: a pivot this small against its own diagonal entry means singular.
#: Measured: well-posed matrices >= 1e-4 (cubic splines at a clamp); the
#: rank-deficient case (cubic splines, 2 points per cell, a body 2 cells
#: thick) between 1e-17 and 2e-10 from step to step, so 1e-10 let a few
#: singular steps through and the run blew up.
PIVOT_RATIO = 1e-8


def _rows_and_block(matrix: sp.csr_matrix, nodes: np.ndarray) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """``M[nodes, :]`` and ``M[nodes][:, nodes]``, plain scipy matrices over ``matrix``'s arrays."""
    rows = sp.csr_matrix((matrix.data, matrix.indices, matrix.indptr), shape=matrix.shape)[nodes]
    return rows, rows[:, nodes]


def _near_empty_nodes(lattice: np.ndarray, empty: np.ndarray, width: int) -> np.ndarray:
    """(n_nodes,) bool: the nodes within ``width`` lattice steps (along x and y, and
    diagonally) of an ``empty`` one or of the grid's edge (a body there fills its
    elements partly too); ``lattice`` (n_nodes, 2) gives each node's indices.  CG's
    singularity check near the edges and its boundary layer (:class:`BoundaryLayer`)."""
    from scipy.ndimage import maximum_filter

    image = np.zeros(tuple(lattice.max(axis=0) + 1), dtype=bool)
    image[lattice[:, 0], lattice[:, 1]] = empty
    return maximum_filter(image, size=2 * width + 1, mode="constant", cval=True)[lattice[:, 0], lattice[:, 1]]


def _pivots(matrix: sp.csr_matrix):
    """SuperLU factors of a symmetric matrix and each pivot against its own diagonal
    entry with that pivot's node, ``(factors, ratios, nodes)``; None if SuperLU finds
    it exactly singular.

    SuperLU does not warn on a numerically singular matrix; its smallest
    pivot does tell (in symmetric mode the pivots are the diagonal of an
    LDL^T-like factorization, bounded below by the smallest eigenvalue):
    ~1 for an independent node of any mass, ~1e-16 for a node whose function
    the others reproduce.

    The matrices of the fixed mass pattern store every stencil entry, also
    the zeros left where empty, fixed or weak nodes were taken out; SuperLU
    orders and fills by the stored structure, so they are dropped from a
    copy first (cubic splines, cantilever 8 cells deep, 737 of 2025 nodes
    active: 2/3 of the entries zero, 85 -> 3.8 ms per factorization).
    """
    compact = sp.csc_matrix(matrix)  # a copy: the pattern's index arrays stay as they are
    compact.eliminate_zeros()
    try:
        factors = spla.splu(compact, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
    except RuntimeError:  # "Factor is exactly singular"
        return None
    nodes = np.empty_like(factors.perm_c)
    nodes[factors.perm_c] = np.arange(len(nodes))
    return factors, np.abs(factors.U.diagonal()) / matrix.diagonal()[nodes], nodes


def _factor(matrix: sp.csr_matrix):
    """SuperLU factors of a symmetric matrix, or None if it is singular (a pivot below
    :data:`PIVOT_RATIO` of its diagonal entry, see :func:`_pivots`)."""
    pivots = _pivots(matrix)
    if pivots is None or np.min(pivots[1]) < PIVOT_RATIO:
        return None
    return pivots[0]


def _smallest_pivot_node(matrix: sp.csr_matrix) -> int | None:
    """The node of the smallest pivot against its diagonal entry (see :func:`_pivots`),
    or None if SuperLU finds the matrix exactly singular."""
    pivots = _pivots(matrix)
    return None if pivots is None else int(pivots[2][np.argmin(pivots[1])])


def _direct_solve(factors, matrix: sp.csr_matrix, rhs: np.ndarray) -> tuple[np.ndarray, bool]:
    """Solve with the factors and check the backward error."""
    if factors is None:
        return np.zeros_like(rhs), False
    solution = factors.solve(rhs)
    residual = np.linalg.norm(matrix @ solution - rhs, axis=0)
    scale = np.linalg.norm(rhs, axis=0) + matrix.diagonal().max() * np.linalg.norm(solution, axis=0)
    converged = bool(np.all(np.isfinite(solution)) and np.all(residual <= 1e-10 * scale))
    return solution, converged


def _active(N: sp.csr_matrix, m_p: np.ndarray, lumped: np.ndarray, reference_mass: float) -> np.ndarray:
    """Nodes whose lumped mass can be divided by.

    Empty nodes are not.  With negative shape functions (q2, serendipity) a
    node's mass can also pass through zero by cancellation while points
    still touch it; there ``p_i / m_i`` is round-off over round-off, so a
    node whose mass is below 1e-6 of its absolute mass ``sum m_p |N_ip|``
    is not active either (its solution is zero, as for empty nodes).
    """
    absolute = _absolute_mass(N, m_p, lumped)
    return (np.abs(lumped) > 1e-6 * absolute) & (absolute > 1e-12 * reference_mass)


def _absolute_mass(N: sp.csr_matrix, m_p: np.ndarray, lumped: np.ndarray) -> np.ndarray:
    """``|N|.T @ m_p``: the lumped mass itself for non-negative bases."""
    if N.data.min(initial=0.0) >= 0.0:
        return lumped
    # a matrix of |N| on N's index arrays, for a transposed product only
    return sp.csr_matrix((np.abs(N.data), N.indices, N.indptr), shape=N.shape).T @ m_p


@compiled()
def _lumped_inverse(lumped, absolute, reference_mass, inverse, active):
    """:func:`_active` and ``1 / m_i`` on the active nodes, from the sums; returns the
    smallest ``m_i`` (for the negative-mass check, which would otherwise pass over them again)."""
    smallest = np.inf
    for i in range(len(lumped)):
        active[i] = abs(lumped[i]) > 1e-6 * absolute[i] and absolute[i] > 1e-12 * reference_mass
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


#: CG's first guess (:meth:`ConsistentMass._initial_guess`): the lumped solution; the last
#: solution; two solutions extrapolated; the last velocity advanced by its acceleration
GUESS_LUMPED, GUESS_LAST, GUESS_EXTRAPOLATED, GUESS_ADVANCED = range(4)


@compiled()
def _guess(mode, rhs, lumped, tiny, inverse_diagonal, first, second, dt, shift, columns, excluded):
    """CG's first guess on the system's columns (one pass; numpy's where-chains took ~0.5 ms
    a solve at 27,000 nodes).  ``first``/``second``: the last and the older solution
    (extrapolated), the last velocity and acceleration (advanced), as (n_nodes, 2) arrays
    of all columns.  A node takes the history's value where the history knows it
    (nonzero), the lumped solution ``rhs / m_i`` elsewhere, zero where excluded."""
    n, k = rhs.shape
    guess = np.empty((n, k))
    for i in range(n):
        if excluded[i]:
            for c in range(k):
                guess[i, c] = 0.0
            continue
        scale = lumped[i] if abs(lumped[i]) > tiny else 1.0 / inverse_diagonal[i]
        known = False
        if mode == GUESS_ADVANCED:
            for c in range(k):
                known = known or first[i, columns[c]] != 0.0 or second[i, columns[c]] != 0.0
        elif mode == GUESS_EXTRAPOLATED:
            for c in range(k):
                known = known or (second[i, columns[c]] != 0.0 and first[i, columns[c]] != 0.0)
        elif mode == GUESS_LAST:
            for c in range(k):
                known = known or first[i, columns[c]] != 0.0
        for c in range(k):
            j = columns[c]
            if not known:
                guess[i, c] = rhs[i, c] / scale
            elif mode == GUESS_ADVANCED:
                guess[i, c] = first[i, j] + dt * second[i, j] + shift[c]
            elif mode == GUESS_EXTRAPOLATED:
                guess[i, c] = 2.0 * first[i, j] - second[i, j]
            else:
                guess[i, c] = first[i, j]
    return guess


@compiled()
def _rows_touching(indptr, indices, marked):
    """The rows of marked nodes and of their neighbours, on a structurally symmetric
    pattern with every diagonal entry (the neighbours are the marked rows' columns)."""
    touched = np.zeros(len(indptr) - 1, dtype=np.bool_)
    for i in range(len(indptr) - 1):
        if marked[i]:
            for entry in range(indptr[i], indptr[i + 1]):  # the diagonal too: the row itself
                touched[indices[entry]] = True
    return touched


@compiled()
def _lump_couplings_in_place(indptr, indices, data, diagonal_index, weak):
    """:func:`_lump_couplings` keeping the structure (moved entries become explicit zeros).

    Only the rows of weak nodes and of their neighbours have such couplings: the
    structure is symmetric (the entry (i, j) exists where (j, i) does), so the
    neighbours are the columns of the weak rows.  The other rows are not read
    (a handful of weak nodes among 27,000: 2.5 ms -> ~30 us per step).
    """
    touched = _rows_touching(indptr, indices, weak)
    for i in range(len(indptr) - 1):
        if not touched[i]:
            continue
        for entry in range(indptr[i], indptr[i + 1]):
            j = indices[entry]
            if j != i and (weak[i] or weak[j]):
                data[diagonal_index[i]] += data[entry]
                data[entry] = 0.0


@compiled()
def _exclude_in_place(indptr, indices, data, diagonal_index, excluded):
    """``keep M keep + diag(excluded)`` in ``data`` itself, on a structure with every
    diagonal entry, returning what it overwrote, ``(positions, rows, old)``: every
    nonzero entry of an excluded row, the diagonal of an excluded row whatever its
    value, and the nonzero entries of kept rows in excluded columns.  The matrix before
    is the one after with those entries put back (exactly, :attr:`ConsistentMass.matrix`),
    and its product is the one after with the excluded rows replaced
    (:meth:`ConsistentMass.apply`).

    As in :func:`_lump_couplings_in_place`, only the rows of excluded nodes and of
    their neighbours change; the others are not read."""
    touched = _rows_touching(indptr, indices, excluded)
    size = 0
    for i in range(len(indptr) - 1):
        if touched[i]:
            size += indptr[i + 1] - indptr[i]
    positions = np.empty(size, dtype=np.int64)
    rows = np.empty(size, dtype=np.int64)
    old = np.empty(size)
    count = 0
    for i in range(len(indptr) - 1):
        if not touched[i]:
            continue
        for entry in range(indptr[i], indptr[i + 1]):
            if excluded[i] or excluded[indices[entry]]:
                diagonal = excluded[i] and entry == diagonal_index[i]
                if data[entry] != 0.0 or diagonal:
                    positions[count] = entry
                    rows[count] = i
                    old[count] = data[entry]
                    count += 1
                data[entry] = 1.0 if diagonal else 0.0
    return positions[:count], rows[:count], old[:count]


@compiled()
def _unexcluded_product(product, excluded, indices, positions, rows, old, vector):
    """``M @ vector`` from ``product = R @ vector`` (R: M with the excluded rows and columns
    made identity) and the entries the exclusion overwrote (:func:`_exclude_in_place`):
    an excluded row of R is exactly its unit row, so it is cleared and summed afresh; a kept
    row gains the couplings to excluded columns that R left out.  vector, product (n, k)."""
    for i in range(product.shape[0]):
        if excluded[i]:
            for c in range(product.shape[1]):
                product[i, c] = 0.0
    for t in range(rows.shape[0]):
        j = indices[positions[t]]
        for c in range(vector.shape[1]):
            product[rows[t], c] += old[t] * vector[j, c]
    return product


@compiled(inline="always")
def _row_times_dense(indptr, indices, data, x, i):
    """Row i of ``A @ x`` for x of shape (n, 2), as four partial sums per column:
    the sums of a row (49 entries for cubic splines) are chains of dependent
    additions in strict IEEE arithmetic, and one chain per column left the
    product bound by the adder's latency (partial sums: 25% faster).

    Positions and column indices are taken as unsigned: numba tests a signed
    index for Python's negative wraparound on every access, and without the
    tests the consistent steps at 1e5 points ran 9-11% faster (q1 147 -> 131,
    q2 300 -> 265, cubic splines 500 -> 455 ns, together with the unsigned
    positions of the assembly in :mod:`.kernels.transfer`)."""
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    a3 = 0.0
    b0 = 0.0
    b1 = 0.0
    b2 = 0.0
    b3 = 0.0
    one, two, three, four = np.uint64(1), np.uint64(2), np.uint64(3), np.uint64(4)
    entry = np.uint64(indptr[i])
    stop = np.uint64(indptr[i + 1])
    while entry + three < stop:
        j0, j1 = np.uint64(indices[entry]), np.uint64(indices[entry + one])
        j2, j3 = np.uint64(indices[entry + two]), np.uint64(indices[entry + three])
        d0, d1, d2, d3 = data[entry], data[entry + one], data[entry + two], data[entry + three]
        a0 = fused(d0, x[j0, 0], a0)
        b0 = fused(d0, x[j0, 1], b0)
        a1 = fused(d1, x[j1, 0], a1)
        b1 = fused(d1, x[j1, 1], b1)
        a2 = fused(d2, x[j2, 0], a2)
        b2 = fused(d2, x[j2, 1], b2)
        a3 = fused(d3, x[j3, 0], a3)
        b3 = fused(d3, x[j3, 1], b3)
        entry += four
    while entry < stop:
        j = np.uint64(indices[entry])
        d = data[entry]
        a0 = fused(d, x[j, 0], a0)
        b0 = fused(d, x[j, 1], b0)
        entry += one
    return (a0 + a1) + (a2 + a3), (b0 + b1) + (b2 + b3)


@compiled(inline="always")
def _precondition(r, z, use_tensor, inverse_diagonal, scale, excluded, factor_x, factor_y):
    """``z = P^-1 r``: the splines' tensor Gram preconditioner, or Jacobi."""
    if use_tensor:
        _apply_tensor(r, z, scale, excluded, factor_x, factor_y)
    else:
        for i in range(r.shape[0]):
            for c in range(r.shape[1]):
                z[i, c] = inverse_diagonal[i] * r[i, c]


@compiled()
def _csr_times_dense_dot(indptr, indices, data, x, out, dot):
    """``out = A @ x`` and ``dot[c] = x[:, c] . out[:, c]`` in one pass (x of shape (n, k))."""
    dot[:] = 0.0
    if x.shape[1] == 2:
        for i in range(len(indptr) - 1):
            first, second = _row_times_dense(indptr, indices, data, x, i)
            out[i, 0] = first
            out[i, 1] = second
            dot[0] = fused(x[i, 0], first, dot[0])
            dot[1] = fused(x[i, 1], second, dot[1])
    else:  # any number of columns, one at a time
        for i in range(len(indptr) - 1):
            for c in range(x.shape[1]):
                total = 0.0
                for entry in range(indptr[i], indptr[i + 1]):
                    total = fused(data[entry], x[indices[entry], c], total)
                out[i, c] = total
                dot[c] = fused(x[i, c], total, dot[c])


@compiled()
def _symmetric_times_dense_dot(indptr, indices, data, upper_start, x, out, dot):
    """:func:`_csr_times_dense_dot` of a symmetric matrix from one entry of each pair.

    ``upper_start[i]`` is row i's diagonal entry; the entries after it are one of
    each symmetric pair (i, j), j != i (those of a stencil-ordered mass pattern:
    slot > centre).  Each such entry adds ``a_ij x_j`` to row i and ``a_ij x_i`` to
    row j, so the product reads half of the matrix (cubic splines at 1e5 points:
    1.31 -> 0.99 ms for two columns).  The sums run in another order than the
    row-wise product's: the same to round-off, reproducible bit for bit.
    """
    n, k = x.shape
    out[:] = 0.0
    dot[:] = 0.0
    if k == 2:
        for i in range(n):
            diagonal = upper_start[i]
            xi0 = x[i, 0]
            xi1 = x[i, 1]
            # two partial sums per column: chains of dependent additions (see _row_times_dense)
            a0 = data[diagonal] * xi0
            b0 = data[diagonal] * xi1
            a1 = 0.0
            b1 = 0.0
            one = np.uint64(1)
            entry = np.uint64(diagonal) + one
            stop = np.uint64(indptr[i + 1])
            while entry + one < stop:
                j0, j1 = np.uint64(indices[entry]), np.uint64(indices[entry + one])
                d0, d1 = data[entry], data[entry + one]
                a0 = fused(d0, x[j0, 0], a0)
                b0 = fused(d0, x[j0, 1], b0)
                a1 = fused(d1, x[j1, 0], a1)
                b1 = fused(d1, x[j1, 1], b1)
                out[j0, 0] = fused(d0, xi0, out[j0, 0])
                out[j0, 1] = fused(d0, xi1, out[j0, 1])
                out[j1, 0] = fused(d1, xi0, out[j1, 0])
                out[j1, 1] = fused(d1, xi1, out[j1, 1])
                entry += np.uint64(2)
            if entry < stop:
                j0 = np.uint64(indices[entry])
                d0 = data[entry]
                a0 = fused(d0, x[j0, 0], a0)
                b0 = fused(d0, x[j0, 1], b0)
                out[j0, 0] = fused(d0, xi0, out[j0, 0])
                out[j0, 1] = fused(d0, xi1, out[j0, 1])
            out[i, 0] += a0 + a1
            out[i, 1] += b0 + b1
    else:
        for i in range(n):
            diagonal = upper_start[i]
            for c in range(k):
                total = data[diagonal] * x[i, c]
                for entry in range(diagonal + 1, indptr[i + 1]):
                    j = indices[entry]
                    total = fused(data[entry], x[j, c], total)
                    out[j, c] = fused(data[entry], x[i, c], out[j, c])
                out[i, c] += total
    for i in range(n):  # every row is complete only now
        for c in range(k):
            dot[c] = fused(x[i, c], out[i, c], dot[c])


@compiled(inline="always")
def _product_dot(indptr, indices, data, upper_start, x, out, dot):
    """``out = A @ x`` and the dots ``x . out``: from one half when ``upper_start`` is given
    (a symmetric stencil-ordered matrix), else row by row."""
    if upper_start.shape[0] > 0:
        _symmetric_times_dense_dot(indptr, indices, data, upper_start, x, out, dot)
    else:
        _csr_times_dense_dot(indptr, indices, data, x, out, dot)


@compiled()
def _transpose_times_dense(indptr, indices, data, y, n_columns):
    """``A.T @ y`` for a CSR matrix A of shape (len(y), n_columns) and y of shape (len(y), k)."""
    out = np.zeros((n_columns, y.shape[1]))
    for row in range(len(indptr) - 1):
        for entry in range(indptr[row], indptr[row + 1]):
            j = indices[entry]
            for c in range(y.shape[1]):
                out[j, c] = fused(data[entry], y[row, c], out[j, c])
    return out


@compiled(inline="always")
def _all_within(residual, target):
    """Whether every column's squared residual norm is within its target norm."""
    for c in range(residual.shape[0]):
        if np.sqrt(residual[c]) > target[c]:
            return False
    return True


@compiled()
def _compiled_cg(indptr, indices, data, upper_start, b, x0, inverse_diagonal, rtol, max_iterations,
                 use_tensor, scale, excluded, factor_x, factor_y):
    """:func:`_preconditioned_cg` compiled, for one or two columns (the same steps).

    The vector updates, the Jacobi preconditioner and the two reductions
    (``r.z``, ``r.r``) share one pass over the nodes, and ``p.Ap`` is summed
    in the matrix product's pass: the iteration reads each vector once, and
    the independent sums of the fused passes hide each other's latency.
    """
    n, k = b.shape
    x = x0.copy()
    r = np.empty_like(b)
    _product_dot(indptr, indices, data, upper_start, x, r, np.zeros(k))
    z = np.empty_like(b)
    p = np.empty_like(b)
    Ap = np.empty_like(b)
    target = np.zeros(k)
    residual = np.zeros(k)
    rz = np.zeros(k)
    rz_new = np.zeros(k)
    curvature = np.zeros(k)
    alpha = np.zeros(k)
    beta = np.zeros(k)
    for i in range(n):
        for c in range(k):
            r[i, c] = b[i, c] - r[i, c]
            target[c] += b[i, c] * b[i, c]
            residual[c] = fused(r[i, c], r[i, c], residual[c])
    for c in range(k):
        target[c] = rtol * np.sqrt(target[c])
    if _all_within(residual, target):  # the first guess is the solution: no preconditioning
        return x, True, 0
    _precondition(r, z, use_tensor, inverse_diagonal, scale, excluded, factor_x, factor_y)
    for i in range(n):
        for c in range(k):
            p[i, c] = z[i, c]
            rz[c] += r[i, c] * z[i, c]
    for iteration in range(max_iterations + 1):
        done = True
        any_rz = False
        for c in range(k):
            if np.sqrt(residual[c]) > target[c]:
                done = False
            if rz[c] != 0.0:
                any_rz = True
        if done or not any_rz:
            return x, True, iteration
        if iteration == max_iterations:
            break
        _product_dot(indptr, indices, data, upper_start, p, Ap, curvature)
        for c in range(k):
            if curvature[c] <= 0.0 and rz[c] != 0.0:
                return x, False, iteration
            alpha[c] = rz[c] / curvature[c] if curvature[c] > 0.0 else 0.0
            residual[c] = 0.0
            rz_new[c] = 0.0
        if use_tensor:
            for i in range(n):
                for c in range(k):
                    x[i, c] = fused(alpha[c], p[i, c], x[i, c])
                    r[i, c] = fused(-alpha[c], Ap[i, c], r[i, c])
                    residual[c] = fused(r[i, c], r[i, c], residual[c])
            if _all_within(residual, target):  # converged: the preconditioner's sweep would go unused
                return x, True, iteration + 1
            _apply_tensor(r, z, scale, excluded, factor_x, factor_y)
            for i in range(n):
                for c in range(k):
                    rz_new[c] = fused(r[i, c], z[i, c], rz_new[c])
        else:
            for i in range(n):
                for c in range(k):
                    x[i, c] = fused(alpha[c], p[i, c], x[i, c])
                    r[i, c] = fused(-alpha[c], Ap[i, c], r[i, c])
                    z[i, c] = inverse_diagonal[i] * r[i, c]
                    rz_new[c] = fused(r[i, c], z[i, c], rz_new[c])
                    residual[c] = fused(r[i, c], r[i, c], residual[c])
        for c in range(k):
            beta[c] = rz_new[c] / rz[c] if rz[c] != 0.0 else 0.0
            rz[c] = rz_new[c]
        for i in range(n):
            for c in range(k):
                p[i, c] = fused(beta[c], p[i, c], z[i, c])
    return x, False, max_iterations


@dataclass(frozen=True)
class TensorPreconditioner:
    """CG's preconditioner for tensor-product cubic B-splines: ``z = S^-1 (K_x ⊗ K_y)^-1 S^-1 r``.

    Inside a body of uniform density, ``N.T diag(m) N`` approaches ``rho h^2
    K_x ⊗ K_y`` with ``K`` the 1D Gram matrix of the splines (stencil
    ``(1, 120, 1191, 2416, 1191, 120, 1) / 5040``); its Jacobi-scaled form
    has a condition number near 350 in 2D, where CG needed ~340 iterations
    at 1e5 nodes.  ``S = sqrt(M_ii / K_ii)`` carries each node's mass and the
    tensor inverse is two sweeps of banded Cholesky solves, O(n); CG then
    needs ~25.  It is symmetric positive definite on the kept degrees of
    freedom (a principal block of the inverse of an SPD matrix), the excluded
    ones keep their identity rows.
    """

    factor_x: np.ndarray  # (4, n_x) upper banded Cholesky factor of K_x
    factor_y: np.ndarray
    gram_diagonal: float

    @property
    def lattice_shape(self) -> tuple[int, int]:
        """Nodes along x and y (node ``ix * n_y + iy``)."""
        return self.factor_x.shape[1], self.factor_y.shape[1]

    def scaled(self, system: "_System") -> tuple:
        """The arguments of :func:`_apply_tensor` for one system."""
        diagonal = 1.0 / system.inverse_diagonal
        scale = np.where(system.excluded, 0.0, 1.0 / np.sqrt(np.abs(diagonal) / self.gram_diagonal))
        return (scale, system.excluded, self.factor_x, self.factor_y)


#: lattice steps from an excluded or weak node, or from the lattice's edge, within
#: which :class:`BoundaryLayer` solves exactly.  Velocity + acceleration CG iterations
#: per step for cubic splines at 1e5 points: width 2: 2 + 5, 3: 1 + 4 (5 ms of
#: factoring), 4: 1 + 3 (8 ms)
LAYER_WIDTH = 3
#: the largest share of the kept nodes a :class:`BoundaryLayer` may hold
LAYER_LIMIT = 0.5


@dataclass
class BoundaryLayer:
    """Completes :class:`TensorPreconditioner` where a body's edge makes ``M`` unlike a tensor product.

    The tensor preconditioner is exact for a uniform body that fills the
    lattice; near an edge (partly filled supports, lumped weak nodes, a
    support's excluded nodes) it is not, and CG's residual lingers there:
    after 8 iterations, 90% of it sat within 3 nodes of an excluded one
    (cubic splines, 1e5 points).  The layer of nodes within
    :data:`LAYER_WIDTH` of such nodes gets an exact solve with its block
    ``M_LL`` (SuperLU, factored once per step), in a symmetric
    multiplicative Schwarz sweep, layer - tensor - layer::

        z  = R^T M_LL^-1 R r
        z += T^-1 (r - M z)
        z += R^T M_LL^-1 R (r - M z)

    ``M z`` needs only the layer's rows (``M`` is symmetric, ``z`` lives on
    the layer in the first product), so a sweep costs the tensor solve, two
    small triangular solves and two products with the layer's rows.  With
    ``B = R^T M_LL^-1 R`` and ``Q = I - B M`` the sweep is
    ``P^-1 = B + Q T^-1 Q^T``: symmetric, and positive definite whenever
    ``T`` is (the layer's solve being exact; a second review found
    ``T^-1 M`` with eigenvalues up to 9 and ``P^-1 M`` still in [0.68, 1.01]).
    Only an inaccurate factorization could spoil it: CG checks ``r.z > 0``
    as it goes and :class:`ConsistentMass` then falls back to the tensor
    preconditioner alone.  A layer holding more than :data:`LAYER_LIMIT` of
    the kept nodes (a thin body) is not built: factoring it costs more than
    the iterations it saves (a body 4 cells thick, 86% in the layer: 109
    against 89 ms per step).  Cubic splines, 1e5 points: 5 + 14 -> 1 + 4
    iterations per step (velocity + acceleration), for ~5 ms of factoring
    per step.

    Attributes
    ----------
    nodes : ndarray of int, shape (n_layer,)
    factors : SuperLU of ``M_LL``
    rows : csr_matrix, shape (n_layer, n_nodes)
        ``M[nodes, :]``; ``M[:, nodes]`` is its transpose (``M`` symmetric),
        applied by :func:`_transpose_times_dense` (a CSR matrix of the
        transpose loops over every node's row: 0.25 against 0.09 ms).
    """

    nodes: np.ndarray
    factors: object
    rows: sp.csr_matrix

    @classmethod
    def build(cls, matrix: sp.csr_matrix, excluded: np.ndarray, weak: np.ndarray,
              lattice_shape: tuple) -> "BoundaryLayer | None":
        """The layer of a system, or None if it is empty, holds more than
        :data:`LAYER_LIMIT` of the kept nodes, or its block is singular (CG
        then meets the singularity and reports it, as without a layer)."""
        lattice = np.column_stack(np.unravel_index(np.arange(len(excluded)), lattice_shape))
        nodes = np.flatnonzero(_near_empty_nodes(lattice, excluded | weak, LAYER_WIDTH) & ~excluded)
        if nodes.size == 0 or nodes.size > LAYER_LIMIT * np.count_nonzero(~excluded):
            return None
        rows, block = _rows_and_block(matrix, nodes)
        factors = _factor(block)
        if factors is None:
            return None
        return cls(nodes, factors, _CompiledCSR(rows))

    def sweep(self, r: np.ndarray, tensor_solve) -> np.ndarray:
        """``z = P^-1 r`` for r of shape (n_nodes, k); ``tensor_solve(v)`` is ``T^-1 v``."""
        nodes = self.nodes
        z = np.zeros_like(r)
        z[nodes] = self.factors.solve(np.ascontiguousarray(r[nodes]))
        rows = self.rows
        z += tensor_solve(r - _transpose_times_dense(rows.indptr, rows.indices, rows.data, z[nodes], r.shape[0]))
        z[nodes] += self.factors.solve(np.ascontiguousarray(r[nodes] - self.rows @ z))
        return z


def tensor_preconditioner(grid) -> TensorPreconditioner | None:
    """For cubic B-spline grids (nodes numbered ``i * n_y + j``), else None (Jacobi)."""
    from scipy.linalg import cholesky_banded

    if grid.basis not in ("bspline3", "bspline3_open"):
        return None
    stencil = np.array([2416.0, 1191.0, 120.0, 1.0]) / 5040.0
    factors = []
    for n_cells in grid.discretization.n_elements:
        n = n_cells + 3
        banded = np.zeros((4, n))
        for offset in range(4):
            banded[3 - offset, offset:] = stencil[offset]
        factors.append(np.ascontiguousarray(cholesky_banded(banded, lower=False)))
    if factors[0].shape[1] * factors[1].shape[1] != grid.n_nodes:  # pragma: no cover
        return None
    return TensorPreconditioner(factors[0], factors[1], stencil[0] ** 2)


_NO_TENSOR = (False, np.zeros(1), np.zeros(1, dtype=bool), np.zeros((4, 1)), np.zeros((4, 1)))


@compiled()
def _banded_sweeps(factor, values, count, n_lines):
    """Solve ``U^T U z = values`` in place on ``n_lines`` independent lattice lines
    at once (U upper banded, bandwidth 3, ``factor[3 + i - j, j] = U[i, j]``):
    entry ``j`` of line ``l`` is ``values[j * n_lines + l]``, so the inner loop
    runs over contiguous, independent lines.  The diagonal is inverted once (a
    product per entry instead of a division)."""
    inverse = 1.0 / factor[3]
    for j in range(count):
        row = j * n_lines
        for line in range(n_lines):
            total = values[row + line]
            if j >= 3:
                total = fused(-factor[0, j], values[row - 3 * n_lines + line], total)
            if j >= 2:
                total = fused(-factor[1, j], values[row - 2 * n_lines + line], total)
            if j >= 1:
                total = fused(-factor[2, j], values[row - n_lines + line], total)
            values[row + line] = total * inverse[j]
    for i in range(count - 1, -1, -1):
        row = i * n_lines
        for line in range(n_lines):
            total = values[row + line]
            if i + 1 < count:
                total = fused(-factor[2, i + 1], values[row + n_lines + line], total)
            if i + 2 < count:
                total = fused(-factor[1, i + 2], values[row + 2 * n_lines + line], total)
            if i + 3 < count:
                total = fused(-factor[0, i + 3], values[row + 3 * n_lines + line], total)
            values[row + line] = total * inverse[i]


@compiled()
def _apply_tensor(r, out, scale, excluded, factor_x, factor_y):
    """``out = S^-1 (K_x ⊗ K_y)^-1 S^-1 r`` on kept nodes, ``r`` on excluded ones
    (node ``ix * n_y + iy``)."""
    n_x, n_y = factor_x.shape[1], factor_y.shape[1]
    line = np.empty(n_x * n_y)
    transposed = np.empty(n_x * n_y)
    for c in range(r.shape[1]):
        for ix in range(n_x):
            for iy in range(n_y):
                transposed[iy * n_x + ix] = scale[ix * n_y + iy] * r[ix * n_y + iy, c]
        _banded_sweeps(factor_y, transposed, n_y, n_x)  # along y, the lines (ix) contiguous
        for ix in range(n_x):
            for iy in range(n_y):
                line[ix * n_y + iy] = transposed[iy * n_x + ix]
        _banded_sweeps(factor_x, line, n_x, n_y)  # along x, the lines (iy) contiguous
        for i in range(n_x * n_y):
            out[i, c] = r[i, c] if excluded[i] else scale[i] * line[i]
    return out


class _CompiledCSR(sp.csr_matrix):
    """A CSR matrix whose product with a dense (n, k) array is a compiled loop
    (scipy's ``csr_matvecs`` took ~3 ns per stored entry with two columns).

    ``upper_start`` (set by whoever knows it): the matrix is symmetric bit for
    bit and stored in stencil order, row i's entries after ``upper_start[i]``
    (its diagonal) one of each symmetric pair: the product then reads that half
    (:func:`_symmetric_times_dense_dot`).  Operations that make a new matrix
    (scipy's) do not carry it.
    """

    upper_start: np.ndarray | None = None

    def upper_start_or_none(self) -> np.ndarray:
        """``upper_start`` for the kernels (an empty array: row by row)."""
        return _ROW_BY_ROW if self.upper_start is None else self.upper_start

    def __matmul__(self, other):
        if isinstance(other, np.ndarray) and other.ndim == 2 and other.dtype == np.float64:
            out = np.empty((self.shape[0], other.shape[1]))
            _product_dot(self.indptr, self.indices, self.data, self.upper_start_or_none(),
                         np.ascontiguousarray(other), out, np.zeros(other.shape[1]))
            return out
        return super().__matmul__(other)


_ROW_BY_ROW = np.zeros(0, dtype=np.int64)


def _lump_couplings(matrix: sp.csr_matrix, weak: np.ndarray) -> sp.csr_matrix:
    """Move every off-diagonal entry that touches a weak node onto both diagonals."""
    coo = matrix.tocoo()
    moved = (coo.row != coo.col) & (weak[coo.row] | weak[coo.col])
    to_diagonal = np.bincount(coo.row[moved], weights=coo.data[moved], minlength=matrix.shape[0])
    data = np.where(moved, 0.0, coo.data)
    kept = sp.csr_matrix((data, (coo.row, coo.col)), shape=matrix.shape)
    kept.eliminate_zeros()
    return (kept + sp.diags(to_diagonal)).tocsr()


@compiled()
def _cg_advance(x, r, p, Ap, alpha, residual):
    """``x += alpha p``, ``r -= alpha Ap`` column by column; ``residual`` gets ``r.r``."""
    residual[:] = 0.0
    for i in range(x.shape[0]):
        for c in range(x.shape[1]):
            x[i, c] += alpha[c] * p[i, c]
            r[i, c] -= alpha[c] * Ap[i, c]
            residual[c] += r[i, c] * r[i, c]


@compiled()
def _cg_direction(p, z, beta):
    """``p = z + beta p`` column by column, in place."""
    for i in range(p.shape[0]):
        for c in range(p.shape[1]):
            p[i, c] = z[i, c] + beta[c] * p[i, c]


@compiled()
def _column_dots(a, b):
    """``a[:, c] . b[:, c]`` for each column (numpy's einsum took ~100 us for (27225, 2))."""
    out = np.zeros(a.shape[1])
    for i in range(a.shape[0]):
        for c in range(a.shape[1]):
            out[c] = fused(a[i, c], b[i, c], out[c])
    return out


def _product_and_curvature(A, p):
    """``A @ p`` and ``p . A p`` per column, in one compiled pass where ``A`` is compiled."""
    if isinstance(A, _CompiledCSR):
        Ap, curvature = np.empty_like(p), np.zeros(p.shape[1])
        _product_dot(A.indptr, A.indices, A.data, A.upper_start_or_none(), p, Ap, curvature)
        return Ap, curvature
    Ap = A @ p
    return Ap, _column_dots(p, np.ascontiguousarray(Ap))


def _preconditioned_cg(A, b, x0, inverse_diagonal, rtol, max_iterations, tensor=None, layer=None):
    """Preconditioned CG on the columns of ``b`` (n, k) at once: Jacobi, or the
    arguments of :func:`_apply_tensor` (``tensor``), completed by a
    :class:`BoundaryLayer` (``layer``).

    Returns ``(x, converged, iterations)``.  Converged means every column's
    residual fell to ``rtol * |b|``.  A non-positive curvature ``p.A.p``
    (singular matrix met by an inconsistent right-hand side) stops the
    iteration as not converged (False); a negative ``r.z`` (a preconditioner
    that is not positive definite) stops it with ``converged = None``.
    """
    if isinstance(A, _CompiledCSR) and layer is None:
        return _compiled_cg(A.indptr, A.indices, A.data, A.upper_start_or_none(), np.ascontiguousarray(b, dtype=float),
                            np.ascontiguousarray(x0, dtype=float), inverse_diagonal, rtol, max_iterations,
                            *(_NO_TENSOR if tensor is None else (True, *tensor)))

    def tensor_solve(r):
        return _apply_tensor(np.ascontiguousarray(r), np.empty_like(r), *tensor)

    def precondition(r):
        if tensor is None:
            return inverse_diagonal[:, None] * r
        return tensor_solve(r) if layer is None else layer.sweep(r, tensor_solve)

    # the vector updates in compiled passes (numpy's temporaries took as long as the products)
    b = np.ascontiguousarray(b, dtype=float)
    x = np.array(x0, dtype=float)
    target = rtol * np.linalg.norm(b, axis=0)
    r = b - A @ x
    residual = _column_dots(r, r)
    if np.all(np.sqrt(residual) <= target):  # the first guess is the solution: no preconditioning
        return x, True, 0
    z = precondition(r)
    p = z.copy()
    rz = _column_dots(r, z)
    if np.any(rz < 0):
        return x, None, 0
    for iteration in range(max_iterations + 1):
        if not np.any(rz):
            return x, True, iteration
        if iteration == max_iterations:
            break
        Ap, curvature = _product_and_curvature(A, p)
        if np.any((curvature <= 0) & (rz != 0)):
            return x, False, iteration
        alpha = np.divide(rz, curvature, out=np.zeros_like(rz), where=curvature > 0)
        _cg_advance(x, r, p, Ap, alpha, residual)
        if np.all(np.sqrt(residual) <= target):  # converged: the preconditioner's sweep would go unused
            return x, True, iteration + 1
        z = precondition(r)
        rz_new = _column_dots(r, z)
        if np.any(rz_new < 0):
            return x, None, iteration + 1
        beta = np.divide(rz_new, rz, out=np.zeros_like(rz), where=rz != 0)
        _cg_direction(p, z, beta)
        rz = rz_new
    return x, False, max_iterations
