"""What the kernels are specialised on stays fixed per form, so a first run compiles each once.

numba compiles a kernel afresh for every new combination of its arguments' types: an array's
memory order (C, Fortran or strided) and a tuple's length are part of the type.  A strided
column of the excluded nodes, SuperLU's solution in Fortran order and a shorter numbering
tuple on a grid one element tall each made a second compilation of kernels that already had
one (G2P, the guesses, the node-wise passes; serendipity's three passes), ~30 of the 143 CPU
seconds ``reproduce`` compiled (``python benchmarks/compile_time.py --only reproduce --kernels``).
"""

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from femgrid_mpm import Grid
from femgrid_mpm.kernels.tables import separated_tables
from femgrid_mpm.mass.direct import _direct_solve
from femgrid_mpm.mass.layout import SystemsLayout


def test_each_systems_column_of_excluded_nodes_is_contiguous():
    """With supports (each component fixed on its own nodes) and without: the column a system
    takes, ``excluded[:, c]``, is a contiguous read-only array, the type the kernels compiled for."""
    rng = np.random.default_rng(3)
    active, weak = rng.random(50) > 0.2, np.zeros(50, dtype=bool)
    fixed = rng.random((50, 2)) > 0.8
    for layout in (SystemsLayout.of(active, weak, None, "auto"), SystemsLayout.of(active, weak, fixed, "auto")):
        for c in (0, 1):
            column = layout.excluded[:, c]
            assert column.flags.c_contiguous and not column.flags.writeable
    layout = SystemsLayout.of(active, weak, fixed, "auto")
    np.testing.assert_array_equal(layout.excluded, ~active[:, None] | fixed)  # the same nodes
    assert layout.groups == [(0,), (1,)]


def test_superlus_solution_is_handed_on_in_row_order():
    """SuperLU solves a two-column right-hand side into a Fortran-ordered array (scipy 1.x);
    the direct solve hands on a C-ordered one with the same values (the G2P and guess kernels
    take it)."""
    n = 40
    matrix = sp.diags([np.full(n - 1, 0.25), np.full(n, 2.0), np.full(n - 1, 0.25)], [-1, 0, 1], format="csc")
    rhs = np.random.default_rng(0).random((n, 2))
    factors = spla.splu(matrix)
    solution, converged = _direct_solve(factors, matrix.tocsr(), rhs)
    assert converged and solution.flags.c_contiguous
    np.testing.assert_array_equal(solution, factors.solve(rhs))
    np.testing.assert_allclose(matrix @ solution, rhs, rtol=0, atol=1e-14)


def test_serendipity_numbers_its_cells_alike_on_a_grid_one_element_tall():
    """The numbering tuple of serendipity's folded form has one step per column of slots on a
    grid one element tall too (where all steps are 0), the length it has on taller grids; and
    on both its affine formula (what the kernels' ``cell_nodes`` computes) gives every cell's
    nodes of the folded connectivity."""
    lengths = []
    for upper_y in (1.0, 3.0):
        grid = Grid("serendipity", lower=(0.0, 0.0), upper=(5.0, upper_y), spacing=1.0)
        folded = separated_tables(grid).folded
        numbering, connectivity = folded.numbering, folded.connectivity
        lengths.append(len(numbering))
        n_x, n_y = grid.discretization.n_elements
        step_x, steps_y, offsets = numbering[0], numbering[1:4], numbering[4:]
        assert len(offsets) == 9
        for ix in range(n_x):
            for iy in range(n_y):
                nodes = [ix * step_x + iy * steps_y[s // 3] + offsets[s] for s in range(9)]
                row = connectivity[ix * n_y + iy]
                assert [nodes[s] for s in range(9) if s != 4] == [int(row[s]) for s in range(9) if s != 4]
    assert lengths == [13, 13]


def test_the_compile_benchmark_names_kernels_compiled_again_for_another_layout():
    """``benchmarks/compile_time.py --kernels`` lists the kernels compiled more than once for
    types that differ only in memory order or writability (helpers, level 1, are not counted;
    another tuple length is another form)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from compile_time import recompiled

    c = "Array(float64, 2, 'C', False, aligned=True)"
    f = "Array(float64, 2, 'F', False, aligned=True)"
    readonly = "Array(bool, 1, 'C', True, aligned=True)"
    writable = "Array(bool, 1, 'C', False, aligned=True)"
    compilations = [
        ("g2p", f"({c}, UniTuple(int64, 3))", 1.0, 0),
        ("g2p", f"({f}, UniTuple(int64, 3))", 1.0, 0),  # again: Fortran order
        ("g2p", f"({c}, UniTuple(int64, 4))", 1.0, 0),  # another form
        ("free_part", f"({readonly},)", 0.1, 0),
        ("free_part", f"({writable},)", 0.1, 0),  # again: writable
        ("helper", f"({c},)", 0.1, 1),
        ("helper", f"({f},)", 0.1, 1),  # a helper's: not a kernel of its own
    ]
    assert recompiled(compilations) == ["free_part (2x)", "g2p (2x)"]
