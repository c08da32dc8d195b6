"""A probe: an observer that records one number of the state at every record step."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..effects.base import Effect
from ..step import Stage, StepContext


@dataclass
class Probe(Effect):
    """An observer that records ``function(ctx)`` at every record step.

    Pass it to :class:`femgrid_mpm.solver.Simulation` as one of its
    ``observers``; ``times`` and ``values`` fill as the run goes, and start
    afresh when it is bound to another simulation.
    """

    function: Callable[[StepContext], float]
    name: str = "probe"
    times: list = field(default_factory=list)
    values: list = field(default_factory=list)

    stage = Stage.OBSERVE

    def bind(self, simulation):
        # one probe reused for a second run would otherwise append that run's records to the
        # first's, and a period measured on them is wrong without an error; new lists leave
        # the first run's arrays, if the caller kept them, as they were
        self.times, self.values = [], []

        def record(ctx: StepContext) -> None:
            self.times.append(ctx.time)
            self.values.append(self.function(ctx))

        return record

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(self.times), np.asarray(self.values)
