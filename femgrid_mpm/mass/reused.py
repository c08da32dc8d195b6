"""A factorization of the consistent mass kept over many steps, as the preconditioner of CG.

The matrix changes slowly while the points move (its entries are
``m_p N_a(x_p) N_b(x_p)``), so the SuperLU factors of an earlier step's
system ``M_0`` leave ``M_0^-1 M`` close to the identity: CG preconditioned
by them reaches its tolerance in one to three iterations, each a product
with ``M`` and two triangular solves, all in one compiled call.  Factoring
was most of a consistent step below 5000 active nodes (q1 at 1e3-1e4
points: 15-20x lumped per step).

:class:`ReusedFactors` holds the factors and says when they are stale: the
excluded or weak nodes changed (a different system), or the last solve
needed more than :data:`REFACTOR_ITERATIONS` iterations (the matrix drifted
away).  A solve that does not converge within :data:`REUSED_MAX_ITERATIONS`
is not taken: the caller factors the step's own matrix and solves directly,
as :mod:`.direct` always did.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..kernels.arithmetic import fused
from ..kernels.compiled import compiled
from .gauss_seidel import errors_within, zero_columns
from .sparse import _ROW_BY_ROW, _CompiledCSR, _product_dot

#: more iterations than this in a solve with the kept factors: refactor at the next step
#: (each iteration costs a product and two triangular solves; a fresh factorization at
#: 1e3-1e4 points costs tens of them)
REFACTOR_ITERATIONS = 3

#: a solve with the kept factors that has not converged after this many iterations is
#: abandoned for a fresh factorization and a direct solve
REUSED_MAX_ITERATIONS = 12


@dataclass
class ReusedFactors:
    """SuperLU's factors of one system as compiled arrays, and what they were made for.

    ``Pr A Pc = L U`` (scipy's convention): ``A^-1 b = Pc U^-1 L^-1 Pr b``.
    L's unit diagonal is left out; U's diagonal is kept apart.
    """

    lower: tuple  # (indptr, indices, data) of L strictly below the diagonal, by columns
    upper: tuple  # (indptr, indices, data) of U strictly above the diagonal, by columns
    upper_diagonal: np.ndarray
    row_permutation: np.ndarray
    column_permutation: np.ndarray
    excluded: np.ndarray
    weak: np.ndarray
    columns: tuple
    stale: bool = False

    @classmethod
    def of(cls, factors, excluded: np.ndarray, weak: np.ndarray, columns) -> "ReusedFactors":
        # one compiled pass each: scipy's tril and triu went through COO (13 of the 39 ms of a
        # refactorization of cubic splines at 1e4 points)
        n = factors.shape[0]
        lower, upper = (sp.csc_matrix(m) for m in (factors.L, factors.U))
        upper_diagonal = np.zeros(n)
        arrays = [_off_diagonal(m.indptr.astype(np.int64), m.indices.astype(np.int64), m.data.astype(float),
                                diagonal) for m, diagonal in ((lower, np.zeros(n)), (upper, upper_diagonal))]
        return cls(arrays[0], arrays[1], upper_diagonal, factors.perm_r.astype(np.int64),
                   factors.perm_c.astype(np.int64), excluded.copy(), weak.copy(), tuple(columns))

    @classmethod
    def of_ldl(cls, factors, excluded: np.ndarray, weak: np.ndarray, columns) -> "ReusedFactors":
        """The same from a compiled ``L D L^T`` (:class:`.ldl.NumericLDL`): ``U = D L^T`` and
        one permutation both sides, the excluded nodes last with a unit pivot."""
        order, lower_indptr = factors.symbolic.order, factors.symbolic.lower_indptr
        n, free = len(excluded), len(order)
        position = np.empty(n, dtype=np.int64)
        position[order] = np.arange(free)
        position[np.flatnonzero(excluded)] = free + np.arange(n - free)
        indptr = np.concatenate([lower_indptr, np.full(n - free, lower_indptr[-1])])
        diagonal = np.concatenate([factors.pivots, np.ones(n - free)])
        lower = (indptr, factors.lower_rows.astype(np.int64), factors.lower_data.copy())
        return cls(lower, _scaled_transpose(*lower, diagonal), diagonal, position, position.copy(), excluded.copy(),
                   weak.copy(), tuple(columns))

    @property
    def entries(self) -> int:
        """Entries of both factors, diagonal included (the work of a solve with them, per column)."""
        return len(self.lower[1]) + len(self.upper[1]) + len(self.upper_diagonal)

    def arrays(self) -> dict:
        """The factors as named arrays (a checkpoint's; :meth:`from_arrays` takes them back)."""
        names = ("indptr", "indices", "data")
        return {**{f"lower.{name}": array for name, array in zip(names, self.lower)},
                **{f"upper.{name}": array for name, array in zip(names, self.upper)},
                "upper_diagonal": self.upper_diagonal, "row_permutation": self.row_permutation,
                "column_permutation": self.column_permutation, "excluded": self.excluded, "weak": self.weak,
                "columns": np.asarray(self.columns, dtype=np.int64), "stale": np.asarray(self.stale)}

    @classmethod
    def from_arrays(cls, arrays: dict) -> "ReusedFactors":
        names = ("indptr", "indices", "data")
        return cls(tuple(np.array(arrays[f"lower.{name}"]) for name in names),
                   tuple(np.array(arrays[f"upper.{name}"]) for name in names),
                   np.array(arrays["upper_diagonal"]), np.array(arrays["row_permutation"]),
                   np.array(arrays["column_permutation"]), np.array(arrays["excluded"], dtype=bool),
                   np.array(arrays["weak"], dtype=bool), tuple(int(c) for c in arrays["columns"]),
                   bool(arrays["stale"]))

    def fits(self, excluded: np.ndarray, weak: np.ndarray, columns) -> bool:
        """Whether these factors may precondition the system of these excluded and weak nodes."""
        return (not self.stale and tuple(columns) == self.columns and np.array_equal(excluded, self.excluded)
                and np.array_equal(weak, self.weak))

    def solve(self, matrix, rhs: np.ndarray, guess: np.ndarray, tolerance: float) -> tuple[np.ndarray, bool, int]:
        """CG on ``matrix x = rhs`` (rhs (n, k)) preconditioned by these factors, from
        ``guess``: ``(x, converged, iterations)``; marks the factors stale when it took
        more than :data:`REFACTOR_ITERATIONS`."""
        upper_start = matrix.upper_start_or_none() if isinstance(matrix, _CompiledCSR) else _ROW_BY_ROW
        x, converged, iterations = _factor_preconditioned_cg(
            matrix.indptr, matrix.indices, matrix.data, upper_start,
            np.ascontiguousarray(rhs, dtype=float), np.ascontiguousarray(guess, dtype=float), tolerance,
            REUSED_MAX_ITERATIONS, *self.lower, *self.upper, self.upper_diagonal, self.row_permutation,
            self.column_permutation)
        if not converged or iterations > REFACTOR_ITERATIONS:
            self.stale = True
        return x, converged, iterations

    def apply(self, vector: np.ndarray) -> np.ndarray:
        """``A_0^-1 vector`` for vector (n, k): the preconditioner itself."""
        out = np.empty_like(vector)
        _apply_factors(np.ascontiguousarray(vector, dtype=float), out, np.empty_like(vector), *self.lower,
                       *self.upper, self.upper_diagonal, self.row_permutation, self.column_permutation)
        return out


class KeptFactors(dict):
    """The factors kept over the steps, ``{columns: ReusedFactors}``, one per system."""

    def fitting(self, groups, excluded: np.ndarray, weak: np.ndarray) -> "KeptFactors":
        """Those of these systems' columns that still fit them (:meth:`ReusedFactors.fits`)."""
        return KeptFactors({columns: self[columns] for columns in groups
                            if columns in self and self[columns].fits(excluded[:, columns[0]], weak, columns)})

    def fresh(self, groups) -> "KeptFactors":
        """Those of these systems' columns not stale: :meth:`fitting` when the excluded and
        weak nodes are those the kept factors were last checked against."""
        return KeptFactors({columns: self[columns] for columns in groups
                            if columns in self and not self[columns].stale})

    def keep(self, system, weak: np.ndarray) -> None:
        """Keep a freshly factored system's factors for the next steps (none if it is singular)."""
        columns = tuple(system.columns)
        if system.ldl is not None and not system.blended:
            self[columns] = ReusedFactors.of_ldl(system.ldl, system.excluded, weak, columns)
        elif system.factors is None or system.blended:
            self.pop(columns, None)
        else:
            self[columns] = ReusedFactors.of(system.factors, system.excluded, weak, columns)

    def arrays(self) -> dict:
        """The kept factors of each system as a checkpoint's arrays (:meth:`restored`)."""
        return {f"kept.{index}.{name}": array for index, factors in enumerate(self.values())
                for name, array in factors.arrays().items()}

    @classmethod
    def restored(cls, arrays: dict, count: int) -> "KeptFactors":
        """:meth:`arrays` taken back."""
        kept = cls()
        for index in range(count):
            prefix = f"kept.{index}."
            factors = ReusedFactors.from_arrays({name[len(prefix):]: array for name, array in arrays.items()
                                                 if name.startswith(prefix)})
            kept[factors.columns] = factors
        return kept


@compiled()
def _off_diagonal(indptr, indices, data, diagonal):
    """A CSC matrix without its diagonal entries, which go into ``diagonal``; the order of the
    others kept."""
    n = len(indptr) - 1
    kept = np.zeros(n + 1, dtype=np.int64)
    for j in range(n):
        for entry in range(indptr[j], indptr[j + 1]):
            if indices[entry] == j:
                diagonal[j] += data[entry]
            else:
                kept[j + 1] += 1
    out_indptr = np.cumsum(kept)
    out_indices = np.empty(out_indptr[n], dtype=np.int64)
    out_data = np.empty(out_indptr[n])
    for j in range(n):
        slot = out_indptr[j]
        for entry in range(indptr[j], indptr[j + 1]):
            if indices[entry] != j:
                out_indices[slot] = indices[entry]
                out_data[slot] = data[entry]
                slot += 1
    return out_indptr, out_indices, out_data


@compiled()
def _scaled_transpose(indptr, indices, data, scale):
    """``diag(scale) A^T`` by columns, of ``A`` by columns (square): ``U = D L^T`` from ``L``.
    Column ``j`` of the result is row ``j`` of ``A``, each entry ``A[j, i]`` times ``scale[i]``,
    in increasing ``i`` (scipy's transpose and product took 200-320 us at 1e3 points, more than
    the factorization they followed)."""
    n = len(indptr) - 1
    out_indptr = np.zeros(n + 1, dtype=np.int64)
    for entry in range(indptr[n]):
        out_indptr[indices[entry] + 1] += 1
    for j in range(n):
        out_indptr[j + 1] += out_indptr[j]
    filled = out_indptr[:n].copy()
    out_indices = np.empty(indptr[n], dtype=np.int64)
    out_data = np.empty(indptr[n])
    for i in range(n):
        for entry in range(indptr[i], indptr[i + 1]):
            j = indices[entry]
            out_indices[filled[j]] = i
            out_data[filled[j]] = data[entry] * scale[i]
            filled[j] += 1
    return out_indptr, out_indices, out_data


@compiled()
def _apply_factors(r, z, work, lower_indptr, lower_indices, lower_data, upper_indptr, upper_indices, upper_data,
                   upper_diagonal, row_permutation, column_permutation):
    """``z = Pc U^-1 L^-1 Pr r`` column by column (``work`` of r's shape).

    Two columns take a loop of their own, its positions unsigned (numba tests a signed
    index for Python's wraparound on every access): the triangular solves are most of
    an iteration, their factors holding ~5x the matrix's entries."""
    n, k = r.shape
    for i in range(n):
        for c in range(k):
            work[row_permutation[i], c] = r[i, c]
    if k == 2:
        for j in range(n):  # L (unit diagonal) by columns, forward
            w0 = work[j, 0]
            w1 = work[j, 1]
            for entry in range(np.uint64(lower_indptr[j]), np.uint64(lower_indptr[j + 1])):
                i = np.uint64(lower_indices[entry])
                d = lower_data[entry]
                work[i, 0] = fused(-d, w0, work[i, 0])
                work[i, 1] = fused(-d, w1, work[i, 1])
        for j in range(n - 1, -1, -1):  # U by columns, backward
            w0 = work[j, 0] / upper_diagonal[j]
            w1 = work[j, 1] / upper_diagonal[j]
            work[j, 0] = w0
            work[j, 1] = w1
            for entry in range(np.uint64(upper_indptr[j]), np.uint64(upper_indptr[j + 1])):
                i = np.uint64(upper_indices[entry])
                d = upper_data[entry]
                work[i, 0] = fused(-d, w0, work[i, 0])
                work[i, 1] = fused(-d, w1, work[i, 1])
    else:
        for j in range(n):
            for entry in range(lower_indptr[j], lower_indptr[j + 1]):
                i = lower_indices[entry]
                for c in range(k):
                    work[i, c] = fused(-lower_data[entry], work[j, c], work[i, c])
        for j in range(n - 1, -1, -1):
            for c in range(k):
                work[j, c] = work[j, c] / upper_diagonal[j]
            for entry in range(upper_indptr[j], upper_indptr[j + 1]):
                i = upper_indices[entry]
                for c in range(k):
                    work[i, c] = fused(-upper_data[entry], work[j, c], work[i, c])
    for i in range(n):
        for c in range(k):
            z[i, c] = work[column_permutation[i], c]


@compiled()
def _factor_preconditioned_cg(indptr, indices, data, upper_start, b, x0, rtol, max_iterations,
                              lower_indptr, lower_indices, lower_data, upper_indptr, upper_indices, upper_data,
                              upper_diagonal, row_permutation, column_permutation):
    """CG on the columns of ``b`` (n, k) at once, preconditioned by kept LU factors
    (:func:`_apply_factors`).  Converged: in every column the preconditioned residual
    ``z = M_0^-1 r``, close to the error of ``x`` since ``M_0`` is close to ``M``, is
    within ``rtol max|x|`` at every node.  It is measured in velocity, not in force:
    with bodies 1e12 apart in mass, a residual relative to ``|b|`` is the heavy body's
    alone and left the light one's velocities wrong by 6e-4 of themselves.  A
    non-positive curvature or ``r.z`` stops it as not converged."""
    n, k = b.shape
    x = x0.copy()
    zero_columns(b, x)
    r = np.empty_like(b)
    _product_dot(indptr, indices, data, upper_start, x, r, np.zeros(k))
    z = np.empty_like(b)
    p = np.zeros_like(b)  # the first direction is z: beta = 0 times this
    Ap = np.empty_like(b)
    work = np.empty_like(b)
    rz = np.zeros(k)
    curvature = np.zeros(k)
    for i in range(n):
        for c in range(k):
            r[i, c] = b[i, c] - r[i, c]
    for iteration in range(max_iterations + 1):
        _apply_factors(r, z, work, lower_indptr, lower_indices, lower_data, upper_indptr, upper_indices, upper_data,
                       upper_diagonal, row_permutation, column_permutation)
        error = np.zeros(k)  # largest |z| and |x| per column
        size = np.zeros(k)
        for i in range(n):
            for c in range(k):
                error[c] = max(error[c], abs(z[i, c]))
                size[c] = max(size[c], abs(x[i, c]))
        if errors_within(error, size, rtol):
            return x, True, iteration
        if iteration == max_iterations:
            break
        rz_new = np.zeros(k)
        for i in range(n):
            for c in range(k):
                rz_new[c] = fused(r[i, c], z[i, c], rz_new[c])
        for c in range(k):
            if rz_new[c] < 0.0 or (rz_new[c] == 0.0 and error[c] > rtol * size[c]):
                return x, False, iteration
        for c in range(k):
            beta = rz_new[c] / rz[c] if iteration > 0 and rz[c] != 0.0 else 0.0
            rz[c] = rz_new[c]
            for i in range(n):
                p[i, c] = fused(beta, p[i, c], z[i, c])
        _product_dot(indptr, indices, data, upper_start, p, Ap, curvature)
        for c in range(k):
            if curvature[c] <= 0.0 and rz[c] != 0.0:
                return x, False, iteration
        for c in range(k):
            alpha = rz[c] / curvature[c] if curvature[c] > 0.0 else 0.0
            for i in range(n):
                x[i, c] = fused(alpha, p[i, c], x[i, c])
                r[i, c] = fused(-alpha, Ap[i, c], r[i, c])
    return x, False, max_iterations
