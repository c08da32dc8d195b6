"""CG on the consistent mass preconditioned by symmetric Gauss-Seidel, in Eisenstat's form.

A mass matrix is well conditioned but not diagonal: Jacobi leaves CG 9-24 iterations on an
acceleration (q1, q2, serendipity, gimp at 1e4-1e5 points), the couplings of each node to
its neighbours unresolved.  Symmetric Gauss-Seidel, ``P = (D + L) D^-1 (D + U)`` with
``A = L + D + U``, resolves them in one sweep down the nodes and one back up: 4-11
iterations on the same systems.  ``P - A = L D^-1 U`` is positive semi-definite, so the
eigenvalues of ``P^-1 A`` lie in (0, 1].

Eisenstat's form makes an iteration cost one pass over the matrix, as Jacobi's does,
instead of a product and two sweeps.  CG runs on ``C^-1 A C^-T`` with ``P = C C^T``,
``C = (D + L) D^-1/2``, whose product with a direction ``p^`` is, for ``t = C^-T p^``
(one sweep up), ``D^1/2 (t + (D + L)^-1 (D^1/2 p^ - D t))`` (one sweep down), because
``A = (D + L) + (D + U) - D``.  ``t`` is the direction in the unknowns' own space, so the
solution is updated there directly, and the preconditioned residual ``z = P^-1 r`` of
standard PCG is ``t_k - beta_k t_(k-1)``: the test below costs nothing.  The arrays kept
are scaled by ``D^1/2`` (``q = D^1/2 p^``, ``s = D^1/2 r^``), so no square root is taken.
An iteration is the two sweeps and nothing else: CG's step along the last direction (``x +=
alpha t``, ``r^ -= alpha A^ p^``) rides on the next sweep up, whose ``beta`` comes from sums of
the sweep down (``|r^ - alpha A^ p^|^2`` expanded).  That saves a pass over the nodes where
they do not fit the cache (q1 at 1e6 points: a step 109 -> 102 ms, with the first guess's
faster pass) and costs ~4% more an iteration where they do (1e5: 0.38 -> 0.40 ms).

Converged: in every column ``max |z| <= rtol max |x|``, ``z`` close to the error of ``x``
(as in :mod:`.reused`): the velocities are accurate to ``rtol`` of the largest,
whatever the bodies' masses (``z`` is the error times ``P^-1 A``: below it by up to the
smallest eigenvalue of ``P^-1 A``, docs/performance.md).  Both sweeps read the entries after
each row's diagonal only: the mass pattern's stored half, in stencil order (``upper_start``,
:class:`.sparse._CompiledCSR`), or the upper triangle of a CSR matrix with sorted columns
(:func:`sweep_layout`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..kernels.arithmetic import fused
from ..kernels.compiled import compiled
from .ldl import _diagonal_index
from .sparse import _ROW_BY_ROW, _CompiledCSR, _product_dot


#: a solve's work in products with the matrix: its start (the residual's pass down and the
#: first sweep up) and each iteration (a sweep each way, with CG's step).  Fitted to the solves
#: of 60 steps (time against iterations), two columns: start 1.5-2.8 and iteration 1.2-1.5
#: products for q1, q2, serendipity, gimp and quadratic splines at 1e4 points and q1 on the
#: cantilever at h = 0.0625 (a product 31-75 us)
START_WORK = 2.0
ITERATION_WORK = 1.4


def cg_work(solves: int, iterations: int) -> float:
    """The work of ``solves`` solves taking ``iterations`` in all, in products with the matrix."""
    return START_WORK * solves + ITERATION_WORK * iterations


def sweep_layout(matrix) -> "tuple[np.ndarray, np.ndarray] | None":
    """Where the sweeps find each row's diagonal, and the product's half (empty: row by row), or
    None where they cannot sweep: the mass pattern's matrix (its stored half, in stencil order,
    each row's later columns after its diagonal) or any CSR matrix with sorted columns and every
    diagonal stored (the scipy path's, a blended one: the entries after a row's diagonal are its
    upper triangle)."""
    if isinstance(matrix, _CompiledCSR) and matrix.upper_start is not None:
        return (matrix.upper_start, matrix.upper_start) if matrix.upper_ordered else None
    if not sp.issparse(matrix) or matrix.format != "csr" or not matrix.has_sorted_indices:
        return None
    diagonal = _diagonal_index(matrix.indptr, matrix.indices)
    return None if len(diagonal) and diagonal.min() < 0 else (diagonal, _ROW_BY_ROW)


def sweeps_apply(matrix) -> bool:
    """Whether CG on ``matrix`` takes symmetric Gauss-Seidel (:func:`sweep_layout`)."""
    return sweep_layout(matrix) is not None


def gauss_seidel_cg(matrix, b: np.ndarray, x0: np.ndarray, rtol: float, max_iterations: int,
                    inverse_diagonal: np.ndarray | None = None) -> tuple[np.ndarray, bool, int]:
    """CG on ``matrix x = b`` (b (n, k)) from ``x0``: ``(x, converged, iterations)``; a
    non-positive curvature (a singular matrix) stops it as not converged.  ``inverse_diagonal``:
    ``1 / diag(matrix)`` where the caller has it (a system's, made with it)."""
    diagonal, half = sweep_layout(matrix)
    if inverse_diagonal is None:
        inverse_diagonal = 1.0 / matrix.data[diagonal]
    return _gauss_seidel_cg(matrix.indptr, matrix.indices, matrix.data, diagonal, half, inverse_diagonal,
                            np.ascontiguousarray(b, dtype=float), np.ascontiguousarray(x0, dtype=float),
                            rtol, max_iterations)


@compiled(forceinline=True)
def zero_columns(b, x):
    """``x``'s columns zero where ``b``'s are (a zero right-hand side: the solution is zero)."""
    n, k = b.shape
    for c in range(k):
        zero = True
        for i in range(n):
            if b[i, c] != 0.0:
                zero = False
        if zero:
            for i in range(n):
                x[i, c] = 0.0


@compiled(forceinline=True)
def errors_within(error, size, rtol) -> bool:
    """Whether every column's largest error estimate is within ``rtol`` of its largest value (NaN: not)."""
    for c in range(error.shape[0]):
        if not error[c] <= rtol * size[c]:
            return False
    return True


@compiled()
def _gauss_seidel_cg(indptr, indices, data, upper_start, half, inverse, b, x0, rtol, max_iterations):
    n, k = b.shape
    x = x0.copy()
    zero_columns(b, x)
    s = np.empty_like(b)  # D^1/2 r^ = D (D + L)^-1 r
    if k == 2 and half.shape[0] > 0:
        _residual_down(indptr, indices, data, upper_start, inverse, b, x, s)
    else:
        _product_dot(indptr, indices, data, half, x, s, np.zeros(k))
        for i in range(n):
            for c in range(k):
                s[i, c] = b[i, c] - s[i, c]
        _sweep_down(indptr, indices, data, upper_start, inverse, s, s, s, s, False, np.zeros((3, k)))
    rr = np.zeros(k)  # r^ . r^
    size = np.zeros(k)  # max |x|
    q = np.empty_like(b)  # D^1/2 p^, s at the first sweep up (beta 0)
    t = np.empty_like(b)  # C^-T p^, the direction of x
    previous = np.empty_like(b)  # the last direction t (not read at the first sweep: zeroing it, and q,
    # took 2 memsets of 16 MB a solve, 4 a step, for q2 at 1e6 points)
    u = np.empty_like(b)  # q - D t, then D^1/2 A^ p^
    alpha = np.zeros(k)
    beta = np.zeros(k)
    error = np.zeros(k)
    sums = np.zeros((3, k))  # p^ . A^ p^, r^ . A^ p^ and |A^ p^|^2, per column
    _sweep_up(indptr, indices, data, upper_start, inverse, q, s, alpha, beta, t, previous, u, x, False, rr,
              size, error)
    for iteration in range(max_iterations + 1):
        if errors_within(error, size, rtol):
            return x, True, iteration
        if iteration == max_iterations:
            break
        _sweep_down(indptr, indices, data, upper_start, inverse, u, t, q, s, True, sums)
        for c in range(k):
            if sums[0, c] <= 0.0 and rr[c] != 0.0:
                return x, False, iteration
            # the next r^ . r^ from this pass's sums, so that the step and the next sweep up are
            # one pass: |r^ - alpha A^ p^|^2 expanded.  It loses the digits of rr / rr_next
            # (a few per iteration) and sets beta only: the sweep up computes rr afresh for alpha
            alpha[c] = rr[c] / sums[0, c] if sums[0, c] > 0.0 else 0.0
            following = rr[c] - 2.0 * alpha[c] * sums[1, c] + alpha[c] * alpha[c] * sums[2, c]
            beta[c] = max(following, 0.0) / rr[c] if rr[c] != 0.0 else 0.0
        t, previous = previous, t
        _sweep_up(indptr, indices, data, upper_start, inverse, q, s, alpha, beta, t, previous, u, x, True, rr,
                  size, error)
    return x, False, max_iterations


@compiled(forceinline=True)
def _residual_down(indptr, indices, data, upper_start, inverse, b, x, w):
    """``w = (D + L)^-1 (b - A x)`` for two columns in one pass down the stored half: row ``i``
    gathers its later columns' ``a_ij x_j``, has every earlier row's ``a_li (x_l + w_l)`` already,
    and passes on ``a_ij (x_i + w_i)``: the product's and the sweep's scatters are one (a product
    and a sweep read the matrix twice; at 1e6 points the passes are bound by memory)."""
    n = x.shape[0]
    one = np.uint64(1)
    for i in range(n):
        w[i, 0] = 0.0
        w[i, 1] = 0.0
    for i in range(n):
        diagonal = np.uint64(upper_start[i])
        stop = np.uint64(indptr[i + 1])
        x0 = x[i, 0]
        x1 = x[i, 1]
        a0 = data[diagonal] * x0
        a1 = data[diagonal] * x1
        for entry in range(diagonal + one, stop):
            j = np.uint64(indices[entry])
            a0 = fused(data[entry], x[j, 0], a0)
            a1 = fused(data[entry], x[j, 1], a1)
        w0 = ((b[i, 0] - a0) - w[i, 0]) * inverse[i]
        w1 = ((b[i, 1] - a1) - w[i, 1]) * inverse[i]
        w[i, 0] = w0
        w[i, 1] = w1
        y0 = x0 + w0
        y1 = x1 + w1
        for entry in range(diagonal + one, stop):
            j = np.uint64(indices[entry])
            w[j, 0] = fused(data[entry], y0, w[j, 0])
            w[j, 1] = fused(data[entry], y1, w[j, 1])


@compiled(forceinline=True)
def _sweep_down(indptr, indices, data, upper_start, inverse, v, t, q, s, product, sums):
    """``v = (D + L)^-1 v`` in place, ``L`` the transpose of the stored upper half: each
    finished unknown scattered down its row's later columns, the nearest first (the next
    row waits on it).  ``product``: then ``v = D (t + v)`` (``v`` was ``q - D t``: ``D^1/2 A^
    p^``) and ``sums`` ``p^ . A^ p^``, ``r^ . A^ p^`` and ``A^ p^ . A^ p^`` per column (``s`` is
    ``D^1/2 r^``)."""
    n, k = v.shape
    one = np.uint64(1)
    if k == 2:
        c0, c1, g0, g1, h0, h1 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        for i in range(n):
            v0 = v[i, 0] * inverse[i]
            v1 = v[i, 1] * inverse[i]
            for entry in range(np.uint64(upper_start[i]) + one, np.uint64(indptr[i + 1])):
                j = np.uint64(indices[entry])
                d = data[entry]
                v[j, 0] = fused(-d, v0, v[j, 0])
                v[j, 1] = fused(-d, v1, v[j, 1])
            if product:
                d = data[upper_start[i]]
                v0 = d * (t[i, 0] + v0)
                v1 = d * (t[i, 1] + v1)
                w0 = v0 * inverse[i]
                w1 = v1 * inverse[i]
                c0 = fused(q[i, 0], w0, c0)
                c1 = fused(q[i, 1], w1, c1)
                g0 = fused(s[i, 0], w0, g0)
                g1 = fused(s[i, 1], w1, g1)
                h0 = fused(v0, w0, h0)
                h1 = fused(v1, w1, h1)
            v[i, 0] = v0
            v[i, 1] = v1
        sums[0, 0], sums[0, 1], sums[1, 0], sums[1, 1], sums[2, 0], sums[2, 1] = c0, c1, g0, g1, h0, h1
        return
    sums[:, :] = 0.0
    for i in range(n):
        for c in range(k):
            v[i, c] *= inverse[i]
        for entry in range(np.uint64(upper_start[i]) + one, np.uint64(indptr[i + 1])):
            j = np.uint64(indices[entry])
            for c in range(k):
                v[j, c] = fused(-data[entry], v[i, c], v[j, c])
        if product:
            for c in range(k):
                v[i, c] = data[upper_start[i]] * (t[i, c] + v[i, c])
                w = v[i, c] * inverse[i]
                sums[0, c] = fused(q[i, c], w, sums[0, c])
                sums[1, c] = fused(s[i, c], w, sums[1, c])
                sums[2, c] = fused(v[i, c], w, sums[2, c])


@compiled(forceinline=True)
def _sweep_up(indptr, indices, data, upper_start, inverse, q, s, alpha, beta, t, previous, u, x, step, rr, size,
              error):
    """One pass up the rows, from the last.  ``step``: first CG's step along the last
    direction (``previous``), ``x += alpha previous`` and ``s -= alpha u`` (``u`` is ``D^1/2 A^
    p^``); otherwise ``s`` becomes ``D s`` (the start: ``s`` held ``(D + L)^-1 r``).  Then
    ``rr`` is ``r^ . r^`` and ``size`` the largest ``|x|``.  Then the next direction ``q = s +
    beta q``, ``t = (D + U)^-1 q``, ``u = q - D t`` (for :func:`_sweep_down`), and ``error``
    the largest ``|t - beta previous|`` per column (``z = P^-1 r``).  A row's later columns are
    taken from the farthest: the nearest, just solved, comes last, off the other terms' path."""
    n, k = q.shape
    one = np.uint64(1)
    if k == 2:
        e0, e1, r0, r1, m0, m1 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        for i in range(n - 1, -1, -1):
            d = data[upper_start[i]]
            if step:
                x0 = fused(alpha[0], previous[i, 0], x[i, 0])
                x1 = fused(alpha[1], previous[i, 1], x[i, 1])
                x[i, 0] = x0
                x[i, 1] = x1
                s0 = fused(-alpha[0], u[i, 0], s[i, 0])
                s1 = fused(-alpha[1], u[i, 1], s[i, 1])
            else:
                x0 = x[i, 0]
                x1 = x[i, 1]
                s0 = s[i, 0] * d
                s1 = s[i, 1] * d
            s[i, 0] = s0
            s[i, 1] = s1
            m0 = max(m0, abs(x0))
            m1 = max(m1, abs(x1))
            r0 = fused(s0, s0 * inverse[i], r0)
            r1 = fused(s1, s1 * inverse[i], r1)
            if step:
                q0 = fused(beta[0], q[i, 0], s0)
                q1 = fused(beta[1], q[i, 1], s1)
            else:  # the first direction: the residual (+ 0.0: as beta 0 times a zero direction added)
                q0 = s0 + 0.0
                q1 = s1 + 0.0
            q[i, 0] = q0
            q[i, 1] = q1
            t0 = q0
            t1 = q1
            first = np.uint64(upper_start[i]) + one
            entry = np.uint64(indptr[i + 1])
            while entry > first:
                entry -= one
                j = np.uint64(indices[entry])
                a = data[entry]
                t0 = fused(-a, t[j, 0], t0)
                t1 = fused(-a, t[j, 1], t1)
            t0 *= inverse[i]
            t1 *= inverse[i]
            t[i, 0] = t0
            t[i, 1] = t1
            u[i, 0] = fused(-d, t0, q0)
            u[i, 1] = fused(-d, t1, q1)
            e0 = max(e0, abs(fused(-beta[0], previous[i, 0], t0)) if step else abs(t0))
            e1 = max(e1, abs(fused(-beta[1], previous[i, 1], t1)) if step else abs(t1))
        error[0], error[1], rr[0], rr[1], size[0], size[1] = e0, e1, r0, r1, m0, m1
        return
    error[:] = 0.0
    rr[:] = 0.0
    size[:] = 0.0
    for i in range(n - 1, -1, -1):
        d = data[upper_start[i]]
        for c in range(k):
            if step:
                x[i, c] = fused(alpha[c], previous[i, c], x[i, c])
                s[i, c] = fused(-alpha[c], u[i, c], s[i, c])
            else:
                s[i, c] *= d
            size[c] = max(size[c], abs(x[i, c]))
            rr[c] = fused(s[i, c], s[i, c] * inverse[i], rr[c])
            q[i, c] = fused(beta[c], q[i, c], s[i, c]) if step else s[i, c] + 0.0
            t[i, c] = q[i, c]
        entry = np.uint64(indptr[i + 1])
        while entry > np.uint64(upper_start[i]) + one:
            entry -= one
            j = np.uint64(indices[entry])
            for c in range(k):
                t[i, c] = fused(-data[entry], t[j, c], t[i, c])
        for c in range(k):
            t[i, c] *= inverse[i]
            u[i, c] = fused(-d, t[i, c], q[i, c])
            error[c] = max(error[c], abs(fused(-beta[c], previous[i, c], t[i, c])) if step else abs(t[i, c]))

