"""Compiled (numba) hot paths of the step, and the engine interface the step is written against.

``basis``     every grid's shape functions in separated (tensor) form, evaluated
              per point inside the kernels; checked against
              :meth:`femgrid_mpm.Grid.shape_functions` (which stays the
              scikit-fem-backed definition) to 1e-12 in ``tests/test_kernels.py``.
``transfer``  the three passes over the points of a step: ``p2g`` (mass,
              momentum, consistent mass matrix; ``p2g_sums`` without the
              matrix), ``*_stress_and_force`` (Eqs. 18, 6, 11 fused for linear
              elasticity), ``g2p`` (Eqs. 19-21); ``tensor_*`` kernels (q1, q2,
              cubic splines: unrolled loops, sum factorization) and ``local_*``
              kernels (function by function: serendipity's folded form, and
              the flat tables for any other basis).
``pattern``   the consistent mass matrix's sparsity, fixed per grid, so that the
              P2G pass assembles it in place.
``engines``   :class:`~.engines.ScipyTransfer` (the reference: the paper's
              sparse algebra with scipy matrices) and
              :class:`~.engines.CompiledTransfer` (these kernels), selected by
              ``[solver] engine``.

Every kernel is serial, cached on disk (:func:`.compiled.compiled`: compiled
once per machine and source tree, then loaded: about 60 s the first time for
every basis and mass kind) and ``fastmath=False``, its fused multiply-adds
asked for by name (:mod:`.arithmetic`): results are reproducible bit for bit
from run to run and from machine to machine.  Node and entry indices are
unsigned where they are computed (numba tests signed ones for Python's
negative wraparound at every access).

``arithmetic`` ``fused(a, b, c)``, the IEEE 754 fused multiply-add.
``compiled``   ``numba.njit(cache=True)`` with a cache directory named by a
              fingerprint of every module a kernel can inline (numba alone
              checks a kernel's own file: an edit of ``basis.py`` left the
              transfers compiled from its old text).
"""
