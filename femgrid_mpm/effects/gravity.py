"""Gravity: a uniform body acceleration, ``f_i = sum_p m_p N_ip g`` (paper Eq. 13)."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic.dataclasses import dataclass

from ..step import Stage, StepContext
from .base import Effect
from .config import EFFECT_CONFIG


@dataclass(frozen=True, config=EFFECT_CONFIG)
class Gravity(Effect):
    """``[[loads]] kind = "gravity"``: ``acceleration = [gx, gy]`` (m/s^2)."""

    kind: Literal["gravity"]
    acceleration: tuple[float, float]

    name = "gravity"
    stage = Stage.EXTERNAL_FORCE

    def bind(self, simulation):
        g = np.asarray(self.acceleration, dtype=float)
        with np.errstate(over="ignore"):  # beyond 1e308: inf, and the state guard stops the run
            weight = simulation.particles.mass[:, None] * g  # constant: computed once

        def add_gravity(ctx: StepContext) -> None:
            ctx.add_point_forces(self.name, weight)

        return add_gravity
