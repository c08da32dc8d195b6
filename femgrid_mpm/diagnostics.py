"""Guards that stop a run with a clear message, and the events they record.

Every stop is a :class:`SimulationStopped` naming the step, the time and the
place (a node or a particle); the run's outputs written so far stay valid.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np


class SimulationStopped(RuntimeError):
    """A run could not go on.  ``result`` holds what was computed so far."""

    def __init__(self, message: str, step: int, time: float, reason: str):
        super().__init__(message)
        self.step = step
        self.time = time
        self.reason = reason
        self.result = None


class NegativeMassWarning(RuntimeWarning):
    """Negative lumped grid masses under the ``warn`` policy."""


@dataclass
class NegativeMassMonitor:
    """Checks the lumped (row-sum) grid masses every step.

    A mass counts as negative below ``-1e-12`` of a full cell's mass
    (rounding in shape functions that are exactly zero must not count).
    The mass ratio reported is ``m_i / reference_mass``, the nodal mass over
    the mass of one full lattice cell (``spacing^2 * density``).

    Parameters
    ----------
    policy : {"error", "warn"}
        Stop the run at the first negative mass, or record it and go on.
    applies : bool
        False for consistent mass, whose matrix is positive semi-definite
        whatever the row sums: negative row sums are still recorded but
        never stop the run.
    """

    reference_mass: float
    policy: str = "error"
    applies: bool = True
    steps_with_negative: int = 0
    first_step: int | None = None
    min_ratio: float = field(default=np.inf)
    max_nodes: int = 0

    def check(self, lumped: np.ndarray, step: int, time: float, nodes: np.ndarray) -> None:
        ratio = lumped.min() / self.reference_mass
        self.min_ratio = min(self.min_ratio, float(ratio))
        if ratio >= -1e-12:
            return
        count = int(np.count_nonzero(lumped < -1e-12 * self.reference_mass))
        self.steps_with_negative += 1
        self.max_nodes = max(self.max_nodes, count)
        if self.first_step is None:
            self.first_step = step
        if not self.applies or (self.policy != "error" and self.steps_with_negative > 1):
            return  # nothing to say: the message is built only when it is raised or warned
        negative = np.flatnonzero(lumped < -1e-12 * self.reference_mass)
        worst = negative[np.argmin(lumped[negative])]
        message = (
            f"step {step} (t = {time:.6g} s): negative grid mass at {len(negative)} node(s), "
            f"the most negative is node {worst} at ({nodes[worst, 0]:g}, {nodes[worst, 1]:g}) "
            f"with {lumped[worst] / self.reference_mass:.3g} of a full cell's mass"
        )
        if not self.applies:
            return
        if self.policy == "error":
            raise SimulationStopped(message, step, time, "negative_mass")
        if self.steps_with_negative == 1:
            warnings.warn(message + " (policy 'warn': going on)", NegativeMassWarning, stacklevel=3)

    def summary(self) -> dict:
        return {
            "steps_with_negative_mass": self.steps_with_negative,
            "first_step": self.first_step,
            "min_mass_ratio": None if not np.isfinite(self.min_ratio) else self.min_ratio,
            "max_negative_nodes": self.max_nodes,
        }
