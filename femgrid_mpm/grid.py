"""The background grid: a lattice of nodes and the shape-function matrices.

Examples
--------
>>> import numpy as np
>>> from femgrid_mpm import Grid
>>> grid = Grid("q2", lower=(0.0, 0.0), upper=(7.0, 1.0), spacing=0.5)
>>> grid.nodes.shape
(45, 2)
>>> N, dNdx, dNdy = grid.shape_functions(np.array([[0.3, 0.2], [6.9, 0.9]]))
>>> N.shape, np.allclose(N.sum(axis=1), 1.0)
((2, 45), True)
>>> N @ grid.nodes
array([[0.3, 0.2],
       [6.9, 0.9]])
"""

from __future__ import annotations

import functools
import math
from typing import Callable, Union

import numpy as np
import scipy.sparse as sp

from .bases import BASES, Discretization
from .expressions import compile_expression

#: Largest grid accepted: refused before anything is allocated.
MAX_NODES = 100_000_000
#: lengths (m) the grid takes: its spacing and coordinates lie within [1/MAX_LENGTH, MAX_LENGTH]
#: in magnitude, so that areas, masses and node counts stay finite floats
MAX_LENGTH = 1e100

NodeCondition = Union[str, Callable[[np.ndarray, np.ndarray], np.ndarray]]


