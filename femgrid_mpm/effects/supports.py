"""Supports: fixed grid nodes, velocity and acceleration zero (the paper's rigid boundary), or
a wall of mirrored ghost nodes for the ghost-column splines."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field
from pydantic.dataclasses import dataclass

from ..step import Stage, StepContext
from .base import Effect
from .config import EFFECT_CONFIG


@dataclass(frozen=True, config=EFFECT_CONFIG)
class Support(Effect):
    """``[[supports]]``: ``where`` selects nodes, ``fix`` the components held at zero.

    Parameters
    ----------
    where : str
        Expression in the node coordinates ``x``, ``y`` (see
        :meth:`femgrid_mpm.Grid.nodes_where`), e.g. ``"x <= 0"``.  For
        bspline3 it should include the extra column beyond the boundary.
    fix : list of {"x", "y"}
        Components of velocity and acceleration set to zero.
    ghosts : {"fixed", "mirrored"}
        ``"fixed"``: every selected node holds ``fix`` at zero (the paper's).
        ``"mirrored"`` (ghost-column splines): ``where`` selects a half-plane of
        nodes, ``x <= a``, ``x >= a``, ``y <= a`` or ``y >= a``, whose inner line
        is a wall of symmetry: there the ``fix`` components are zero, and the
        ghost node beyond it takes its mirror image's velocity, minus for the
        ``fix`` components (odd), plus for the others (even), so that a roller
        (``fix`` the normal) or a clamp (both) holds exactly
        (:mod:`femgrid_mpm.mass.constraint`).  Nodes further out are held at zero.
        A basis with no column beyond the grid's edge (q1, q2, serendipity, the
        open-knot splines) has its edge nodes fixed, as with ``"fixed"``: a scene
        declares its walls once for every basis.
    """

    where: str
    fix: tuple[Literal["x", "y"], ...] = Field(default=("x", "y"), min_length=1)
    ghosts: Literal["fixed", "mirrored"] = "fixed"

    name = "supports"
    stage = Stage.CONSTRAIN

    def bind(self, simulation):
        if self.mirror(simulation.grid) is not None:
            constraint = simulation.constraint

            def mirror_nodes(ctx: StepContext) -> None:
                ctx.target[...] = constraint.unfold(ctx.target)  # every ghost from its image: idempotent

            return mirror_nodes
        rows, columns = self._degrees_of_freedom(simulation.grid)

        def fix_nodes(ctx: StepContext) -> None:
            ctx.target[..., rows, columns] = 0.0  # every field, with one per body

        return fix_nodes

    def fixed(self, grid) -> np.ndarray:
        """The held degrees of freedom; with mirrored ghosts, those on the wall and beyond
        the ghost column (the ghosts follow their images: :meth:`mirror`)."""
        fixed = np.zeros((grid.n_nodes, 2), dtype=bool)
        mirror = self.mirror(grid)
        if mirror is not None:
            fixed[mirror[1] == 0.0] = True
            return fixed
        rows, columns = self._degrees_of_freedom(grid)
        fixed[rows, columns] = True
        return fixed

    def mirror(self, grid) -> tuple[np.ndarray, np.ndarray] | None:
        """``(image, sign)``, each (n_nodes, 2): ``v[n, c] = sign * v[image, c]`` across this
        wall (:class:`femgrid_mpm.mass.NodeConstraint`); None for fixed ghosts, and on a
        basis with no column of nodes beyond the grid's edge (then the support fixes)."""
        if self.ghosts != "mirrored":
            return None
        nodes = grid.nodes_where(self.where)
        if len(nodes) == 0:
            raise ValueError(f"support where = {self.where!r} selects no grid node")
        tolerance = 1e-9 * grid.spacing
        if not (np.any(grid.nodes < grid.lower - tolerance) or np.any(grid.nodes > grid.upper + tolerance)):
            return None  # no ghost column (q1, q2, open knots): the edge's nodes are fixed, as "fixed" does
        lattice = grid.lattice_indices
        axis, line, outward = _half_plane(lattice, nodes, self.where)
        low = lattice.min(axis=0)
        index = np.full(lattice.max(axis=0) - low + 1, -1)
        index[tuple((lattice - low).T)] = np.arange(grid.n_nodes)
        distance = outward * (lattice[:, axis] - line)  # lattice steps beyond the wall (0: on it)
        mirrored = lattice.copy()
        mirrored[:, axis] = line - outward * distance
        odd = np.zeros(2, dtype=bool)
        odd[[{"x": 0, "y": 1}[c] for c in self.fix]] = True
        image = np.repeat(np.arange(grid.n_nodes)[:, None], 2, axis=1)
        sign = np.ones((grid.n_nodes, 2))
        sign[distance == 0] = np.where(odd, 0.0, 1.0)
        sign[distance >= 2] = 0.0
        ghosts = np.flatnonzero(distance == 1)
        inside = np.all((mirrored[ghosts] >= low) & (mirrored[ghosts] - low < index.shape), axis=1)
        if not np.all(inside):
            raise ValueError(f"support where = {self.where!r}: the ghost nodes' mirror images lie beyond the grid")
        image[ghosts] = index[tuple((mirrored[ghosts] - low).T)][:, None]
        sign[ghosts] = np.where(odd, -1.0, 1.0)
        return image, sign

    def _degrees_of_freedom(self, grid) -> tuple[np.ndarray, np.ndarray]:
        """The selected nodes and components, as ``np.ix_`` index arrays."""
        nodes = grid.nodes_where(self.where)
        if len(nodes) == 0:
            raise ValueError(f"support where = {self.where!r} selects no grid node")
        components = np.array(sorted({"x": 0, "y": 1}[c] for c in self.fix))
        return np.ix_(nodes, components)


def _half_plane(lattice: np.ndarray, nodes: np.ndarray, where: str) -> tuple[int, int, int]:
    """``(axis, line, outward)`` of the half-plane of lattice nodes ``nodes`` is: all nodes
    with index ``<= line`` (outward -1) or ``>= line`` (+1) along ``axis``."""
    selected = np.zeros(len(lattice), dtype=bool)
    selected[nodes] = True
    for axis in (0, 1):
        for outward, line in ((-1, lattice[nodes, axis].max()), (1, lattice[nodes, axis].min())):
            if np.array_equal(selected, outward * (lattice[:, axis] - line) >= 0) and not selected.all():
                return axis, int(line), outward
    raise ValueError(f"support where = {where!r} with ghosts = 'mirrored' must select the nodes on one side of a "
                     f"grid line, e.g. 'x <= 0' (the wall and the ghost column beyond it)")
