"""The consistent solve's node-wise passes over (n, k) arrays, compiled.

numpy broadcasts a node's array against a column of the frame row by row: ``p + m[:, None] * v``
over 3025 nodes took 28 us, a tenth of a q1 consistent step at 1e4 points, and
``np.where(excluded[:, None], 0, rhs[:, columns])`` 11 us; one compiled pass takes 2-3 us.  The
arithmetic is numpy's, operation by operation (no fused products): the results are the same bits.
"""

from __future__ import annotations

import numpy as np

from ..kernels.compiled import compiled


@compiled()
def in_frame(relative, lumped, frame):
    """``relative + lumped[:, None] * frame``: the momentum ``p_rel + m v_ref``."""
    n, k = relative.shape
    out = np.empty((n, k))
    for i in range(n):
        for c in range(k):
            out[i, c] = relative[i, c] + lumped[i] * frame[c]
    return out


@compiled()
def plus_row(values, row):
    """``values + row[None, :]``: a velocity relative to the frame made absolute."""
    n, k = values.shape
    out = np.empty((n, k))
    for i in range(n):
        for c in range(k):
            out[i, c] = values[i, c] + row[c]
    return out


@compiled()
def free_part(values, columns, excluded):
    """``values[:, columns]`` (one or two columns) with the excluded rows zero, and whether any
    entry is nonzero.  The columns are locals (one column: taken twice): numba would load them
    again after every store of ``out``."""
    n, k = values.shape[0], len(columns)
    out = np.empty((n, k))
    nonzero = False
    j0, j1, last = columns[0], columns[k - 1], k - 1
    for i in range(n):
        keep = not excluded[i]
        first = values[i, j0] if keep else 0.0
        second = values[i, j1] if keep else 0.0
        out[i, 0] = first
        out[i, last] = second
        nonzero |= (first != 0.0) | (second != 0.0)
    return out, nonzero
