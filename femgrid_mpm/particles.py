"""Material-point state (plain arrays) and seeding of rectangles."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from .diagnostics import ScaleWarning
from .expressions import compile_expression


@dataclass
class Particles:
    """The state carried by the material points, body after body.

    Attributes
    ----------
    x : ndarray, shape (n, 2)
        Positions (m).
    v : ndarray, shape (n, 2)
        Velocities (m/s).
    mass : ndarray, shape (n,)
        Masses (kg per unit thickness); constant.
    density : ndarray, shape (n,)
        Current mass densities (kg/m^3); volume is ``mass / density``.
    stress : ndarray, shape (n, 3)
        Cauchy stress xx, yy, xy (Pa).
    strain : ndarray, shape (n, 3)
        Small strain xx, yy, xy (tensor shear, half the engineering shear).
    body : ndarray of int32, shape (n,)
        Index of the body in scene order.
    x0 : ndarray, shape (n, 2)
        Initial positions (m).
    deformation_gradient : ndarray, shape (n, 4)
        F_xx, F_xy, F_yx, F_yy; kept up to date only for materials that use
        it (neo-Hookean), identity otherwise.
    """

    x: np.ndarray
    v: np.ndarray
    mass: np.ndarray
    density: np.ndarray
    stress: np.ndarray
    strain: np.ndarray
    body: np.ndarray
    x0: np.ndarray = field(repr=False)
    deformation_gradient: np.ndarray = field(default=None, repr=False)

    def __post_init__(self):
        if self.deformation_gradient is None:
            self.deformation_gradient = np.tile([1.0, 0.0, 0.0, 1.0], (len(self.mass), 1))

    @property
    def n(self) -> int:
        return len(self.mass)

    @property
    def volume(self) -> np.ndarray:
        """Current volumes (m^2 per unit thickness), shape (n,); infinite where a stopped run's
        density has gone to 0 (without numpy's warning: the stop has said why)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.mass / self.density

    def body_slices(self) -> list[slice]:
        """Contiguous index range of each body (particles are stored body by body)."""
        edges = np.flatnonzero(np.diff(self.body)) + 1
        bounds = [0, *edges.tolist(), self.n]
        return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]

    def arrays(self) -> dict[str, np.ndarray]:
        """Every array of the points by its field's name (the arrays themselves, not copies)."""
        return {name: vars(self)[name] for name in self.__dataclass_fields__}

    @classmethod
    def concatenate(cls, parts: list["Particles"]) -> "Particles":
        return cls(**{name: np.concatenate([p.arrays()[name] for p in parts]) for name in cls.__dataclass_fields__})

    def copy(self) -> "Particles":
        return Particles(**{name: array.copy() for name, array in self.arrays().items()})


def seed_rectangle(lower, upper, spacing: float, points_per_cell: int) -> tuple[np.ndarray, np.ndarray]:
    """Points at the centroids of a uniform subdivision of a rectangle.

    The rectangle is cut into ``nx x ny`` equal sub-cells with
    ``n = round(extent * points_per_cell / spacing)`` (at least 1) per
    direction, so a rectangle aligned with the grid gets exactly
    ``points_per_cell`` x ``points_per_cell`` points in every grid cell, and
    any rectangle is filled exactly (equal volumes summing to its area).

    Returns
    -------
    points : ndarray, shape (nx * ny, 2)
    volume : float
        Volume (area) of each point (m^2).
    """
    lower = np.asarray(lower, dtype=float)
    upper = np.asarray(upper, dtype=float)
    extent = upper - lower
    counts = points_across(lower, upper, spacing, points_per_cell)
    pitch = extent / counts
    axes = [lower[k] + pitch[k] * (np.arange(counts[k]) + 0.5) for k in range(2)]
    gx, gy = np.meshgrid(*axes, indexing="ij")
    return np.column_stack([gx.ravel(), gy.ravel()]), float(pitch[0] * pitch[1])


def count_rectangle(lower, upper, spacing: float, points_per_cell: int) -> int | float:
    """Number of points :func:`seed_rectangle` makes, without making them: in Python's numbers,
    not int64 (which wrapped for points_per_cell near 2**63, to a count under the limits), a
    float where it passes 2**53 (for a limit's test and message)."""
    across = [max(1.0, float(np.rint((float(b) - float(a)) * float(points_per_cell) / spacing)))
              for a, b in zip(lower, upper)]
    total = across[0] * across[1]
    return int(total) if total < 2**53 else total


def points_across(lower, upper, spacing: float, points_per_cell: int) -> np.ndarray:
    """The points :func:`seed_rectangle` puts along x and along y, shape (2,)."""
    extent = np.asarray(upper, dtype=float) - np.asarray(lower, dtype=float)
    return np.maximum(1, np.rint(extent * points_per_cell / spacing)).astype(int)


def warn_of_thin_bodies(bodies, spacing: float, support_width: int, basis: str) -> None:
    """A warning (:class:`~femgrid_mpm.diagnostics.ScaleWarning`) for each body with fewer
    points across than the basis' support is wide (in grid spacings): its functions
    are seen by the points of one side only and its strains are not resolved.  A
    spacing in millimetres for a body in metres makes one point of every body."""
    for index, body in enumerate(bodies):
        counts = points_across(body.lower, body.upper, spacing, body.points_per_cell)
        if counts.min() < support_width:
            axis = "xy"[int(np.argmin(counts))]
            width = float(np.subtract(body.upper, body.lower)[int(np.argmin(counts))])
            warnings.warn(
                f"bodies[{index}] ({body.name!r}): {counts.min()} point(s) across in {axis}, fewer than the "
                f"{support_width} that {basis} needs (its functions' support in grid spacings): the body is "
                f"{width:g} m wide in a grid of spacing {spacing:g} m (are both in the same units?)",
                ScaleWarning, stacklevel=3)


