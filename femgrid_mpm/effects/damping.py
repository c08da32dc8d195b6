"""Mass-proportional damping, ``f_i = -c (M v)_i``: dynamic relaxation."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import NonNegativeFloat
from pydantic.dataclasses import dataclass

from ..step import Stage, StepContext
from .base import Effect
from .config import EFFECT_CONFIG


@dataclass(frozen=True, config=EFFECT_CONFIG)
class MassDamping(Effect):
    """``[damping] kind = "mass"``, ``coefficient = c`` (1/s).

    Acts on the grid velocity with the step's own mass (lumped or
    consistent), so a rigid motion decays as ``exp(-c t)``.  Its (negative)
    work is booked like any other force's.
    """

    kind: Literal["mass"]
    coefficient: NonNegativeFloat

    name = "damping"
    stage = Stage.ADJUST_FORCE
    # -c M v against the kick's mid velocity v (1 - c dt / 2) (no stiffness) puts energy in
    # only where c dt > 2, where the step itself grows as (1 - c dt)^n
    dissipative = True

    def bind(self, simulation):
        c = float(self.coefficient)

        def damp(ctx: StepContext) -> None:
            with np.errstate(over="ignore"):  # beyond 1e308: inf, and the state guard stops the run
                ctx.add_force(self.name, -c * ctx.mass.apply(ctx.velocity))

        return damp