class Grid:
    """A regular background grid of one of the registered bases.

    Parameters
    ----------
    basis : str
        Interpolation, a name of :data:`femgrid_mpm.bases.BASES` (q1, q2,
        serendipity, bspline2(_open), bspline3(_open), gimp).  q1, q2 and
        serendipity are scikit-fem's ``ElementQuad1``, ``ElementQuad2`` and
        ``ElementQuadS2``; bspline3 is the tensor-product cubic B-spline of
        the paper's Eq. 23.
    lower, upper : (float, float)
        Corners of the domain (m).
    spacing : float
        Distance between neighbouring nodes (m), the same for every basis:
        q2 and serendipity elements are ``2 * spacing`` wide, so their nodes
        coincide with q1's nodes (serendipity has no element-centre node).
    points_per_cell : int
        Points seeded along each axis of a lattice cell, for a basis whose
        weights depend on the points' size (``sized``: GIMP); the others ignore it.

    Notes
    -----
    If ``upper - lower`` is not a whole number of elements in a direction,
    the grid is extended: ``self.upper`` is moved up to the next whole
    element (``lower + ceil(extent / element_width) * element_width``) so that
    the domain asked for is always covered.  For q2 and serendipity an odd
    number of spacings therefore gains one spacing.

    For bspline3 the grid also carries one column (row) of nodes beyond each
    side of the domain (see :mod:`femgrid_mpm.bases.bspline3`), so its node
    count is ``(nx + 3) * (ny + 3)`` for ``nx x ny`` cells, against
    ``(nx + 1) * (ny + 1)`` for q1.

    Attributes
    ----------
    nodes : ndarray, shape (n_nodes, 2)
        Node coordinates (m).
    lower, upper : ndarray, shape (2,)
        The domain actually covered (m).
    cells : (int, int)
        Lattice cells (``spacing`` wide) along x and y.
    """

    def __init__(self, basis: str, lower=(0.0, 0.0), upper=(1.0, 1.0), spacing: float = 1.0, points_per_cell: int = 2):
        if basis not in BASES:
            raise ValueError(f"unknown basis {basis!r}; choose one of {', '.join(BASES)}")
        builder = BASES[basis]
        lower = _vector("lower", lower)
        upper = _vector("upper", upper)
        if not (isinstance(spacing, (int, float, np.floating, np.integer)) and not isinstance(spacing, bool)
                and math.isfinite(spacing) and spacing > 0):
            raise ValueError(f"spacing must be a positive finite number, got {spacing!r}")
        if not (isinstance(points_per_cell, (int, np.integer)) and not isinstance(points_per_cell, bool)
                and points_per_cell >= 1):  # gimp's particle size is the spacing over it
            raise ValueError(f"points_per_cell must be a whole number, at least 1, got {points_per_cell!r}")
        problem = length_problem(lower, upper, spacing)
        if problem is not None:
            raise ValueError(f"{problem[0]} {problem[1]}")
        if np.any(upper <= lower):
            raise ValueError(f"upper {upper.tolist()} must exceed lower {lower.tolist()} in both directions")
        n_nodes_estimate = node_count(lower, upper, spacing, builder.cells_per_element)
        if n_nodes_estimate > MAX_NODES:
            raise ValueError(
                f"the grid would have about {n_nodes_estimate:.3g} nodes, more than the limit of {MAX_NODES:.0e}"
            )
        width = spacing * builder.cells_per_element
        # a tolerance so that 7.0 / 0.5 counts as 14, not 15, under rounding
        n_elements = tuple(int(max(1, math.ceil(extent / width - 1e-9))) for extent in upper - lower)
        self.basis = basis
        #: what the basis declares about itself (:class:`~femgrid_mpm.bases.BasisDefinition`)
        self.definition = builder
        self.spacing = float(spacing)
        self.lower = lower
        self.upper = lower + np.array(n_elements) * width
        self.discretization: Discretization = builder.build(lower, n_elements, float(spacing), points_per_cell)
        self.cells = (n_elements[0] * builder.cells_per_element, n_elements[1] * builder.cells_per_element)

    # -- lattice -------------------------------------------------------------

    @property
    def nodes(self) -> np.ndarray:
        return self.discretization.nodes

    @functools.cached_property
    def lattice_indices(self) -> np.ndarray:
        """(n_nodes, 2) int: each node's x and y index on the lattice, ``(nodes - lower) / spacing``
        (the splines' Greville points of open knots are not on it: rounded)."""
        return np.rint((self.nodes - self.lower) / self.spacing).astype(np.int64)

    @property
    def n_nodes(self) -> int:
        return len(self.discretization.nodes)

    @property
    def n_local(self) -> int:
        """Nodes that influence one point: 4 (q1), 8, 9 or 16 (bspline3)."""
        return self.discretization.connectivity.shape[1]

    @property
    def mesh(self):
        """The elements as a scikit-fem ``MeshQuad``."""
        return self.discretization.mesh

    @property
    def nonnegative(self) -> bool:
        """Whether every shape function is >= 0 (q1, bspline3)."""
        return self.discretization.nonnegative

    @functools.cached_property
    def node_integrals(self) -> np.ndarray:
        """``integral(phi_i)`` over the grid's domain (m^2), shape (n_nodes,).

        The share of the domain's area each node carries, exact (3 x 3 Gauss
        points per element integrate the cubic pieces exactly).  A node of a
        body filling its whole support has lumped volume equal to this.
        """
        d = self.discretization
        gauss, weights = np.polynomial.legendre.leggauss(3)
        gauss, weights = (gauss + 1) / 2, weights / 2
        ix, iy = np.meshgrid(np.arange(d.n_elements[0]), np.arange(d.n_elements[1]), indexing="ij")
        corners = self.lower + d.element_width * np.column_stack([ix.ravel(), iy.ravel()])
        gx, gy = np.meshgrid(gauss, gauss, indexing="ij")
        offsets = d.element_width * np.column_stack([gx.ravel(), gy.ravel()])
        area = np.outer(weights, weights).ravel() * d.element_width**2
        integrals = np.zeros(self.n_nodes)
        chunk = 4096  # elements at a time: the matrices of all Gauss points at once were ~1.4 KB per particle
        for start in range(0, len(corners), chunk):
            points = (corners[start : start + chunk, None, :] + offsets[None, :, :]).reshape(-1, 2)
            N, _, _ = self.shape_functions(points)
            integrals += N.T @ np.tile(area, len(points) // len(area))
        return integrals

    def __repr__(self) -> str:
        return (
            f"Grid({self.basis!r}, lower={self.lower.tolist()}, upper={self.upper.tolist()}, "
            f"spacing={self.spacing}, nodes={self.n_nodes})"
        )

    def nodes_where(self, condition: NodeCondition) -> np.ndarray:
        """Indices of the nodes that satisfy a condition, for supports.

        Parameters
        ----------
        condition : str or callable
            An expression in the node coordinates ``x`` and ``y`` such as
            ``"x <= 0"`` or ``"(x <= 0) or (x >= 8)"`` (evaluated safely, see
            :mod:`femgrid_mpm.expressions`), or a function ``f(x, y)``
            returning a boolean array.  Node coordinates are exactly
            ``lower + i * spacing``, so ``x <= 0`` catches the nodes at 0;
            for spacings that are not binary fractions compare with a small
            tolerance.

        Returns
        -------
        ndarray of int, shape (n_selected,)
        """
        x, y = self.nodes[:, 0], self.nodes[:, 1]
        if isinstance(condition, str):
            selected = compile_expression(condition, ("x", "y"))(x=x, y=y)
        elif callable(condition):
            selected = np.asarray(condition(x, y))
        else:
            raise TypeError(f"condition must be an expression string or a callable, got {type(condition).__name__}")
        if selected.shape != x.shape or selected.dtype != bool:
            raise ValueError(f"node condition {condition!r} must give one boolean per node")
        return np.flatnonzero(selected)

    # -- shape functions -------------------------------------------------------

    def locate(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Element of each point and its cell coordinates.

        Parameters
        ----------
        points : ndarray, shape (n, 2)

        Returns
        -------
        element : ndarray of int32, shape (n,)
            Lattice element index ``ix * n_elements_y + iy``.
        cell_points : ndarray, shape (n, 2)
            ``(xi, eta)`` in [0, 1]^2.  Points on an element edge belong to
            the element above/right of it, except on the domain's upper
            edges.

        Raises
        ------
        ValueError
            If any point lies outside the domain (or is not finite), naming
            how many and the first of them.
        """
        points = _points(points)
        x, y = points[:, 0], points[:, 1]
        # cheap reductions on columns; the per-point test only runs to name the
        # culprits (min/max propagate NaN, which then fails the comparison)
        if len(points) and not (
            x.min() >= self.lower[0] and x.max() <= self.upper[0]
            and y.min() >= self.lower[1] and y.max() <= self.upper[1]
        ):
            inside = np.all((points >= self.lower) & (points <= self.upper), axis=1)
            outside = np.flatnonzero(~inside)
            first = outside[0]
            raise ValueError(
                f"{len(outside)} of {len(points)} points lie outside the grid "
                f"[{self.lower[0]:g}, {self.upper[0]:g}] x [{self.lower[1]:g}, {self.upper[1]:g}]; "
                f"the first is point {first} at ({points[first, 0]:g}, {points[first, 1]:g})"
            )
        d = self.discretization
        inverse_width = 1.0 / d.element_width
        cell_points = np.empty_like(points)
        element = np.zeros(len(points), dtype=np.int32)
        for axis, coordinate in enumerate((x, y)):
            scaled = cell_points[:, axis]
            np.subtract(coordinate, self.lower[axis], out=scaled)
            scaled *= inverse_width
            # points on the upper edge belong to the last element
            index = np.minimum(scaled.astype(np.int32), np.int32(d.n_elements[axis] - 1))
            scaled -= index
            if axis == 0:
                index *= np.int32(d.n_elements[1])
            element += index
        return element, cell_points

    def shape_functions(self, points: np.ndarray) -> tuple[sp.csr_matrix, sp.csr_matrix, sp.csr_matrix]:
        """Shape-function values and gradients at points, as sparse matrices.

        Parameters
        ----------
        points : ndarray, shape (n_points, 2)
            Positions (m), inside the domain.

        Returns
        -------
        N, dNdx, dNdy : scipy.sparse.csr_matrix, shape (n_points, n_nodes)
            ``N[p, i]`` is node i's function at point p; ``dNdx``, ``dNdy``
            its derivatives (1/m).  Every row has exactly ``n_local`` stored
            entries (some may be zero), in the element's local order (not
            sorted by node).  Each matrix owns its index arrays: scipy sorts
            indices in place in some operations, which would scramble a
            matrix sharing them.
        """
        element, cell_points = self.locate(points)
        d = self.discretization
        values, d_xi, d_eta = d.local_basis.evaluate(cell_points, element)
        inverse_width = 1.0 / d.element_width
        d_xi *= inverse_width
        d_eta *= inverse_width
        n_points, n_local = values.shape
        indices = d.connectivity[element].ravel()
        indptr = np.arange(0, n_points * n_local + 1, n_local, dtype=np.int32)
        shape = (n_points, self.n_nodes)
        return tuple(
            sp.csr_matrix((data.ravel(), indices if k == 0 else indices.copy(), indptr if k == 0 else indptr.copy()), shape=shape, copy=False)
            for k, data in enumerate((values, d_xi, d_eta))
        )


def length_problem(lower, upper, spacing: float) -> tuple[str, str] | None:
    """``(argument, message)`` if the spacing or a coordinate lies outside
    :data:`MAX_LENGTH` (see there), else None."""
    spacing = float(spacing)
    if not 1.0 / MAX_LENGTH <= spacing <= MAX_LENGTH:
        return "spacing", f"{spacing:g} is outside the supported range {1 / MAX_LENGTH:g} to {MAX_LENGTH:g} m"
    for name, corner in (("lower", lower), ("upper", upper)):
        values = [float(value) for value in corner]
        if any(abs(value) > MAX_LENGTH for value in values):
            return name, f"{values} is outside the supported range of +-{MAX_LENGTH:g} m"
    return None


def node_count(lower, upper, spacing: float, cells_per_element: int) -> float:
    """About how many nodes a grid over ``[lower, upper]`` has (a float: no integer
    conversion of a huge count, and infinity where the extent overflows)."""
    with np.errstate(over="ignore"):
        extent = np.asarray(upper, dtype=float) - np.asarray(lower, dtype=float)
        elements = np.maximum(1.0, np.ceil(extent / (spacing * cells_per_element) - 1e-9))
        return float(np.prod(elements * cells_per_element + 3.0))


def _vector(name: str, value) -> np.ndarray:
    if np.iscomplexobj(value):  # float() would drop the imaginary part
        raise ValueError(f"{name} must be two finite numbers, got {value!r}")
    array = np.asarray(value, dtype=float)
    if array.shape != (2,) or not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be two finite numbers, got {value!r}")
    return array


def _points(points) -> np.ndarray:
    if np.iscomplexobj(points):  # float() would drop the imaginary part, with a warning only
        raise ValueError(f"points must be real numbers, got {np.asarray(points).dtype}")
    array = np.asarray(points, dtype=float)
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f"points must have shape (n, 2), got {array.shape}")
    return array
