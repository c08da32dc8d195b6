"""Preconditioned conjugate gradients on the consistent mass, both components at once,
and its first guess from the last steps' solutions."""

from __future__ import annotations

import numpy as np

from ..kernels.arithmetic import fused
from ..kernels.compiled import compiled
from .gauss_seidel import gauss_seidel_cg, sweeps_apply
from .preconditioners import BoundaryLayer, _apply_tensor, _layer_sweep
from .sparse import _CompiledCSR, _product_dot


_NO_TENSOR = (False, np.zeros(1), np.zeros(1, dtype=bool), np.zeros((4, 1)), np.zeros((4, 1)))


def _preconditioned_cg(A, b, x0, inverse_diagonal, rtol, max_iterations, tensor=None, layer=None):
    """Preconditioned CG on the columns of ``b`` (n, k) at once: symmetric Gauss-Seidel
    where the matrix is stored as its sweeps read it (:mod:`.gauss_seidel`, its own test of
    convergence), else Jacobi, or the arguments of :func:`_apply_tensor` (``tensor``),
    completed by a :class:`BoundaryLayer` (``layer``).

    Returns ``(x, converged, iterations)``.  Converged means every column's
    residual fell to ``rtol * |b|``.  A non-positive curvature ``p.A.p``
    (singular matrix met by an inconsistent right-hand side) stops the
    iteration as not converged (False); a negative ``r.z`` (a preconditioner
    that is not positive definite) stops it with ``converged = None``.
    """
    if tensor is None and layer is None and sweeps_apply(A):
        return gauss_seidel_cg(A, b, x0, rtol, max_iterations, inverse_diagonal)
    if isinstance(A, _CompiledCSR) and isinstance(layer, BoundaryLayer):
        x, state, iterations = _layered_cg(A.indptr, A.indices, A.data, A.upper_start_or_none(),
                                           np.ascontiguousarray(b, dtype=float), np.ascontiguousarray(x0, dtype=float),
                                           rtol, max_iterations, *layer.arguments(), *tensor)
        return x, (None if state < 0 else bool(state)), iterations
    if isinstance(A, _CompiledCSR) and layer is None:
        return _compiled_cg(A.indptr, A.indices, A.data, A.upper_start_or_none(), np.ascontiguousarray(b, dtype=float),
                            np.ascontiguousarray(x0, dtype=float), inverse_diagonal, rtol, max_iterations,
                            *(_NO_TENSOR if tensor is None else (True, *tensor)))

    def precondition(r):
        if tensor is None:
            return inverse_diagonal[:, None] * r
        if layer is None:
            return _apply_tensor(np.ascontiguousarray(r), np.empty_like(r), *tensor)
        return layer.sweep(r, tensor)

    # the vector updates in compiled passes (numpy's temporaries took as long as the products)
    b = np.ascontiguousarray(b, dtype=float)
    x = np.array(x0, dtype=float)
    target = _target(b, rtol)
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


@compiled()
def _layered_cg(indptr, indices, data, upper_start, b, x0, rtol, max_iterations, nodes, rows_indptr, rows_indices,
                rows_data, order, lower_indptr, lower_rows, lower_data, pivots, scale, excluded, factor_x, factor_y):
    """:func:`_preconditioned_cg`'s loop with a :class:`.BoundaryLayer`, compiled: the same
    compiled passes in the same order, so bit for bit the Python loop, which runs for scipy's
    matrices (the scipy engine's); from Python its calls and temporaries took ~0.55 ms of cubic
    splines' 5.2 ms step at 1e4 points.  ``converged`` as 1, 0 or -1 (None)."""
    n, k = b.shape
    target = _target(b, rtol)
    x = x0.copy()
    product = np.empty((n, k))
    _product_dot(indptr, indices, data, upper_start, x, product, np.zeros(k))
    r = b - product
    residual = _column_dots(r, r)
    if np.all(np.sqrt(residual) <= target):  # the first guess is the solution: no preconditioning
        return x, 1, 0
    z = _layer_sweep(r, nodes, rows_indptr, rows_indices, rows_data, order, lower_indptr, lower_rows, lower_data,
                     pivots, scale, excluded, factor_x, factor_y)
    p = z.copy()
    rz = _column_dots(r, z)
    if np.any(rz < 0):
        return x, -1, 0
    Ap = np.empty((n, k))
    curvature = np.zeros(k)
    alpha = np.zeros(k)
    beta = np.zeros(k)
    for iteration in range(max_iterations + 1):
        if not np.any(rz != 0):
            return x, 1, iteration
        if iteration == max_iterations:
            break
        curvature[:] = 0.0
        _product_dot(indptr, indices, data, upper_start, p, Ap, curvature)
        for c in range(k):
            if curvature[c] <= 0.0 and rz[c] != 0.0:
                return x, 0, iteration
        for c in range(k):
            alpha[c] = rz[c] / curvature[c] if curvature[c] > 0.0 else 0.0
        _cg_advance(x, r, p, Ap, alpha, residual)
        if np.all(np.sqrt(residual) <= target):  # converged: the preconditioner's sweep would go unused
            return x, 1, iteration + 1
        z = _layer_sweep(r, nodes, rows_indptr, rows_indices, rows_data, order, lower_indptr, lower_rows,
                         lower_data, pivots, scale, excluded, factor_x, factor_y)
        rz_new = _column_dots(r, z)
        if np.any(rz_new < 0):
            return x, -1, iteration + 1
        for c in range(k):
            beta[c] = rz_new[c] / rz[c] if rz[c] != 0.0 else 0.0
        _cg_direction(p, z, beta)
        rz = rz_new
    return x, 0, max_iterations


