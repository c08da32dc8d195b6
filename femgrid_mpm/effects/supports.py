"""Supports: fixed grid nodes, velocity and acceleration zero (the paper's rigid boundary)."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field
from pydantic.dataclasses import dataclass

from .base import Stage, StepContext
from .config import EFFECT_CONFIG


@dataclass(frozen=True, config=EFFECT_CONFIG)
class Support:
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
        nodes = simulation.grid.nodes_where(self.where)
        if len(nodes) == 0:
            raise ValueError(f"support where = {self.where!r} selects no grid node")
        components = np.array(sorted({"x": 0, "y": 1}[c] for c in self.fix))
        rows, columns = np.ix_(nodes, components)

        def fix_nodes(ctx: StepContext) -> None:
            ctx.target[..., rows, columns] = 0.0  # every field, with one per body

        fix_nodes.nodes = nodes  # type: ignore[attr-defined]
        # known before any step, so that a coupled (consistent) mass solve can
        # leave these degrees of freedom out instead of zeroing them afterwards
        fixed = np.zeros((simulation.grid.n_nodes, 2), dtype=bool)
        fixed[rows, columns] = True
        fix_nodes.fixed = fixed  # type: ignore[attr-defined]
        return fix_nodes
