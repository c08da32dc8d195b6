"""The background-grid bases: one registry line each.

To add a basis, write a definition with the attributes and the
``build(lower, n_elements, spacing) -> Discretization`` of
:class:`~.definition.BasisDefinition` (see ``finite_element.py`` for
scikit-fem elements and ``bspline3.py`` for a basis of the library's own),
and add it to ``BASES``.  The scene's ``[grid] basis`` choices, the command
line's ``--basis`` and the property tests in ``tests/test_bases.py`` are read
from this registry.
"""

from .definition import BasisDefinition
from .bspline2 import BSPLINE2, BSPLINE2_OPEN
from .bspline3 import BSPLINE3, BSPLINE3_OPEN, ElementBSpline3, cubic_spline
from .finite_element import Q1, Q2, SERENDIPITY, FiniteElementBasis
from .gimp import GIMP
from .lattice import Discretization
from .pieces import TensorPieces
from .polynomial import LocalPolynomials

BASES = {builder.name: builder for builder in (Q1, Q2, SERENDIPITY, BSPLINE3, BSPLINE3_OPEN, GIMP, BSPLINE2, BSPLINE2_OPEN)}



def check_registry() -> None:
    """Raise TypeError naming the first entry of :data:`BASES` that lacks part of
    :class:`BasisDefinition` (the scene reads every attribute), or whose ``name`` is not its key."""
    for key, basis in BASES.items():
        if not isinstance(basis, BasisDefinition):  # the Protocol is runtime-checkable: every member
            missing = sorted({*BasisDefinition.__annotations__, "build"} - set(dir(basis)))
            raise TypeError(f"bases.BASES[{key!r}]: a {type(basis).__name__} without {', '.join(missing)} "
                            "(femgrid_mpm.bases.BasisDefinition)")
        if basis.name != key:
            raise TypeError(f"bases.BASES[{key!r}]: its name is {basis.name!r}")


__all__ = [
    "BASES",
    "BasisDefinition",
    "BSPLINE2",
    "BSPLINE2_OPEN",
    "BSPLINE3",
    "BSPLINE3_OPEN",
    "Discretization",
    "ElementBSpline3",
    "FiniteElementBasis",
    "GIMP",
    "LocalPolynomials",
    "TensorPieces",
    "Q1",
    "Q2",
    "SERENDIPITY",
    "check_registry",
    "cubic_spline",
]