@compiled(forceinline=True)
def _precondition(r, z, use_tensor, inverse_diagonal, scale, excluded, factor_x, factor_y):
    """``z = P^-1 r``: the splines' tensor Gram preconditioner, or Jacobi."""
    if use_tensor:
        _apply_tensor(r, z, scale, excluded, factor_x, factor_y)
    else:
        for i in range(r.shape[0]):
            for c in range(r.shape[1]):
                z[i, c] = inverse_diagonal[i] * r[i, c]


@compiled()
def _target(b, rtol):
    """``rtol |b[:, c]|`` for each column, the squares summed in order, as :func:`_compiled_cg`
    sums them (numpy's norm along the rows does for two columns; for one it sums pairwise, and
    the loops would then stop differently where a residual met the target within a rounding)."""
    target = np.zeros(b.shape[1])
    for i in range(b.shape[0]):
        for c in range(b.shape[1]):
            target[c] += b[i, c] * b[i, c]
    return rtol * np.sqrt(target)


@compiled(forceinline=True)
def _all_within(residual, target):
    """Whether every column's squared residual norm is within its target norm."""
    for c in range(residual.shape[0]):
        if np.sqrt(residual[c]) > target[c]:
            return False
    return True


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


#: CG's first guess (:func:`initial_guess`): the lumped solution; the last
#: solution; two solutions extrapolated; the last velocity advanced by its acceleration
GUESS_LUMPED, GUESS_LAST, GUESS_EXTRAPOLATED, GUESS_ADVANCED = range(4)


@compiled()
def _guess(mode, rhs, lumped, tiny, inverse_diagonal, first, second, dt, shift, columns, excluded):
    """CG's first guess on the system's columns, one or two (one pass; numpy's where-chains
    took ~0.5 ms a solve at 27,000 nodes).  ``first``/``second``: the last and the older
    solution (extrapolated), the last velocity and acceleration (advanced), as (n_nodes, 2)
    arrays of all columns.  A node takes the history's value where the history knows it
    (nonzero), the lumped solution ``rhs / m_i`` elsewhere, zero where excluded.  The
    columns and the shift are locals (one column: taken twice), as numba would load array
    elements again after every store of the guess: 3.5x faster at 1e6 points than a loop
    over the columns, and one loop to compile."""
    n, k = rhs.shape
    if k > 2:
        raise ValueError("a system solves one or two velocity components")
    guess = np.empty((n, k))
    j0, j1 = columns[0], columns[k - 1]
    h0, h1 = shift[0], shift[k - 1]
    last = k - 1
    for i in range(n):
        if excluded[i]:
            guess[i, 0] = 0.0
            guess[i, last] = 0.0
            continue
        f0, f1 = (first[i, j0], first[i, j1]) if mode != GUESS_LUMPED else (0.0, 0.0)
        if mode == GUESS_ADVANCED:
            s0, s1 = second[i, j0], second[i, j1]
            known = (f0 != 0.0) | (f1 != 0.0) | (s0 != 0.0) | (s1 != 0.0)
            g0, g1 = f0 + dt * s0 + h0, f1 + dt * s1 + h1
        elif mode == GUESS_EXTRAPOLATED:
            s0, s1 = second[i, j0], second[i, j1]
            known = ((s0 != 0.0) & (f0 != 0.0)) | ((s1 != 0.0) & (f1 != 0.0))
            g0, g1 = 2.0 * f0 - s0, 2.0 * f1 - s1
        else:
            known = mode == GUESS_LAST and ((f0 != 0.0) | (f1 != 0.0))
            g0, g1 = f0, f1
        if not known:
            scale = lumped[i] if abs(lumped[i]) > tiny else 1.0 / inverse_diagonal[i]
            g0, g1 = rhs[i, 0] / scale, rhs[i, last] / scale
        guess[i, 0] = g0
        guess[i, last] = g1
    return guess


def initial_guess(previous: dict, frame: np.ndarray | None, kind: str, rhs: np.ndarray, lumped: np.ndarray,
                  tiny: float, system, time_step: float | None) -> np.ndarray:
    """CG's first guess for one system of the consistent mass.

    The velocity: the last step's grid velocity advanced by its acceleration,
    ``v + dt a`` (in this step's frame), which the points' own update makes
    exact while the points keep their places (at 1e5 points CG then takes
    2 iterations instead of ~11 for q1 and q2, 9 instead of ~12 for cubic
    splines, whose weakly supported nodes are lumped).  Otherwise linear extrapolation of
    the last two solutions where they exist; the lumped solution elsewhere
    (for a rigid motion that is already exact).  ``previous`` is the history
    (the last two solutions of each kind, and the frame of the velocities in it),
    ``frame`` this step's frame, ``tiny`` the mass below which ``lumped`` is not divided by.
    """
    history = previous.get(kind, ())
    accelerations = previous.get("acceleration", ())
    columns = np.asarray(system.columns, dtype=np.int64)
    none = np.zeros((0, 2))
    if (kind == "velocity" and history and accelerations and "frame" in previous and time_step
            and frame is not None):
        mode, first, second = GUESS_ADVANCED, history[-1], accelerations[-1]
        shift = (previous["frame"][0][0] - frame)[columns]
    elif len(history) == 2:
        (mode, first, second), shift = (GUESS_EXTRAPOLATED, history[1], history[0]), np.zeros(len(columns))
    elif len(history) == 1:
        (mode, first, second), shift = (GUESS_LAST, history[0], none), np.zeros(len(columns))
    else:
        (mode, first, second), shift = (GUESS_LUMPED, none, none), np.zeros(len(columns))
    return _guess(mode, rhs, lumped, tiny, system.inverse_diagonal, first, second, float(time_step or 0.0), shift,
                  columns, system.excluded)
