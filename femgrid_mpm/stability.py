"""Critical time step estimates.

``dt_crit = factor(basis, mass) * element_width / c_p`` with ``c_p`` the
largest dilatational wave speed of the scene's materials.  The factors are
those of a Bloch (von Neumann) analysis of a full grid for the explicit
central-difference step; they are checked against the largest eigenvalue
of ``M^-1 K`` in the tests.  Serendipity with row-sum lumping has negative
corner masses and no stable step at all.
"""

from __future__ import annotations

import math

#: (basis, mass) -> dt_crit * c_p / element_width
BLOCH_FACTORS = {
    ("q1", "lumped"): 1.0,
    ("q1", "consistent"): 0.5,
    ("q2", "lumped"): 0.4,
    ("q2", "consistent"): 0.2,
    ("bspline3", "lumped"): 1.9,
    ("bspline3", "consistent"): 0.55,
    # the open knot vector's boundary functions are narrower: a guess until
    # the eigenvalue estimate replaces this table
    ("bspline3_open", "lumped"): 1.0,
    ("bspline3_open", "consistent"): 0.3,
    ("serendipity", "lumped"): 0.0,
    ("serendipity", "consistent"): 0.2,
}


def critical_time_step(basis: str, mass: str, element_width: float, wave_speed: float) -> float:
    """Estimated largest stable time step (s); 0 if no step is stable."""
    factor = BLOCH_FACTORS[(basis, mass)]
    return factor * element_width / wave_speed if wave_speed > 0 else math.inf
