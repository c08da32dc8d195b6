"""The period of an oscillating record, from its zero crossings.

Examples
--------
>>> import numpy as np
>>> t = np.linspace(0, 10, 2001)
>>> round(zero_crossing_period(t, np.sin(2 * np.pi * t / 3.0)), 6)
3.0
"""

from __future__ import annotations

import numpy as np


def zero_crossing_period(times: np.ndarray, values: np.ndarray) -> float:
    """Period of an oscillating signal from its zero crossings.

    Crossings are located by linear interpolation; the period is twice the
    mean distance between the first and the last crossing.  Returns NaN with
    fewer than two crossings.

    Raises
    ------
    ValueError
        Unless ``times`` and ``values`` are 1D arrays of the same length with
        ``times`` non-decreasing: records of two runs one after the other, or
        of several signals, gave a wrong period or an IndexError from inside.
    """
    times, values = np.asarray(times, dtype=float), np.asarray(values, dtype=float)
    if times.ndim != 1 or values.shape != times.shape:
        raise ValueError(f"times and values must be 1D arrays of one length, got shapes {times.shape} and {values.shape}")
    if np.any(np.diff(times) < 0):
        first = int(np.flatnonzero(np.diff(times) < 0)[0]) + 1
        raise ValueError(f"times must not decrease: times[{first}] = {times[first]:g} follows {times[first - 1]:g} "
                         "(the records of two runs?)")
    sign_change = np.flatnonzero(np.signbit(values[:-1]) != np.signbit(values[1:]))
    if len(sign_change) < 2:
        return float("nan")
    t0, t1 = times[sign_change], times[sign_change + 1]
    v0, v1 = values[sign_change], values[sign_change + 1]
    crossings = t0 - v0 * (t1 - t0) / (v1 - v0)
    return float(2 * (crossings[-1] - crossings[0]) / (len(crossings) - 1))
