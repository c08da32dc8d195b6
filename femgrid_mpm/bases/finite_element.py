"""Q1, Q2 and serendipity grids from scikit-fem.

scikit-fem defines the elements (``lbasis``), the mesh topology and the
degree-of-freedom numbering; this module only lays them on the MPM lattice
and derives, once, the affine map between a lattice cell and scikit-fem's
reference square.  ``MeshQuad.init_tensor`` orders an element's vertices
(x0,y0), (x0,y1), (x1,y1), (x1,y0), so reference X0 runs along global *y*:
the map is read off ``mesh.p``/``mesh.t`` and asserted for every element
instead of being assumed.

The grid numbers the nodes along the lattice, column by column (x, then
y), not as scikit-fem numbers its degrees of freedom (vertices, then edges
by facet index, then centres): a node of element ``(ix, iy)`` is then an
affine function of ``ix`` and ``iy``, which the compiled kernels compute
instead of reading (:func:`femgrid_mpm.kernels.tables.lattice_numbering`).
``Discretization.dofs`` keeps scikit-fem's number of each node.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

import numpy as np
import skfem

from .lattice import Discretization
from .polynomial import LocalPolynomials


@dataclass(frozen=True)
class FiniteElementBasis:
    """A scikit-fem quadrilateral element on the MPM lattice.

    Parameters
    ----------
    name : str
        Registry name (``"q1"``, ``"q2"``, ``"serendipity"``).
    element : type
        scikit-fem element class.
    degree : int
        Polynomial degree of ``lbasis`` in each reference coordinate.
    cells_per_element : int
        Element width in lattice spacings: 1 for Q1; 2 for Q2 and
        serendipity, whose mid-side (and centre) nodes then sit on the same
        lattice as Q1's nodes.

    The other attributes are those of
    :class:`~femgrid_mpm.bases.definition.BasisDefinition`.
    """

    name: str
    element: type
    degree: int
    cells_per_element: int
    nonnegative: bool
    critical_step_factors: Mapping[str, float] = field(default_factory=dict)
    mass_threshold: bool = True
    #: scikit-fem's elements are Lagrange or serendipity polynomials, not splines
    tensor_gram: bool = False
    sized: bool = False

    @property
    def support_width(self) -> int:
        """A vertex function spans the two elements beside its node."""
        return 2 * self.cells_per_element

    def build(self, lower: np.ndarray, n_elements: tuple[int, int], spacing: float,
              points_per_cell: int = 2) -> Discretization:
        width = spacing * self.cells_per_element
        x = lower[0] + width * np.arange(n_elements[0] + 1)
        y = lower[1] + width * np.arange(n_elements[1] + 1)
        mesh = skfem.MeshQuad.init_tensor(x, y)
        element = self.element()
        basis = skfem.CellBasis(mesh, element, intorder=1)

        to_reference, offset = _reference_map(mesh, width)
        order = _element_order(mesh, lower, width, n_elements)
        nodes = _snap_to_lattice(basis.doflocs.T, lower, spacing)
        dofs = _lattice_order(nodes, lower, spacing)
        number = np.empty(len(dofs), dtype=np.int64)
        number[dofs] = np.arange(len(dofs))
        connectivity = np.ascontiguousarray(number[basis.element_dofs[:, order].T], dtype=np.int32)
        nodes = np.ascontiguousarray(nodes[dofs])
        local_basis = LocalPolynomials.from_lbasis(
            element.lbasis, connectivity.shape[1], self.degree, to_reference, offset
        )
        return Discretization(
            basis=self.name,
            spacing=spacing,
            element_width=width,
            lower=lower,
            n_elements=n_elements,
            nodes=nodes,
            connectivity=connectivity,
            local_basis=local_basis,
            mesh=mesh,
            element=element,
            nonnegative=self.nonnegative,
            dofs=dofs,
        )


def _reference_map(mesh: skfem.MeshQuad, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Affine map (cell coordinates) -> (scikit-fem reference coordinates).

    scikit-fem maps reference vertex k of ``RefQuad`` ((0,0), (1,0), (1,1),
    (0,1)) to ``mesh.p[:, mesh.t[k]]``.  With ``J = [p1 - p0, p3 - p0]`` the
    element map is ``x = p0 + J X``; a point at cell coordinates ``xi`` is
    ``x = corner + width * xi``, hence ``X = J^-1 width xi + J^-1 (corner - p0)``.
    The map must be the same for every element; that is checked here.
    """
    vertices = mesh.p[:, mesh.t]  # (2, 4, n_elements)
    p0, p1, p2, p3 = (vertices[:, k, :] for k in range(4))
    columns = np.stack([p1 - p0, p3 - p0], axis=1)  # (2, 2, n_elements)
    corner = vertices.min(axis=1)
    if not np.allclose(p0 + (p1 - p0) + (p3 - p0), p2, rtol=0, atol=1e-12 * width):
        raise AssertionError("scikit-fem tensor mesh elements are not parallelograms")
    jacobian = columns[:, :, 0]
    if not np.allclose(columns, jacobian[:, :, None], rtol=0, atol=1e-9 * width):
        raise AssertionError("scikit-fem tensor mesh elements are not all oriented alike")
    inverse = np.linalg.inv(jacobian)
    offsets = inverse @ (corner - p0)
    offset = offsets[:, 0]
    if not np.allclose(offsets, offset[:, None], rtol=0, atol=1e-9):
        raise AssertionError("scikit-fem tensor mesh elements do not share one reference map")
    to_reference = inverse * width
    # Snap to the exact permutation/reflection it must be, so rounding in
    # the mesh coordinates does not leak into the shape functions.
    return np.round(to_reference), np.round(offset)


