"""A body force given as an acceleration field: ``f_p = m_p b(x0_p, t)`` (manufactured solutions)."""

from __future__ import annotations

from dataclasses import field
from typing import Literal, Union

import numpy as np
from pydantic import model_validator
from pydantic.dataclasses import dataclass

from ..expressions import compile_vector, evaluate_vector
from ..step import Stage, StepContext
from .base import Effect, ForceNotFinite
from .config import EFFECT_CONFIG

#: the variables of the acceleration's expressions: the point's initial position and the time
VARIABLES = ("x", "y", "t")


@dataclass(frozen=True, config=EFFECT_CONFIG)
class BodyForce(Effect):
    """``[[loads]] kind = "body_force"``: ``acceleration = ["bx", "by"]`` (m/s^2), ``constants``.

    Each component is a number or an expression in the point's *initial*
    position ``x``, ``y`` (m), the time ``t`` (s) and the table's named
    ``constants`` (e.g. ``constants = { A = 1e-8, c = 100.0 }``), e.g. ``"-pi**2*sin(pi*x)*sin(t)"``:
    a body force is a property of the material, so it follows the point, as the
    fields of a manufactured solution do.  The point receives ``m_p b(t + dt)``,
    carried to the grid as its momentum is (``N.T``, or ``W.T`` with HRZ mass);
    its work is booked like any other force's.  (``ctx.force_time``: ``t`` in the
    centred scheme's starting half step, which balances the stress of ``t``.)

    Why ``t + dt``: the internal force it is added to comes from the stress
    already advanced by the step's strain increment, the stress of ``t + dt``
    (paper section 3.2, steps 4-7), so both forces of a step belong to one
    instant.  Taken at ``t``, the forcing lags a step behind, and on
    ``scenes/manufactured.toml`` (whose body force has a net resultant) the
    rigid translation errs to first order in dt: the largest error of
    consistent cubic splines at spacing 1/16 is 1.4e-2 at ``t``, 4.2e-5 at ``t + dt``.
    """

    kind: Literal["body_force"]
    acceleration: tuple[Union[float, str], Union[float, str]]
    constants: dict[str, float] = field(default_factory=dict)

    name = "body_force"
    stage = Stage.EXTERNAL_FORCE

    @model_validator(mode="after")
    def _expressions(self):
        compile_vector("acceleration", self.acceleration, VARIABLES, self.constants)
        return self

    def bind(self, simulation):
        particles = simulation.particles
        x, y = particles.x0[:, 0], particles.x0[:, 1]
        mass = particles.mass
        components = compile_vector("acceleration", self.acceleration, VARIABLES, self.constants)

        def add_body_force(ctx: StepContext) -> None:
            t = np.float64(ctx.force_time)  # t + dt in the step, t at the centred scheme's start
            with np.errstate(over="ignore", invalid="ignore"):  # checked below: a stop naming the key
                forces = mass[:, None] * evaluate_vector(components, len(mass), x=x, y=y, t=t)
            bad = ~np.isfinite(forces).all(axis=1)
            if bad.any():
                raise ForceNotFinite(self, "acceleration", np.flatnonzero(bad), float(t))
            ctx.add_point_forces(self.name, forces)

        return add_body_force
