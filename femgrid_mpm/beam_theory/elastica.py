"""Large deflection: the inextensible elastica under a dead vertical tip load
(Bisshopp & Drucker 1945), by elliptic integrals and by shooting."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq
from scipy.special import ellipe, ellipeinc, ellipkinc, ellipkm1


class ElasticaTip(NamedTuple):
    """Tip of the elastica (all positive for a downward load).

    deflection : float
        Downward tip displacement (m).
    shortening : float
        Horizontal tip displacement towards the clamp (m).
    rotation : float
        Tip rotation (rad), the tip turning downward.
    """

    deflection: float
    shortening: float
    rotation: float


def load_parameter(P: float, L: float, E: float, I: float) -> float:
    """Bisshopp & Drucker's ``alpha = P L^2 / (E I)`` (-)."""
    return P * L**2 / (E * I)


def _elliptic_root_mismatch(tip_rotation: float, alpha: float) -> float:
    """Dimensionless length from the first integral minus ``sqrt(alpha)``; zero at the solution.

    With ``theta`` the downward slope, ``theta'' = -alpha cos(theta)`` and
    ``theta'(1) = 0`` integrate once to ``theta'^2 = 2 alpha (sin theta0 - sin theta)``.
    The substitution ``1 + sin(theta) = 2 m sin^2(phi)``, ``m = (1 + sin theta0) / 2``
    turns the arc length into ``(K(m) - F(phi_root, m)) / sqrt(alpha)``.
    """
    # 1 - m and phi_root are written so that neither loses digits near theta0 = pi/2 or 0.
    one_minus_m = np.sin((np.pi / 2 - tip_rotation) / 2) ** 2
    phi_root = np.arctan2(1.0, np.sqrt(np.sin(tip_rotation)))
    return float(ellipkm1(one_minus_m) - ellipkinc(phi_root, 1.0 - one_minus_m) - np.sqrt(alpha))


def _elastica_elliptic(alpha: float) -> ElasticaTip:
    """Dimensionless tip (``L = 1``) from the elliptic-integral closed form."""
    upper = np.pi / 2 - 1e-15  # K diverges at pi/2: the bracket stops just short of it
    tip_rotation = brentq(_elliptic_root_mismatch, 0.0, upper, args=(alpha,), xtol=1e-300, rtol=1e-15, maxiter=400)
    m = (1.0 + np.sin(tip_rotation)) / 2
    phi_root = np.arctan2(1.0, np.sqrt(np.sin(tip_rotation)))
    deflection = 1.0 - 2.0 * (ellipe(m) - ellipeinc(phi_root, m)) / np.sqrt(alpha)
    # Moment balance at the root, EI theta'(0) = P x_tip, with theta'(0) from the first integral.
    tip_abscissa = np.sqrt(2.0 * np.sin(tip_rotation) / alpha)
    return ElasticaTip(float(deflection), float(1.0 - tip_abscissa), float(tip_rotation))


def _elastica_rhs(alpha: float):
    """State ``(theta, theta', x, y)`` along the dimensionless arc length, ``y`` up."""

    def rhs(_, state):
        theta, curvature = state[0], state[1]
        return [curvature, -alpha * np.cos(theta), np.cos(theta), -np.sin(theta)]

    return rhs


def _integrate_elastica(alpha: float, root_curvature: float, s_eval=None, events=None):
    return solve_ivp(
        _elastica_rhs(alpha),
        (0.0, 1.0),
        [0.0, root_curvature, 0.0, 0.0],
        method="DOP853",
        rtol=1e-13,
        atol=1e-15,
        t_eval=s_eval,
        events=events,
    )


def _moment_vanishes(_, state):
    return state[1]


_moment_vanishes.terminal = True
_moment_vanishes.direction = -1


def _tip_moment_mismatch(root_curvature: float, alpha: float) -> float:
    """Tip curvature, or minus the arc length left where the curvature reached zero early.

    On the physical branch the curvature decreases monotonically; too small
    a root curvature lets it vanish before the tip.  Counting that as the
    (negative) length left over keeps the residual monotone, so spurious
    looping solutions of large loads are never bracketed.
    """
    if root_curvature <= 0.0:
        return -1.0
    solution = _integrate_elastica(alpha, root_curvature, events=_moment_vanishes)
    if solution.status == 1:
        return float(solution.t_events[0][0] - 1.0)
    return float(solution.y[1, -1])


