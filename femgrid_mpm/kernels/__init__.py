"""Compiled (numba) hot paths of the step, and the engine interface the step is written against.

The shape functions, set up once per grid and evaluated per point:

``tables``          every grid's shape functions in separated (tensor) form,
                    built in Python once per grid: the flat form (any basis),
                    tensor products (q1, q2, cubic splines), the folded form
                    (serendipity), and the nodes' numbering along the lattice.
``shape``           their evaluation per point inside the kernels (numba
                    overloads unrolled per basis, inlined into every pass).
``shape_matrices``  ``N, dNdx, dNdy`` at many points as rows, for the engine's
                    on-demand matrices; checked against
                    :meth:`femgrid_mpm.Grid.shape_functions` (which stays the
                    scikit-fem-backed definition) to 1e-12 in
                    ``tests/test_kernels.py``.

The three passes over the points of a step, each with its ``tensor_*``
kernels (q1, q2, cubic splines: unrolled loops, sum factorization) and its
``local_*`` kernels (function by function: serendipity's folded form, and the
flat tables for any other basis) side by side:

``p2g``             mass, momentum, consistent mass matrix (``p2g_sums``
                    without the matrix).
``force``           ``velocity_gradient`` (Eq. 18), ``internal_force``
                    (Eq. 11) and ``linear_elastic_stress_and_force`` (Eqs.
                    18, 6, 11 fused for linear elasticity).
``g2p``             velocity, position and density (Eqs. 19-21).
``families``        :data:`~.families.FAMILIES`: the kernels of each family,
                    pass by pass (:class:`~.families.Passes`).
``parallel``        threaded variants of the lumped and HRZ passes
                    (``[solver] threads``).
``pattern``         the consistent mass matrix's sparsity, fixed per grid, so
                    that the P2G pass assembles it in place.
``engines``         :class:`~.engines.ScipyTransfer` (the reference: the
                    paper's sparse algebra with scipy matrices) and
                    :class:`~.engines.CompiledTransfer` (these kernels),
                    selected by ``[solver] engine``.

Each kernel evaluates the shape functions of a point afresh instead of
reading stored matrices: at 1e5 points the matrices of cubic B-splines are
~45 MB, and streaming them through memory three times a step costs more than
recomputing them.  The kernels mirror the scipy expressions of
:class:`~.engines.ScipyTransfer` term by term (same frame of reference, same
order of operations where it matters), so the two engines agree to rounding.

Every kernel is serial (the threaded variants are separate functions), cached
on disk (:func:`.compiled.compiled`: compiled once per machine and source
tree, then loaded: about 60 s the first time for every basis and mass kind)
and ``fastmath=False``, its fused multiply-adds asked for by name
(:mod:`.arithmetic`): results are reproducible bit for bit from run to run
and from machine to machine.  Node and entry indices are unsigned where they
are computed (numba tests signed ones for Python's negative wraparound at
every access).  The point volumes ``m / rho`` are :func:`.arithmetic.quotient`
(IEEE 754, no Python test for a zero divisor: a zero density stops the run by
the step's finiteness check instead of a ZeroDivisionError out of a kernel).

``arithmetic``      ``fused(a, b, c)``, the IEEE 754 fused multiply-add, and
                    ``quotient(a, b)``, the IEEE 754 division.
``compiled``        ``numba.njit(cache=True)`` with a cache directory named
                    by a fingerprint of every module a kernel can inline
                    (numba alone checks a kernel's own file: after an edit of
                    ``shape.py`` alone it would load the passes compiled from
                    its old text).
"""
