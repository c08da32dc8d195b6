"""The two families of compiled passes, and which kernel runs each pass of a step.

``tensor``
    Tensor-product bases (q1, q2, cubic splines: :class:`~.tables.TensorTables`),
    by sum factorization over the ``n1 x n1`` nodes.  With
    ``phi_(i,j) = U_i(xi) W_j(eta)``, a gather ``sum_ij phi_ij g_ij`` is
    ``sum_i U_i (sum_j W_j g_ij)`` and its x-derivative reuses the inner sums;
    a scatter multiplies per-i factors by ``W_j``.  ``len(marker)`` (n1) is a
    compile-time constant, so every loop over nodes is unrolled.  A point's
    nodes are computed from its cell (``topology`` is the grid's numbering
    along the lattice, see :func:`.tables.lattice_numbering`), not read.
``local``
    Any basis, function by function: serendipity's folded form
    (:class:`~.tables.FoldedTables`) and the flat form of any other basis
    (:class:`~.tables.BasisTables`).  :func:`.shape.point_weights` gives a
    point's nodes and the values and gradients of its local functions
    (scratch arrays for the flat form, register tuples for the folded one);
    :func:`.shape.function_slots` their count and the slot that is no
    function (the folded form's centre; -1 for none).  Each kernel is
    compiled once per form, which the ``form`` argument (before the
    topology) carries.

Every kernel takes the family's tables as their ``arrays()`` gives them
(:class:`~.tables.BasisTables`), after the pass's own arguments.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from .force import (local_internal_force, local_linear_elastic_stress_and_force, local_velocity_gradient,
                    tensor_internal_force, tensor_linear_elastic_stress_and_force, tensor_velocity_gradient)
from .g2p import local_g2p, tensor_g2p
from .mass_product import local_point_weights, tensor_point_weights
from .p2g import local_p2g, local_p2g_sums, tensor_p2g, tensor_p2g_sums


@dataclass(frozen=True)
class Passes:
    """The kernels of one family, pass by pass.

    Attributes
    ----------
    p2g, p2g_sums : callable
        P2G with the consistent mass matrix, and without it (:mod:`.p2g`).
    stress_and_force : callable
        Eqs. 18, 6 and 11 in one pass for linear elastic bodies (:mod:`.force`).
    velocity_gradient, internal_force : callable
        Eq. 18, then Eq. 11 after the materials' own update (:mod:`.force`).
    g2p : callable
        Eqs. 19-21 (:mod:`.g2p`).
    point_weights : callable
        Each point's function values and nodes, for the matrix-free mass product (:mod:`.mass_product`).
    """

    p2g: Callable
    p2g_sums: Callable
    stress_and_force: Callable
    velocity_gradient: Callable
    internal_force: Callable
    g2p: Callable
    point_weights: Callable


#: the passes of each family (the flat and folded forms share the ``local`` kernels)
FAMILIES = {
    "tensor": Passes(tensor_p2g, tensor_p2g_sums, tensor_linear_elastic_stress_and_force, tensor_velocity_gradient,
                     tensor_internal_force, tensor_g2p, tensor_point_weights),
    "local": Passes(local_p2g, local_p2g_sums, local_linear_elastic_stress_and_force, local_velocity_gradient,
                    local_internal_force, local_g2p, local_point_weights),
}
