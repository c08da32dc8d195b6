"""Consistent mass ``N.T diag(m_p) N`` (paper Eqs. 10, 17, 19, 20) and what makes it solvable.

``M`` is positive semi-definite. It is singular when a node's function is seen by too few points to
fix its value, e.g. a node touched only by the far edge of a body, or, globally, a body with fewer
points across than basis functions span it (cubic B-splines with 2 points per cell in a body 2
cells thick). Momentum always lies in the range of ``M`` (so velocities *at the points* are right),
but internal forces in general do not, and velocity *gradients* there are arbitrary. We treat it in
three layers:

1. *Empty nodes* (``M_ii = 0``) are removed: identity rows, zero solution.
2. *Weak nodes* of non-negative bases (q1, bspline3), whose material volume fraction
   ``(N.T @ V_p)_i / integral(phi_i)`` is below ``weak_fraction``, are lumped: each coupling
   ``M_ij`` to a weak node is moved onto both diagonals. This keeps every row sum (so rigid motion
   and momentum stay exact) and only adds positive semi-definite terms, so it never makes the
   matrix less definite. Rows seen through their function's tail, which set the critical step,
   give a share of their couplings (:mod:`.weak_rows`).
3. What remains singular is *detected*: a SuperLU pivot falls below ``1e-8`` of its own diagonal
   entry (the node's function is reproduced by the others), or preconditioned CG fails to converge
   on the force system. The ``fallback`` policy decides: ``"error"`` raises
   :class:`SingularMassError`; ``"blend"`` solves with ``(1 - blend) M + blend * diag(lumped)`` for
   that step, counts the event and goes on (where row sums are not all positive, q2 and
   serendipity, the HRZ diagonal, ``M_ii`` scaled to the total mass, replaces them).

Linear solver: ``"direct"`` factors the matrix once per step with SuperLU (:mod:`.direct`; both
solves of the step reuse the factors) and checks every solution's residual, because SuperLU returns
garbage without warning on a singular matrix. ``"cg"`` is preconditioned CG warm-started from the
last steps (:mod:`.cg`: symmetric Gauss-Seidel, :mod:`.gauss_seidel`; for cubic splines a tensor
Gram preconditioner, :mod:`.preconditioners`). ``"auto"`` factors up to 5000 active nodes: small
systems every step (:mod:`.ldl`), the others kept as CG's preconditioner (:mod:`.reused`) while
they pay against CG (:mod:`.trial`, :mod:`.layout`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .cg import _preconditioned_cg, initial_guess
from .direct import _direct_solve, _factor
from .exclusion import NO_NODES, active_and_weak, unexcluded_apply, unexcluded_matrix
from .layout import RunChoices
from .nodal import free_part, in_frame, plus_row
from .preconditioners import TensorPreconditioner
from .reused import KeptFactors
from .protocol import Assembly, Inertia, MassModel, NodalSums, SingularMassError
from .scale import NO_SCALES, CellMasses, scale_arguments
from .singular import singular_near_edges
from .sparse import PatternMatrix, _CompiledCSR
from .system import _System
from .weak_rows import lumped_and_mixed, mix_target, weak_by_ratio

@dataclass
class ConsistentMass(MassModel):
    """Consistent mass ``N.T diag(m_p) N``, solved directly or by CG.

    Parameters
    ----------
    n_nodes : int
    cells : CellMasses
        A full lattice cell's mass of each body (kg), the scale for "empty"
        (:meth:`CellMasses.at_nodes`).
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
    fixed : ndarray of bool, shape (n_nodes, 2), optional
        Degrees of freedom held at zero by supports: a coupled matrix must
        leave them out of the solve (zeroing them afterwards, exact for a
        diagonal mass, is wrong here).
    preconditioner : TensorPreconditioner, optional
        CG's for cubic B-splines (:func:`.preconditioners.tensor_preconditioner`); None:
        symmetric Gauss-Seidel on the mass pattern's matrix (:mod:`.gauss_seidel`), else Jacobi.
    lattice : ndarray of int, shape (n_nodes, 2), optional
        Each node's x and y index on the lattice, and ``layer_width`` the
        width of an element in lattice spacings: where CG looks for a
        singular block (signed bases).
    time_step : float, optional
        The step (s): CG's first guess of the velocity is the last step's
        grid velocity advanced by its acceleration.
    solves : bool
        Make the solve's systems (False: only ``M`` is assembled, for a model
        that solves a reduced form of it, :class:`.constraint.ConstrainedMass`).
    weak_ratio, interior, weak_mix, mix : float
        The weak rows (``M_ii / m_i`` below ``weak_ratio * interior``, the basis' value
        inside a body) give the share ``weak_mix`` of their couplings to the diagonals;
        ``mix``: the mixed mass ``(1 - mix) M + mix D`` (:mod:`.weak_rows`).
    """

    n_nodes: int
    cells: CellMasses
    node_integrals: np.ndarray = field(repr=False)
    nonnegative: bool = True
    weak_fraction: float = 0.01
    tolerance: float = 1e-6
    linear_solver: str = "auto"
    fallback: str = "error"
    blend: float = 0.1
    fixed: np.ndarray | None = field(default=None, repr=False)
    preconditioner: "TensorPreconditioner | None" = field(default=None, repr=False)
    lattice: np.ndarray | None = field(default=None, repr=False)
    layer_width: int = 2
    time_step: float | None = None
    solves: bool = True
    weak_ratio: float = 0.0
    interior: float = 0.0
    weak_mix: float = 0.02
    mix: float = 0.0
    kind = "consistent"
    assembly = Assembly(node_volume=True, matrix=True)
    iterations: int = 0
    weak_nodes: int = 0
    weak_rows: int = 0
    blended_steps: int = 0

    def __post_init__(self):
        self._previous: dict[str, tuple] = {}
        self._frame = None  # the frame of the velocity being solved for (set by grid_velocity)
        # the assembled M (or, made into the solve's system in place, that system R and the
        # entries it overwrote), and M rebuilt from them on demand (:attr:`matrix`)
        self._assembled, self._correction, self._full = None, None, None
        self._consistent, self._mix_excess = None, None  # set by _prepare
        self._smallest = None  # the smallest row sum, for the negative-mass check
        self.max_iterations = int(200 + 20 * np.sqrt(self.n_nodes))
        # "auto" below DIRECT_LIMIT: the factors kept from an earlier step, per system's columns
        self._kept = KeptFactors()
        self._choices = RunChoices()  # what "auto" measured during the run
        self._over_pattern = PatternMatrix()
        self._layout = None  # the systems' layout (.layout), kept while the active and weak nodes stay
        self._layer_layouts = {}  # CG's boundary layer: each system's last layout (.preconditioners)

    def state(self) -> tuple[dict, dict]:
        """What carries from step to step, ``(arrays, values)``: CG's warm-start
        history (the last two solutions of each kind) and the counters."""
        arrays = {f"previous.{kind}.{index}": solution
                  for kind, history in self._previous.items() for index, solution in enumerate(history)}
        arrays.update(self._kept.arrays())
        values = {"iterations": self.iterations, "weak_nodes": self.weak_nodes, "blended_steps": self.blended_steps,
                  "previous": {kind: len(history) for kind, history in self._previous.items()},
                  "kept": len(self._kept), **self._choices.values()}
        return arrays, values

    def restore(self, arrays: dict, values: dict) -> None:
        """Take back :meth:`state`."""
        self.iterations, self.weak_nodes = int(values["iterations"]), int(values["weak_nodes"])
        self.blended_steps = int(values["blended_steps"])
        self._previous = {kind: tuple(np.array(arrays[f"previous.{kind}.{index}"]) for index in range(count))
                          for kind, count in values["previous"].items()}
        self._kept = KeptFactors.restored(arrays, values.get("kept", 0))
        self._choices = RunChoices.restored(values)
        self._layout = None

    def assemble(self, N: sp.csr_matrix, m_p: np.ndarray, volume_p: np.ndarray | None = None) -> None:
        weighted = N.multiply(m_p[:, None]).tocsr()
        matrix = (N.T @ weighted).tocsr()
        self.lumped = N.T @ m_p
        self.scale = self.cells.at_nodes(N)
        self._prepare(matrix, None if volume_p is None else N.T @ volume_p)

    def assemble_sums(self, sums: NodalSums) -> None:
        """The same from the compiled P2G, which added ``m_p N_a N_b`` into ``sums.pattern``
        (:class:`femgrid_mpm.kernels.pattern.MassPattern`, a structure fixed per
        grid with every diagonal entry), ``N.T @ m_p`` and ``N.T @ V_p``.  The
        weak-node lumping and the systems keep that structure (no SpGEMM)."""
        pattern, lumped, node_volume = sums.pattern, sums.mass, sums.volume
        self.lumped = lumped
        self.scale = self.cells.uniform if sums.scale is None else sums.scale
        self._prepare(self._over_pattern.of(pattern), node_volume, pattern.diagonal)

    def _prepare(self, matrix: sp.csr_matrix, node_volume: np.ndarray | None, diagonal_index=None) -> None:
        diagonal = matrix.diagonal() if diagonal_index is None else matrix.data[diagonal_index]
        self.active, self._weak = np.empty(self.n_nodes, dtype=bool), np.empty(self.n_nodes, dtype=bool)
        last = self._layout
        self.weak_nodes, self._smallest, unchanged = active_and_weak(
            diagonal, *scale_arguments(self.scale), self.lumped,
            *((node_volume, self.node_integrals) if self.nonnegative and node_volume is not None else (NO_SCALES,) * 2),
            self.weak_fraction, self.active, self._weak, *((last.active, last.weak) if last else (NO_NODES,) * 2))
        self.weak_rows, shares = 0, None
        consistent = matrix  # the scipy path makes new matrices: N.T diag(m) N itself stays, for the estimate
        if self.weak_ratio > 0 and self.nonnegative and node_volume is not None:
            # the rows seen through their function's tail: a share of their couplings
            rows = weak_by_ratio(diagonal, self.lumped, self.active, self.weak_ratio * self.interior) & ~self._weak
            self.weak_rows = int(rows.sum())
            shares = self.weak_mix * rows if self.weak_rows else None
        target = np.where(self.active, mix_target(self.lumped, diagonal, self.active), 0.0) if self.mix > 0 else None
        matrix = lumped_and_mixed(matrix, diagonal_index, self._weak if self.weak_nodes else None, shares, self.mix, target)
        # a (L - D): what the mixed mass's diagonal leaves of the row sums (the frame's share, see solve)
        self._mix_excess = None if target is None or np.array_equal(target, self.lumped * self.active) else \
            self.mix * np.where(self.active, self.lumped - target, 0.0)
        self._consistent = consistent if matrix is not consistent else None
        self._assembled, self._correction, self._full = matrix, None, None
        if not self.solves:
            return
        if not unchanged:
            self._layout = self._choices.layout(self.active, self._weak, self.fixed, self.linear_solver)
            kept = self._kept.fitting(self._layout.groups, self._layout.excluded, self._weak)
        else:  # kept over an unchanged layout, the factors were made for it
            kept = self._kept.fresh(self._layout.groups)
        self._systems, self._correction, kept = self._choices.systems(
            matrix, diagonal_index, self._layout, kept, self._weak, self.linear_solver == "auto",
            self.preconditioner is not None, self.iterations)  # (the choices may change the layout's direct)
        self._direct = self._layout.direct
        self._kept = kept if self._keeps_factors else KeptFactors()

    @property
    def _keeps_factors(self) -> bool:
        """Whether this step's systems are factored and kept ("auto" below :data:`DIRECT_LIMIT` active nodes)."""
        return self._direct and self.linear_solver == "auto"

    @property
    def _keeps_history(self) -> bool:
        """Whether the solutions are kept for the next step's first guess (CG's)."""
        return not self._direct or self.linear_solver == "auto"

    @property
    def matrix(self) -> sp.csr_matrix:
        """``M`` (n_nodes, n_nodes), after the weak-node lumping.  Where the solve's system
        was made from it in place, it is rebuilt on first use in the step (same structure)."""
        if self._correction is None:
            return self._assembled
        if self._full is None:
            self._full = unexcluded_matrix(self._assembled, self._correction)
        return self._full

    def inertia(self, N: sp.csr_matrix) -> Inertia:
        """``M`` (weak nodes and rows treated, mixed), and ``N.T diag(m) N`` where it differs."""
        return Inertia(matrix=self.matrix, consistent=self._consistent)

    def row_sums(self) -> list[tuple[np.ndarray, float | None, float | np.ndarray]]:
        return [(self.lumped, self._smallest, self.scale)]

    def summary(self) -> dict:
        return {"consistent_mass": {"cg_iterations": self.iterations, "weak_nodes_last_step": self.weak_nodes,
                                    "weak_rows_last_step": self.weak_rows, "blended_steps": self.blended_steps}}

    def grid_velocity(self, relative_momentum: np.ndarray, frame_velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 17 in the frame moving with ``frame_velocity``: ``(p, v)``, the momentum
        ``p_rel + m v_ref`` and the velocity ``M^-1 p_rel + v_ref``."""
        self._frame = np.asarray(frame_velocity, dtype=float)
        momentum = in_frame(np.ascontiguousarray(relative_momentum, dtype=float), self.lumped, self._frame)
        velocity = plus_row(self.solve(relative_momentum, "velocity", frame=self._frame), self._frame)
        if self._keeps_history:  # the frame of the velocities in the history, for the next guess
            self._previous["frame"] = (self._frame.reshape(1, 2).copy(),)
        return momentum, velocity

    def apply(self, vector: np.ndarray) -> np.ndarray:
        """``M @ vector`` with the consistent matrix (empty rows zero)."""
        if self._correction is None:
            return self._assembled @ vector
        return unexcluded_apply(self._assembled, self._correction, self._systems[0].excluded, vector)

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
        solution = None  # one system of both columns returns its own (no zeros to copy it over)
        moving = frame is not None and any(frame.tolist())  # (a list's any: 0.1 us, frame.any() 1 us)
        coupling = None  # M_fc v_ref on the free rows
        if moving and self.fixed is not None:
            coupling = self.apply(np.where(self.fixed, frame, 0.0))
        for system in self._systems:
            whole = len(system.columns) == rhs.shape[1]  # the one system: no copies of the columns
            if system.ldl is not None and coupling is None and (self._mix_excess is None or not moving):
                # this step's exact factors, which read the free rows only and are zero elsewhere
                solved = system.ldl.solve(rhs if whole else rhs[:, system.columns])
            else:
                columns = np.asarray(system.columns, dtype=np.int64)
                part, nonzero = free_part(np.ascontiguousarray(rhs, dtype=float), columns, system.excluded)
                coupled = None if coupling is None else free_part(coupling, columns, system.excluded)[0]
                if not nonzero and (coupled is None or not coupled.any()):  # e.g. a rigid motion's relative momentum
                    continue
                solved = self._solve_system(system, part, kind, coupled, frame[system.columns] if moving else None)
            if whole:
                solution = solved
            else:
                solution = np.zeros(rhs.shape) if solution is None else solution
                solution[:, system.columns] = solved
        solution = np.zeros(rhs.shape) if solution is None else solution  # (None: nothing to solve)
        if self._keeps_history:
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
            if self._mix_excess is not None and frame is not None:  # the same for the mixed mass
                total = total + np.where(system.excluded, 0.0, self._mix_excess)[:, None] * frame[None, :]
            return total

        if self._singular_near_edges(system):  # CG would not see it (see the method)
            solution, converged = np.zeros_like(part), False
        else:
            solution, converged = self._solve(system, right_hand_side(), kind)
        if not converged:
            if self.fallback != "blend":
                how = ("a pivot of its factorization is singular" if system.layout is not None else
                       "its block near the bodies' edges has a singular pivot" if system.singular else
                       "the direct solve left a large residual" if self._direct else
                       f"CG did not converge to solver.cg_tolerance = {self.tolerance:g}")
                raise SingularMassError(
                    f"the consistent mass matrix is singular or nearly so: {how} on the {kind} system "
                    f"(too few points per cell for the basis, or weakly supported nodes); use more points "
                    f"per cell, lumped mass, or solver.consistent_fallback = 'blend'",
                    system.weakest_node(right_hand_side(), solution, self._direct))
            if not system.blended:
                self.blended_steps += 1
            system.blend_with(self._blend_target(), self.blend, self._direct)
            self._kept.pop(tuple(system.columns), None)  # the next step factors its own matrix
            solution, converged = self._solve(system, right_hand_side(), kind)
            if not converged:
                tolerance = "" if self._direct else f", CG to solver.cg_tolerance = {self.tolerance:g}"
                raise SingularMassError(f"the blended mass matrix could not be solved either ({kind} system{tolerance})",
                                        system.weakest_node(right_hand_side(), solution, self._direct))
        return solution

    def _singular_near_edges(self, system: "_System") -> bool:
        """Whether CG's system is singular near the bodies' edges (:func:`.singular.singular_near_edges`);
        also CG on kept factors: a matrix that became singular since they were made does not stop it."""
        if (self._direct and system.kept is None) or self.nonnegative or system.blended or self.lattice is None:
            return False
        compiled = isinstance(system.matrix, _CompiledCSR) and system.matrix.upper_start is not None
        return singular_near_edges(system, self.lattice, self.active, self.layer_width,
                                   self._layout.edges if compiled else None)

    def _solve(self, system: "_System", rhs: np.ndarray, kind: str) -> tuple[np.ndarray, bool]:
        if self._direct:
            if system.layout is not None and system.factors is None and not system.blended:
                if system.ldl is not None:  # this step's own L D L^T (.ldl)
                    return system.ldl.solve(rhs), True
                return np.zeros_like(rhs), False  # a pivot said singular
            if system.kept is not None:  # CG preconditioned by an earlier step's factors
                guess = self._initial_guess(rhs, kind, system)
                solution, converged, iterations = system.kept.solve(system.matrix, rhs, guess, self.tolerance)
                self.iterations += iterations
                if converged:
                    return solution, True
                system.kept, system.factors = None, _factor(system.matrix)  # this step's own, and kept
                self._kept.keep(system, self._weak)
            return _direct_solve(system.factors, system.matrix, rhs)
        guess = self._initial_guess(rhs, kind, system)
        tensor = None if self.preconditioner is None else self.preconditioner.scaled(system)
        layer = None if tensor is None else \
            system.boundary_layer(self.preconditioner.lattice_shape, self._weak, self._layer_layouts)
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
        """CG's first guess from this model's history (:func:`.cg.initial_guess`)."""
        # one cut-off for the lumped guess: the lightest body's (only where no history exists)
        tiny = 1e-12 * (self.scale if np.ndim(self.scale) == 0 else self.cells.smallest)
        return initial_guess(self._previous, self._frame, kind, rhs, self.lumped, tiny, system, self.time_step)

    def _blend_target(self) -> np.ndarray:
        """Positive diagonal to blend with (:func:`.weak_rows.mix_target`)."""
        return mix_target(self.lumped, self.matrix.diagonal(), self.active)