def _elastica_shooting(alpha: float) -> ElasticaTip:
    """Dimensionless tip by shooting on the root curvature until the tip moment vanishes.

    The root curvature is ``alpha * x_tip / L``, at most ``alpha`` and, from
    the first integral ``theta'(0)^2 = 2 alpha sin(theta0)``, at most
    ``sqrt(2 alpha)``; the residual is negative at 0 and positive at that
    bound, so ``brentq`` brackets the one physical solution.
    """
    upper = min(alpha, np.sqrt(2.0 * alpha))
    root_curvature = brentq(_tip_moment_mismatch, 0.0, upper, args=(alpha,), xtol=1e-15, rtol=1e-15, maxiter=400)
    theta, _, x, y = _integrate_elastica(alpha, root_curvature).y[:, -1]
    return ElasticaTip(float(-y), float(1.0 - x), float(theta))


def elastica_tip(P: float, L: float, E: float, I: float, method: str = "elliptic") -> ElasticaTip:
    """Large-deflection tip of a cantilever under a vertical dead load (inextensible elastica).

    Solves ``theta'' = -(P / E I) cos(theta)``, ``theta(0) = 0``,
    ``theta'(L) = 0``, with ``theta`` the downward slope of the axis and
    ``s`` the arc length (Bisshopp & Drucker 1945).  Shear and axial
    strain are neglected.

    Parameters
    ----------
    P : float
        Tip force (N per m of thickness), downward positive; it stays vertical.
    L : float
        Length (m).
    E : float
        Bending modulus (Pa); ``E / (1 - nu^2)`` for a plane-strain strip.
    I : float
        Second moment of area (m^4 per m of thickness).
    method : {"elliptic", "shooting"}
        Closed form in incomplete elliptic integrals with a scalar root
        (``brentq`` on the tip rotation), or an independent shooting
        solution (DOP853 with ``rtol = 1e-13``, ``brentq`` on the root
        curvature).  They agree to better than 1e-10 L for
        ``alpha = P L^2 / (E I)`` up to 100; beyond, the tip rotation is
        within 1e-4 of pi/2 and shooting loses accuracy (the closed form
        holds to ``alpha`` of about 1000).

    Returns
    -------
    ElasticaTip
        ``deflection`` and ``shortening`` (m) and ``rotation`` (rad); the
        deflection and rotation change sign with ``P``.
    """
    alpha = abs(load_parameter(P, L, E, I))
    if alpha == 0.0:
        return ElasticaTip(0.0, 0.0, 0.0)
    solvers = {"elliptic": _elastica_elliptic, "shooting": _elastica_shooting}
    if method not in solvers:
        raise ValueError(f"method must be one of {tuple(solvers)}, not {method!r}")
    tip = solvers[method](alpha)
    sign = float(np.sign(P))
    return ElasticaTip(sign * tip.deflection * L, tip.shortening * L, sign * tip.rotation)


def elastica_shape(P: float, L: float, E: float, I: float, n: int = 101) -> tuple[np.ndarray, np.ndarray]:
    """Deformed neutral axis of the elastica, for plotting.

    Parameters
    ----------
    P, L, E, I : float
        As in :func:`elastica_tip`.
    n : int
        Number of points, equally spaced in arc length from root to tip.

    Returns
    -------
    x, y : ndarray, shape (n,)
        Positions (m) of the axis relative to the root's neutral-axis point
        (``y`` up, so negative for a downward load).  Add the undeformed axis
        height (1.5 in the paper's Fig. 9) to overlay on MPM results.
    """
    alpha = load_parameter(P, L, E, I)
    tip = elastica_tip(P, L, E, I)
    # Root curvature from the exact tip: EI theta'(0) = P x_tip.
    root_curvature = alpha * (1.0 - tip.shortening / L)
    solution = _integrate_elastica(alpha, root_curvature, s_eval=np.linspace(0.0, 1.0, n))
    return solution.y[2] * L, solution.y[3] * L
