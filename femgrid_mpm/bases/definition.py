"""What a basis declares: the interface every entry of :data:`femgrid_mpm.bases.BASES` implements.

The rest of the library asks a basis about itself through these attributes
and never compares basis names: the critical time step's table, the mass
models' remedies and CG's preconditioner read them.
"""

from __future__ import annotations

from typing import Mapping, Protocol, runtime_checkable

import numpy as np

from .lattice import Discretization


@runtime_checkable
class BasisDefinition(Protocol):
    """A basis of the background grid.

    Attributes
    ----------
    name : str
        Registry name, the scene's ``[grid] basis``.
    degree : int
        Polynomial degree of the local functions in each cell coordinate.
    cells_per_element : int
        Element width in lattice spacings (2 for q2 and serendipity, whose
        mid-side nodes sit on q1's lattice).
    support_width : int
        Width of one function's support in lattice spacings along each axis
        (q1 2, q2 and serendipity 4, cubic splines 4): a body thinner than
        this leaves functions seen from one side only.
    nonnegative : bool
        Every function is >= 0, so row-sum masses cannot be negative.
    critical_step_factors : mapping of str to float
        ``dt_crit * c_p / spacing`` on a full, unsupported grid for
        ``"lumped"`` and ``"consistent"`` mass (the classic Bloch values, for
        comparison with :func:`femgrid_mpm.stability.critical_time_step`).
    tensor_gram : bool
        The functions are tensor products of uniform cubic B-splines on the
        lattice, so CG may precondition the consistent mass with the 1D Gram
        matrices (:func:`femgrid_mpm.mass.preconditioners.tensor_preconditioner`).
    mass_threshold : bool
        Every function integrates to a positive area, so the relative mass
        threshold (``negative_mass = "threshold"``) has a full share to be a
        fraction of (serendipity's corner functions integrate to -1/12 of an
        element: it has none).
    sized : bool
        The weights depend on the size of the points (GIMP: the functions
        averaged over a point's domain, a square of its initial spacing
        ``spacing / points_per_cell``): ``build`` lays the basis for the
        scene's ``points_per_cell``, which every body must then share.  The
        other bases ignore it.
    """

    name: str
    degree: int
    cells_per_element: int
    support_width: int
    nonnegative: bool
    critical_step_factors: Mapping[str, float]
    tensor_gram: bool
    mass_threshold: bool
    sized: bool

    def build(self, lower: np.ndarray, n_elements: tuple[int, int], spacing: float,
              points_per_cell: int = 2) -> Discretization:
        """The basis laid on ``n_elements`` elements (``cells_per_element`` lattice cells
        wide) from ``lower``, nodes ``spacing`` apart, for points seeded
        ``points_per_cell`` to a cell along each axis.  Its ``Discretization`` may
        cut the elements finer (its ``element_width``): the pieces of its functions."""
