"""An exact solution declared in the scene, and the run's error against it.

``[reference]`` gives the exact displacement as expressions in the point's
*initial* position ``x``, ``y`` (m) and the time ``t`` (s).  At every record
the observer measures

    e(t) = sqrt( mean_p |u_p - u_exact(x0_p, t)|^2 ),   u_p = x_p - x0_p,

and the run's error is ``e`` divided by the largest ``|u_exact|`` over the
records (the field's scale, so that errors of different scenes compare):
``error_end`` at the last record, ``error_max`` the largest over the records.
With ``when = "end"`` (a static solution) only the last record counts, and
the scale is that record's.  With ``period`` the measured first period is
reported against it: the period of the zero crossings of the points'
displacement projected on the exact field at its largest, ``sum_p m_p u_p .
u_exact(x0_p, t*)``, which for a standing mode is the mode's own amplitude.

Examples
--------
>>> reference = ExactReference(displacement=("A*sin(w*t)*x", 0.0), constants={"A": 1e-5, "w": 2.0})
>>> reference.when, reference.period
('always', None)
"""

from __future__ import annotations

from dataclasses import field
from typing import Literal, Union

import numpy as np
from pydantic import PositiveFloat, model_validator
from pydantic.dataclasses import dataclass

from ..expressions import compile_vector, evaluate_vector
from ..oscillation import zero_crossing_period
from ..step import Stage, StepContext
from .base import Effect, Recorder
from .config import EFFECT_CONFIG

#: the variables of the reference's expressions: the point's initial position and the time
VARIABLES = ("x", "y", "t")
#: times at which the exact field is sampled to find the shape its period is measured on
SHAPE_SAMPLES = 64


@dataclass(frozen=True, config=EFFECT_CONFIG)
class ExactReference(Effect):
    """``[reference]``: ``displacement = ["ux", "uy"]`` (m), ``constants``, ``when``, ``period`` (s)."""

    displacement: tuple[Union[float, str], Union[float, str]]
    constants: dict[str, float] = field(default_factory=dict)
    when: Literal["always", "end"] = "always"
    period: Union[PositiveFloat, None] = None

    name = "reference"
    stage = Stage.OBSERVE

    @model_validator(mode="after")
    def _expressions(self):
        compile_vector("displacement", self.displacement, VARIABLES, self.constants)
        return self

    def exact(self):
        """``u(x, y, t) -> (n, 2)``: the exact displacement at initial positions ``x``, ``y``."""
        components = compile_vector("displacement", self.displacement, VARIABLES, self.constants)

        def displacement(x: np.ndarray, y: np.ndarray, t: float) -> np.ndarray:
            return evaluate_vector(components, len(x), x=x, y=y, t=np.float64(t))

        return displacement

    def bind(self, simulation) -> "ReferenceError":
        return ReferenceError(self, simulation)


class ReferenceError(Recorder):
    """The record of :class:`ExactReference`: per record the time, the RMS error (m),
    the largest exact displacement (m) and the projection the period is measured on."""

    FIELDS = ("time", "rms", "peak", "projection")

    def __init__(self, spec: ExactReference, simulation):
        self.spec = spec
        particles = simulation.particles
        self.particles = particles
        self.x, self.y = particles.x0[:, 0].copy(), particles.x0[:, 1].copy()
        self.exact = spec.exact()
        self.rows: list[tuple[float, float, float, float]] = []
        # the shape of the period's projection: the exact field where it is largest (mass-weighted)
        horizon = spec.period if spec.period is not None else simulation.scene.time.end
        samples = [self.exact(self.x, self.y, t) for t in np.linspace(0.0, horizon, SHAPE_SAMPLES + 1)[1:]]
        norms = [float(np.sum(particles.mass[:, None] * u**2)) for u in samples]
        self.shape = samples[int(np.argmax(norms))]

    def __call__(self, ctx: StepContext) -> None:
        p = self.particles
        displacement = p.x - p.x0
        exact = self.exact(self.x, self.y, ctx.time)
        rms = float(np.sqrt(np.mean(np.sum((displacement - exact) ** 2, axis=1)))) if p.n else 0.0
        peak = float(np.sqrt(np.max(np.sum(exact**2, axis=1)))) if p.n else 0.0
        projection = float(np.sum(p.mass * np.sum(displacement * self.shape, axis=1)))
        self.rows.append((float(ctx.time), rms, peak, projection))

    def _scale(self, upto: int) -> float:
        """The largest exact displacement of the records up to ``upto`` (of that record alone
        for a static solution)."""
        if self.spec.when == "end":
            return self.rows[upto][2]
        return max(row[2] for row in self.rows[: upto + 1])

    def relative(self, index: int) -> float:
        """Record ``index``'s RMS error over the scale so far (the last record's is ``error_end``)."""
        rms, scale = self.rows[index][1], self._scale(index)
        return rms / scale if scale > 0 else (0.0 if rms == 0 else float("inf"))

    def columns(self) -> dict:
        return {"reference_error": lambda: self.relative(len(self.rows) - 1)}

    def summary(self) -> dict:
        """``{"reference": {...}}``: ``error_end``, ``error_max``, the measured ``period``,
        ``period_exact`` and ``period_error`` (relative), ``when``; errors None before a record."""
        spec, rows = self.spec, self.rows
        entry = {"when": spec.when, "error_end": None, "error_max": None, "scale": None,
                 "period": None, "period_exact": spec.period, "period_error": None}
        if rows:
            last = len(rows) - 1
            scale = self._scale(last)
            entry["scale"] = scale
            entry["error_end"] = self.relative(last)
            if spec.when == "end":
                entry["error_max"] = entry["error_end"]
            else:
                largest = max(row[1] for row in rows)
                entry["error_max"] = largest / scale if scale > 0 else (0.0 if largest == 0 else float("inf"))
        if spec.period is not None and len(rows) > 2:
            times, projections = np.array([row[0] for row in rows]), np.array([row[3] for row in rows])
            measured = zero_crossing_period(times, projections)
            if np.isfinite(measured):
                entry["period"] = measured
                entry["period_error"] = measured / spec.period - 1.0
        return {"reference": entry}

    def state(self) -> np.ndarray:
        return np.array(self.rows, dtype=float).reshape(-1, len(self.FIELDS))

    def restore(self, rows: np.ndarray) -> None:
        rows = np.asarray(rows, dtype=float)
        if rows.size and (rows.ndim != 2 or rows.shape[1] != len(self.FIELDS)):
            raise ValueError(f"reference.rows: shape {rows.shape}, the reference record has {len(self.FIELDS)} columns")
        self.rows[:] = [tuple(float(v) for v in row) for row in rows]
