"""``final.npz`` and ``summary.json``: the points' last state and how the run ended."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .files import atomic_path, atomic_write


def write_final_state(path: Path, particles, step: int, time: float) -> None:
    """``final.npz``: the points' state, atomically.

    Arrays (n points): ``x0``, ``x`` (n, 2) m; ``v`` (n, 2) m/s; ``stress``
    (n, 3) Pa and ``strain`` (n, 3), columns xx, yy, xy (tensor shear);
    ``mass`` (n,) kg per unit thickness; ``volume`` (n,) m^2 per unit
    thickness; ``body`` (n,) int, the body's index in scene order; the
    scalars ``step`` and ``time`` (s) of the state; and, when the particles
    carry it, ``deformation_gradient`` (n, 4): F_xx, F_xy, F_yx, F_yy.
    """
    arrays = {
        "x0": particles.x0,
        "x": particles.x,
        "v": particles.v,
        "stress": particles.stress,
        "strain": particles.strain,
        "mass": particles.mass,
        "volume": particles.volume,
        "body": particles.body,
        "step": np.int64(step),
        "time": np.float64(time),
    }
    if particles.deformation_gradient is not None:
        arrays["deformation_gradient"] = particles.deformation_gradient
    with atomic_path(path) as temporary, temporary.open("wb") as handle:
        np.savez(handle, **arrays)


def json_safe(value):
    """``value`` with numpy scalars as Python numbers and NaN/inf as strings (strict JSON)."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    return value


def write_summary(path: Path, summary: dict) -> None:
    atomic_write(path, json.dumps(json_safe(summary), indent=2, allow_nan=False) + "\n")
