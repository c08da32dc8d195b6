"""The numbers of a sweep's report: orders of convergence, Richardson's estimate, the
Pareto front of cost and error, and the cheapest run for a target error.

Pure functions of plain sequences (no files, no figures).  Spacings are given
coarsest first or in any order: each function sorts them, coarsest first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: a fitted order at or below this is no convergence
LEAST_ORDER = 0.2


def _sorted(spacings, errors) -> tuple[list[float], list[float]]:
    pairs = sorted(zip(spacings, errors), key=lambda pair: -pair[0])
    return [float(h) for h, _ in pairs], [float(e) for _, e in pairs]


def observed_orders(spacings, errors) -> list[float]:
    """The order of each successive pair of spacings, coarsest first:
    ``log(e_i / e_{i+1}) / log(h_i / h_{i+1})``.

    >>> [round(p, 4) for p in observed_orders([0.5, 0.25, 0.125], [0.1, 0.03, 0.01])]
    [1.737, 1.585]
    """
    h, e = _sorted(spacings, errors)
    return [math.log(e[i] / e[i + 1]) / math.log(h[i] / h[i + 1]) for i in range(len(h) - 1)]


def fitted_order(spacings, errors) -> tuple[float, float]:
    """The least-squares fit ``e = C h^p`` in logarithms; ``(p, C)``.

    Raises
    ------
    ValueError
        With fewer than two distinct spacings.
    """
    h, e = _sorted(spacings, errors)
    if len(set(h)) < 2:
        raise ValueError("a fitted order needs two distinct spacings at least")
    x = [math.log(value) for value in h]
    y = [math.log(value) for value in e]
    mean_x, mean_y = sum(x) / len(x), sum(y) / len(y)
    slope = sum((a - mean_x) * (b - mean_y) for a, b in zip(x, y)) / sum((a - mean_x) ** 2 for a in x)
    return slope, math.exp(mean_y - slope * mean_x)


@dataclass(frozen=True)
class Richardson:
    """``e(h) = limit + C h^order`` through the errors at the three finest spacings: the
    order they show and the error left as ``h -> 0`` (from the time step, the kinematics:
    whatever the spacing does not control)."""

    order: float
    limit: float
    constant: float


def richardson(spacings, errors) -> Richardson | None:
    """Richardson's estimate from the three finest spacings, or None when the errors there
    do not decrease monotonically (no positive order fits them).

    With a constant ratio ``r`` of spacings, ``order = log((e1 - e2) / (e2 - e3)) / log r``
    and ``limit = e3 - (e2 - e3) / (r^order - 1)``; other ratios are solved for the order.

    Raises
    ------
    ValueError
        With fewer than three distinct spacings.
    """
    h, e = _sorted(spacings, errors)
    if len(set(h)) < 3:
        raise ValueError("Richardson's estimate needs three distinct spacings at least")
    (h1, h2, h3), (e1, e2, e3) = h[-3:], e[-3:]
    if not (e1 > e2 > e3):
        return None
    ratio = (e1 - e2) / (e2 - e3)

    def mismatch(p: float) -> float:
        try:
            return (h1**p - h2**p) / (h2**p - h3**p) - ratio
        except (OverflowError, ZeroDivisionError):  # spacings far from 1 (1e100) at a high order
            return math.inf

    low, high = 1e-6, 1.0
    if mismatch(low) >= 0:
        return None  # the errors fall more slowly than any positive order allows
    while mismatch(high) < 0:
        high *= 2
        if high > 64:
            return None
    for _ in range(200):  # bisection: mismatch increases with p
        middle = 0.5 * (low + high)
        if mismatch(middle) < 0:
            low = middle
        else:
            high = middle
    order = 0.5 * (low + high)
    constant = (e1 - e2) / (h1**order - h2**order)
    return Richardson(order, e3 - constant * h3**order, constant)


def convergence_verdict(spacings, errors) -> str | None:
    """A sentence when the errors do not converge with the spacing, or level off; None
    when they converge.  Does not converge: a fitted order at or below
    :data:`LEAST_ORDER`, or the finest spacing no better than the coarsest."""
    h, e = _sorted(spacings, errors)
    if len(set(h)) < 2:
        return None
    order, _ = fitted_order(h, e)
    orders = observed_orders(h, e)
    growing = [f"from h = {h[i]:g} to {h[i + 1]:g} m" for i, p in enumerate(orders) if p < 0]
    if order <= LEAST_ORDER or e[-1] >= e[0]:
        text = f"does not converge (fitted order {order:.2f})"
        return text + (f": the error grows {', '.join(growing)}" if growing else "")
    if len(set(h)) >= 3:
        estimate = richardson(h, e)
        if estimate is not None and estimate.limit > 0.5 * e[-1]:
            return (f"levels off near an error of {estimate.limit:.3g}, which does not come from the spacing "
                    "(the time step or the kinematics)")
    if growing:
        return f"converges with fitted order {order:.2f}, but the error grows {', '.join(growing)}"
    return None


def pareto_front(costs, errors) -> list[int]:
    """The indices of the points no other point beats in both cost and error (at most as
    costly and at most as wrong, one of them strictly), cheapest first.

    >>> pareto_front([1, 2, 1.5, 3, 4], [0.1, 0.05, 0.2, 0.05, 0.01])
    [0, 1, 4]
    """
    order = sorted(range(len(costs)), key=lambda i: (costs[i], errors[i]))
    front, best = [], math.inf
    for index in order:
        if errors[index] < best:
            front.append(index)
            best = errors[index]
    return front


@dataclass(frozen=True)
class Cheapest:
    """The cheapest run reaching a target error, and the next method's cheapest one.

    ``best`` and ``runner_up`` are indices into the runs given (``runner_up`` None when
    no other method reaches the target); ``ratio`` is the runner-up's cost over the best's;
    ``missing`` the methods with no run reaching the target.
    """

    target: float
    best: int | None
    runner_up: int | None
    ratio: float | None
    missing: tuple[str, ...]


def cheapest_for_target(methods, costs, errors, target: float) -> Cheapest:
    """The cheapest run with ``error <= target``, and by how much it beats the cheapest run
    of any other method reaching the target.

    >>> c = cheapest_for_target(["a", "a", "b", "b", "c"], [1, 4, 2, 3, 0.5], [0.2, 0.01, 0.05, 0.001, 0.5], 0.05)
    >>> c.best, c.runner_up, c.ratio, c.missing
    (2, 1, 2.0, ('c',))
    """
    reaching = [i for i in range(len(costs)) if errors[i] is not None and errors[i] <= target]
    every = list(dict.fromkeys(methods))
    if not reaching:
        return Cheapest(target, None, None, None, tuple(every))
    best = min(reaching, key=lambda i: costs[i])
    others = [i for i in reaching if methods[i] != methods[best]]
    runner_up = min(others, key=lambda i: costs[i]) if others else None
    ratio = costs[runner_up] / costs[best] if runner_up is not None and costs[best] > 0 else None
    found = {methods[i] for i in reaching}
    return Cheapest(target, best, runner_up, ratio, tuple(m for m in every if m not in found))
