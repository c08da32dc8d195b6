"""A body force given as an acceleration field: ``f_p = m_p b(x0_p, t)`` (manufactured solutions)."""

from __future__ import annotations

from typing import Literal, Union

import numpy as np
from pydantic import field_validator
from pydantic.dataclasses import dataclass

from ..expressions import compile_expression
from ..step import Stage, StepContext
from .base import Effect
from .config import EFFECT_CONFIG

#: the variables of the acceleration's expressions: the point's initial position and the time
VARIABLES = ("x", "y", "t")


@dataclass(frozen=True, config=EFFECT_CONFIG)
class BodyForce(Effect):
    """``[[loads]] kind = "body_force"``: ``acceleration = ["bx", "by"]`` (m/s^2).

    Each component is a number or an expression in the point's *initial*
    position ``x``, ``y`` (m) and the time ``t`` (s), e.g. ``"-pi**2*sin(pi*x)*sin(t)"``:
    a body force is a property of the material, so it follows the point, as the
    fields of a manufactured solution do.  The point receives ``m_p b`` at the
    step's start time, carried to the grid as its momentum is (``N.T``, or ``W.T``
    with HRZ mass); its work is booked like any other force's.
    """

    kind: Literal["body_force"]
    acceleration: tuple[Union[float, str], Union[float, str]]

    name = "body_force"
    stage = Stage.EXTERNAL_FORCE

    @field_validator("acceleration")
    @classmethod
    def _expressions(cls, value):
        for component in value:
            if isinstance(component, str):
                compile_expression(component, VARIABLES)
        return value

    def bind(self, simulation):
        particles = simulation.particles
        x, y = particles.x0[:, 0], particles.x0[:, 1]
        mass = particles.mass
        components = [compile_expression(c, VARIABLES) if isinstance(c, str) else float(c) for c in self.acceleration]

        def add_body_force(ctx: StepContext) -> None:
            t = np.float64(ctx.time)
            forces = np.empty((len(mass), 2))
            for axis, component in enumerate(components):
                forces[:, axis] = mass * (component(x=x, y=y, t=t) if callable(component) else component)
            ctx.add_point_forces(self.name, forces)

        return add_body_force
