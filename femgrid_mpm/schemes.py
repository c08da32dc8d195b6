"""The time integrations ``[solver] scheme`` chooses: the paper's step and compositions of it.

Every scheme is a sequence of the paper's sub-steps (section 3.2): project the points'
velocity to the grid, move and strain the points by ``drift * dt`` with that grid velocity
(Eqs. 18, 20), then change their velocity by ``kick * dt * N a`` with the forces of the moved
state (Eq. 19).  For small motions on a fixed grid with consistent mass this is the
kick-drift form of the central difference, ``U(k+2) - 2 U(k+1) + U(k) = dt^2 M^-1 F(k+1)``,
and a scheme is a splitting method of the ODE in (U, V) (Hairer, Lubich & Wanner,
*Geometric Numerical Integration*, 2nd ed., Springer 2006, sections II.4-II.5, V.3):

``paper``
    One sub-step ``(1, 1)``, started from v(0): second order when a(0) = 0, first order
    otherwise (the velocity it carries is that of t + dt/2; v(0) misses dt/2 a(0)).
``centred``
    The same sub-step, started with the half kick ``v += dt/2 N a(0)`` and ended with a
    half kick: the velocity Verlet method, second order from any start.
``yoshida4``
    Three centred steps of ``w1 dt, w0 dt, w1 dt``, ``w1 = 1 / (2 - 2^(1/3))``, ``w0 = 1 - 2 w1``
    (Yoshida, Phys. Lett. A 150 (1990) 262-268): fourth order, because the centred step is
    symmetric (its adjoint is itself) and ``2 w1^3 + w0^3 = 0`` cancels its third-order term.
    Written as sub-steps, the half kicks between two centred steps merge: drifts ``w1, w0,
    w1``, kicks ``(w1 + w0)/2, (w0 + w1)/2, w1`` after a start kick of ``w1 / 2``.  The middle
    drift is negative: the points step back by 1.7 dt.  Three projections and force passes a
    step; stable for ``omega_max dt < 1.5734`` (against 2), so per force pass its step is
    0.52 of the central difference's.

A scheme's ``stability_limit`` is ``omega_max dt`` at the edge of stability for the
harmonic oscillator; the critical step of a run is ``stability_limit / omega_max``
(:func:`femgrid_mpm.stability.critical_time_step`).  Adding a scheme is one entry below.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Scheme:
    """A time integration as the paper's sub-steps.

    Attributes
    ----------
    drifts, kicks : tuple of float
        Each sub-step's drift (points moved and strained by ``drift * dt``) and kick (their
        velocity changed by ``kick * dt * N a``), in units of dt.
    start_kick : float
        The kick before the first sub-step, with the stress and forces of t = 0 (0: none);
        the run's last kick is shortened by as much, so that its final velocity is that of
        the end time.
    stability_limit : float
        ``omega_max dt`` at the edge of stability.
    order : int
        The order in dt from any start.
    """

    drifts: tuple[float, ...]
    kicks: tuple[float, ...]
    start_kick: float
    stability_limit: float
    order: int

    @functools.cached_property
    def force_times(self) -> tuple[float, ...]:
        """The instant of each sub-step's forces, in units of dt after the step's start: the
        drifts' running sum, the last exactly 1 (the stress of the step's end)."""
        elapsed = [math.fsum(self.drifts[: index + 1]) for index in range(len(self.drifts))]
        return (*elapsed[:-1], 1.0)

    @property
    def passes(self) -> int:
        """Projections and force passes a step."""
        return len(self.drifts)


def _yoshida4() -> Scheme:
    w1 = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
    w0 = 1.0 - 2.0 * w1
    # the largest omega dt at which the composed step's amplification matrix has
    # |trace| / 2 <= 1 (computed by bisection; checked in tests/test_schemes.py)
    return Scheme(drifts=(w1, w0, w1), kicks=(0.5 * (w1 + w0), 0.5 * (w0 + w1), w1), start_kick=0.5 * w1,
                  stability_limit=1.5734019474, order=4)


#: ``[solver] scheme`` -> its sub-steps
SCHEMES: dict[str, Scheme] = {
    "paper": Scheme(drifts=(1.0,), kicks=(1.0,), start_kick=0.0, stability_limit=2.0, order=1),
    "centred": Scheme(drifts=(1.0,), kicks=(1.0,), start_kick=0.5, stability_limit=2.0, order=2),
    "yoshida4": _yoshida4(),
}
