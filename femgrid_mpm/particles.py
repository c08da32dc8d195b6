"""Material-point state (plain arrays) and seeding of rectangles."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

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
        """Current volumes (m^2 per unit thickness), shape (n,)."""
        return self.mass / self.density

    def body_slices(self) -> list[slice]:
        """Contiguous index range of each body (particles are stored body by body)."""
        edges = np.flatnonzero(np.diff(self.body)) + 1
        bounds = [0, *edges.tolist(), self.n]
        return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]

    @classmethod
    def concatenate(cls, parts: list["Particles"]) -> "Particles":
        return cls(**{name: np.concatenate([getattr(p, name) for p in parts]) for name in cls.__dataclass_fields__})

    def copy(self) -> "Particles":
        return Particles(**{name: getattr(self, name).copy() for name in self.__dataclass_fields__})


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
    counts = np.maximum(1, np.rint(extent * points_per_cell / spacing)).astype(int)
    pitch = extent / counts
    axes = [lower[k] + pitch[k] * (np.arange(counts[k]) + 0.5) for k in range(2)]
    gx, gy = np.meshgrid(*axes, indexing="ij")
    return np.column_stack([gx.ravel(), gy.ravel()]), float(pitch[0] * pitch[1])


def count_rectangle(lower, upper, spacing: float, points_per_cell: int) -> int:
    """Number of points :func:`seed_rectangle` makes, without making them."""
    extent = np.asarray(upper, dtype=float) - np.asarray(lower, dtype=float)
    return int(np.prod(np.maximum(1, np.rint(extent * points_per_cell / spacing))))


def seed_bodies(bodies, materials, spacing: float) -> Particles:
    """The points of a scene's bodies (``[[bodies]]``), body by body, at rest in their
    materials' densities with their initial velocity expressions evaluated.

    Raises
    ------
    ValueError
        A velocity expression that is NaN or infinite somewhere in its body.
    """
    parts = []
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


def warn_of_overlaps(bodies) -> None:
    """A warning for each pair of bodies whose rectangles overlap: their points fill the same
    space, so the mass there is counted twice (allowed: it may be meant)."""
    for i, first in enumerate(bodies):
        for second in bodies[i + 1:]:
            lower = np.maximum(first.lower, second.lower)
            upper = np.minimum(first.upper, second.upper)
            if np.all(upper > lower):
                warnings.warn(f"bodies {first.name!r} and {second.name!r} overlap in [{lower[0]:g}, {lower[1]:g}] to "
                              f"[{upper[0]:g}, {upper[1]:g}]: their points fill the same space (mass counted twice there)",
                              RuntimeWarning, stacklevel=3)
