"""Supports: fixed grid nodes, velocity and acceleration zero (the paper's rigid boundary)."""

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
    """

    where: str
    fix: tuple[Literal["x", "y"], ...] = Field(default=("x", "y"), min_length=1)

    name = "supports"
    stage = Stage.CONSTRAIN

    def bind(self, simulation):
        rows, columns = self._degrees_of_freedom(simulation.grid)

        def fix_nodes(ctx: StepContext) -> None:
            ctx.target[..., rows, columns] = 0.0  # every field, with one per body

        return fix_nodes

    def fixed(self, grid) -> np.ndarray:
        rows, columns = self._degrees_of_freedom(grid)
        fixed = np.zeros((grid.n_nodes, 2), dtype=bool)
        fixed[rows, columns] = True
        return fixed

    def _degrees_of_freedom(self, grid) -> tuple[np.ndarray, np.ndarray]:
        """The selected nodes and components, as ``np.ix_`` index arrays."""
        nodes = grid.nodes_where(self.where)
        if len(nodes) == 0:
            raise ValueError(f"support where = {self.where!r} selects no grid node")
        components = np.array(sorted({"x": 0, "y": 1}[c] for c in self.fix))
        return np.ix_(nodes, components)
