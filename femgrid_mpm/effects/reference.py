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

import warnings
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
    the largest exact displacement (m) and the projection the period is measured on.

    An exact field that is NaN or infinite at a point is refused when the run is built
    (ValueError naming ``reference.displacement``, the time and the point), checked at
    t = 0, at the times sampled for the period's shape and at ``time.end``; one found
    later, between those, makes the errors from that record on undefined (None in the
    summary, with a ``note`` and one warning), never a silent inf or NaN.
    """

    FIELDS = ("time", "rms", "peak", "projection")

    def __init__(self, spec: ExactReference, simulation):
        self.spec = spec
        particles = simulation.particles
        self.particles = particles
        self.x, self.y = particles.x0[:, 0].copy(), particles.x0[:, 1].copy()
        self.exact = spec.exact()
        self.rows: list[tuple[float, float, float, float]] = []
        # the shape of the period's projection: the exact field where it is largest (mass-weighted)
        end = simulation.scene.time.end
        horizon = spec.period if spec.period is not None else end
        times = np.linspace(0.0, horizon, SHAPE_SAMPLES + 1)[1:]
        for t in (0.0, end):
            self.finite(self.exact(self.x, self.y, t), t)
        samples = [self.finite(self.exact(self.x, self.y, t), t) for t in times]
        norms = [rms_norm(np.sqrt(particles.mass)[:, None] * u) for u in samples]
        shape = samples[int(np.argmax(norms))]
        # scaled to a largest component of 1: the zero crossings are the same, and no product overflows
        largest = float(np.max(np.abs(shape))) if shape.size else 0.0
        self.shape = shape / largest if largest > 0 else shape

    def finite(self, exact: np.ndarray, t: float) -> np.ndarray:
        """``exact`` (the field at time ``t``) if finite everywhere; else ValueError naming the key."""
        bad = ~np.isfinite(exact).all(axis=1)
        if bad.any():
            first = int(np.argmax(bad))
            raise ValueError(f"reference.displacement: gives NaN or infinity at {int(bad.sum())} point(s) at "
                             f"t = {t:g} s, the first at ({self.x[first]:g}, {self.y[first]:g})")
        return exact

    def __call__(self, ctx: StepContext) -> None:
        p = self.particles
        displacement = p.x - p.x0
        exact = self.exact(self.x, self.y, ctx.time)
        if not np.isfinite(exact).all():
            if self.undefined_from() is None:
                warnings.warn(f"reference.displacement: gives NaN or infinity at t = {ctx.time:.6g} s: the "
                              "reference errors from then on are undefined", RuntimeWarning)
            self.rows.append((float(ctx.time), np.nan, np.nan, np.nan))
            return
        with np.errstate(over="ignore", invalid="ignore"):  # a displacement beyond 1e308: inf, no warning
            rms = rms_norm(displacement - exact)
            projection = float(np.sum(p.mass * np.sum(displacement * self.shape, axis=1)))
        peak = float(np.max(np.hypot(exact[:, 0], exact[:, 1]))) if p.n else 0.0
        self.rows.append((float(ctx.time), rms, peak, projection))

    def undefined_from(self) -> float | None:
        """The time of the first record where the exact field was not finite, or None."""
        return next((row[0] for row in self.rows if np.isnan(row[2])), None)

    def _scale(self, upto: int) -> float:
        """The largest exact displacement of the records up to ``upto`` (of that record alone
        for a static solution)."""
        if self.spec.when == "end":
            return self.rows[upto][2]
        return max(row[2] for row in self.rows[: upto + 1])

    def relative(self, index: int) -> float:
        """Record ``index``'s RMS error over the scale so far (the last record's is ``error_end``);
        0 where both are 0; NaN where it is undefined: an error against an exact field that is
        0 (scale 0), or one that is not finite."""
        rms, scale = self.rows[index][1], self._scale(index)
        if scale > 0:
            return rms / scale
        return 0.0 if rms == 0 else float("nan")

    def columns(self) -> dict:
        return {"reference_error": lambda: self.relative(len(self.rows) - 1)}

    def summary(self) -> dict:
        """``{"reference": {...}}``: ``error_end``, ``error_max`` (relative to ``scale``),
        ``rms_end``, ``rms_max`` (m), the measured ``period``, ``period_exact`` and
        ``period_error`` (relative), ``when``; errors None before a record.  An exact field
        that is 0 over the records (scale 0) or not finite leaves the relative errors None
        and says why in ``note``."""
        spec, rows = self.spec, self.rows
        entry = {"when": spec.when, "error_end": None, "error_max": None, "scale": None, "rms_end": None,
                 "rms_max": None, "period": None, "period_exact": spec.period, "period_error": None}
        undefined = self.undefined_from()
        if undefined is not None:
            entry["note"] = (f"reference.displacement gives NaN or infinity at t = {undefined:.6g} s: "
                             "the errors are undefined")
        elif rows:
            last = len(rows) - 1
            scale = self._scale(last)
            counted = rows[last:] if spec.when == "end" else rows
            entry["scale"] = scale
            entry["rms_end"] = rows[last][1]
            entry["rms_max"] = max(row[1] for row in counted)
            if scale > 0:
                entry["error_end"] = rows[last][1] / scale
                entry["error_max"] = entry["rms_max"] / scale
            elif entry["rms_max"] == 0:  # the run is at rest as its reference is
                entry["error_end"] = entry["error_max"] = 0.0
            else:
                entry["note"] = ("the exact displacement is 0 at every record counted: an error relative to it "
                                 "is undefined; rms_end and rms_max are the absolute errors (m)")
        if spec.period is not None and len(rows) > 2 and undefined is None:
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


def rms_norm(vectors: np.ndarray) -> float:
    """``sqrt(mean_p |v_p|^2)`` of (n, 2) vectors, 0 for none; scaled by the largest component
    first, so that vectors beyond 1e154 do not overflow their squares."""
    if not len(vectors):
        return 0.0
    largest = float(np.max(np.abs(vectors)))
    if not 0 < largest < np.inf:  # 0, inf or NaN: the norm is that
        return largest
    scaled = vectors / largest
    return largest * float(np.sqrt(np.mean(np.sum(scaled * scaled, axis=1))))
