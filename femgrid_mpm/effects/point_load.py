"""A force on one material point, ramped in time."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import NonNegativeFloat
from pydantic.dataclasses import dataclass

from ..step import Stage, StepContext
from .base import Effect
from .config import EFFECT_CONFIG


@dataclass(frozen=True, config=EFFECT_CONFIG)
class PointLoad(Effect):
    """``[[loads]] kind = "point"``: a force on the point of ``body`` nearest ``at``.

    Parameters
    ----------
    body : str
        Name of the body.
    at : (float, float)
        Where (m); the point nearest to it at t = 0 carries the load for the
        whole run.
    force : (float, float)
        Full force (N per unit thickness).
    ramp : float
        The force grows linearly from zero to full at this time (s), then is
        held; 0 applies it at once.  Taken at the instant of the step's forces
        (``ctx.force_time``, t + dt with the stress of t + dt), as a body force is.
    model : {"force", "paper_eq35"}
        ``"force"``: the point receives ``force``.  ``"paper_eq35"``: the
        paper's Eq. 35, an acceleration ``b = force / m_p * m_p / m_tot`` of
        the point, i.e. the point (and the body) receives only
        ``force * m_p / m_tot``.
    """

    kind: Literal["point"]
    body: str
    at: tuple[float, float]
    force: tuple[float, float]
    ramp: NonNegativeFloat = 0.0
    model: Literal["force", "paper_eq35"] = "force"

    name = "point_load"
    stage = Stage.EXTERNAL_FORCE

    def bind(self, simulation):
        particles = simulation.particles
        members = np.flatnonzero(particles.body == simulation.body_index(self.body))
        offset = particles.x[members] - np.asarray(self.at)
        distance = np.hypot(offset[:, 0], offset[:, 1])  # no overflow for a far-away `at` (the norm's squares did)
        point = int(members[np.argmin(distance)])
        force = np.asarray(self.force, dtype=float)
        if self.model == "paper_eq35":
            force = force * particles.mass[point] / particles.mass[members].sum()
        self_name = f"{self.name}:{self.body}"

        def add_point_load(ctx: StepContext) -> None:
            # the ramp at the forces' instant (t + dt in the step, as the stress's: see BodyForce)
            scale = 1.0 if self.ramp == 0 else min(1.0, ctx.force_time / self.ramp)
            ctx.add_point_forces(self_name, scale * force[None, :], points=np.array([point]))

        add_point_load.point = point  # type: ignore[attr-defined]
        add_point_load.applied_force = force  # type: ignore[attr-defined]
        return add_point_load