def seed_bodies(bodies, materials, spacing: float) -> Particles:
    """The points of a scene's bodies (``[[bodies]]``), body by body, at rest in their
    materials' densities with their initial velocity expressions evaluated.

    Raises
    ------
    ValueError
        A velocity expression that is NaN or infinite somewhere in its body, or whose kinetic
        energy (with the bodies before it) is beyond 1e308 J/m.
    """
    parts, kinetic = [], 0.0
    for index, (body, material) in enumerate(zip(bodies, materials)):
        x, volume = seed_rectangle(body.lower, body.upper, spacing, body.points_per_cell)
        n = len(x)
        v = np.zeros((n, 2))
        for axis, component in enumerate(body.velocity):
            if isinstance(component, str):
                v[:, axis] = compile_expression(component, ("x", "y"))(x=x[:, 0], y=x[:, 1])
            else:
                v[:, axis] = component
        bad = ~np.isfinite(v).all(axis=1)
        if bad.any():  # an expression that is NaN or infinite somewhere in the body
            first = int(np.argmax(bad))
            raise ValueError(f"bodies[{index}].velocity: gives NaN or infinity at {int(bad.sum())} point(s), "
                             f"the first at ({x[first, 0]:g}, {x[first, 1]:g})")
        # an infinite initial energy leaves the runaway guard no bound and every energy record
        # infinite (1e160 m/s ran to its end, exit 0, with inf in each row of energy.csv)
        with np.errstate(over="ignore"):
            point_energy = 0.5 * material.density * volume * np.sum(v * v, axis=1)
            kinetic += float(np.sum(point_energy))
        if not np.isfinite(kinetic):
            first = int(np.argmax(point_energy))
            raise ValueError(f"bodies[{index}].velocity: a kinetic energy beyond 1e308 J/m, the most at "
                             f"({x[first, 0]:g}, {x[first, 1]:g}) (are the velocity, the density and the sizes "
                             "in the same units?)")
        parts.append(
            Particles(
                x=x,
                v=v,
                mass=np.full(n, material.density * volume),
                density=np.full(n, material.density),
                stress=np.zeros((n, 3)),
                strain=np.zeros((n, 3)),
                body=np.full(n, index, dtype=np.int32),
                x0=x.copy(),
            )
        )
    return Particles.concatenate(parts)


#: overlapping pairs named in the warning; the rest are counted
SHOWN_OVERLAPS = 3


def overlapping_pairs(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """The pairs ``(i, j)``, ``i < j``, of rectangles ``[lower, upper]`` (shape (n, 2) each)
    that overlap with a positive area, in lexicographic order.

    A sweep along x: with the rectangles sorted by their left edge, those that overlap
    rectangle k in x are the ones after it whose left edge lies before its right edge (a
    binary search), so the work is n log n plus the pairs that overlap in x.
    """
    order = np.argsort(lower[:, 0], kind="stable")
    left, right = lower[order, 0], upper[order, 0]
    ends = np.searchsorted(left, right, side="left")  # left[k + 1:ends[k]] < right[k]
    pairs = []
    for k in np.flatnonzero(ends > np.arange(len(order)) + 1):
        others = order[k + 1:ends[k]]
        first = order[k]
        meets = (np.minimum(upper[first, 1], upper[others, 1]) > np.maximum(lower[first, 1], lower[others, 1])) \
            & (np.minimum(upper[first, 0], upper[others, 0]) > np.maximum(lower[first, 0], lower[others, 0]))
        found = others[meets]
        pairs.append(np.column_stack([np.minimum(first, found), np.maximum(first, found)]))
    if not pairs:
        return np.empty((0, 2), dtype=np.intp)
    pairs = np.concatenate(pairs)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def warn_of_overlaps(bodies) -> None:
    """One warning if bodies' rectangles overlap: their points fill the same space, so the
    mass there is counted twice (allowed: it may be meant).  It names the first
    :data:`SHOWN_OVERLAPS` pairs in scene order and counts the rest."""
    if len(bodies) < 2:
        return
    lower = np.array([body.lower for body in bodies], dtype=float)
    upper = np.array([body.upper for body in bodies], dtype=float)
    pairs = overlapping_pairs(lower, upper)
    if not len(pairs):
        return
    described = []
    for i, j in pairs[:SHOWN_OVERLAPS]:
        low, high = np.maximum(lower[i], lower[j]), np.minimum(upper[i], upper[j])
        described.append(f"{bodies[i].name!r} and {bodies[j].name!r} overlap in [{low[0]:g}, {low[1]:g}] to "
                         f"[{high[0]:g}, {high[1]:g}]")
    more = f", and {len(pairs) - SHOWN_OVERLAPS} more pairs" if len(pairs) > SHOWN_OVERLAPS else ""
    warnings.warn(f"bodies {'; '.join(described)}{more}: their points fill the same space (mass counted twice there)",
                  RuntimeWarning, stacklevel=3)