def _element_order(mesh: skfem.MeshQuad, lower: np.ndarray, width: float, n_elements: tuple[int, int]) -> np.ndarray:
    """scikit-fem element index for each lattice element ``ix * ny + iy``."""
    corner = mesh.p[:, mesh.t].min(axis=1)
    index = np.rint((corner - lower[:, None]) / width).astype(np.int64)
    lattice_index = index[0] * n_elements[1] + index[1]
    order = np.full(n_elements[0] * n_elements[1], -1, dtype=np.int64)
    order[lattice_index] = np.arange(mesh.t.shape[1])
    if np.any(order < 0):
        raise AssertionError("scikit-fem elements do not tile the lattice")
    return order


def _lattice_order(nodes: np.ndarray, lower: np.ndarray, spacing: float) -> np.ndarray:
    """scikit-fem's degrees of freedom sorted along the lattice: by x index, then by y index."""
    index = np.rint((nodes - lower) / spacing).astype(np.int64)
    return np.lexsort((index[:, 1], index[:, 0]))


def _snap_to_lattice(points: np.ndarray, lower: np.ndarray, spacing: float) -> np.ndarray:
    """Node coordinates as ``lower + i * spacing`` exactly (asserting they are)."""
    index = np.rint((points - lower) / spacing)
    if np.max(np.abs(points - lower - index * spacing), initial=0.0) > 1e-9 * spacing:
        raise AssertionError("element nodes are not on the lattice")
    return np.ascontiguousarray(lower + index * spacing)


Q1 = FiniteElementBasis("q1", skfem.ElementQuad1, degree=1, cells_per_element=1, nonnegative=True,
                        critical_step_factors=MappingProxyType({"lumped": 1.0, "consistent": 0.5}))
Q2 = FiniteElementBasis("q2", skfem.ElementQuad2, degree=2, cells_per_element=2, nonnegative=False,
                        critical_step_factors=MappingProxyType({"lumped": 0.8, "consistent": 0.4}))
# serendipity's corner functions integrate to -1/12 of an element: row-sum masses there are
# negative wherever a body fills the element, so no lumped step is stable and no full share
# exists for the mass threshold
SERENDIPITY = FiniteElementBasis(
    "serendipity", skfem.ElementQuadS2, degree=2, cells_per_element=2, nonnegative=False,
    critical_step_factors=MappingProxyType({"lumped": 0.0, "consistent": 0.4}), mass_threshold=False,
)
