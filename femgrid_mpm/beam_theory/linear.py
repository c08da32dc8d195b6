"""Linear theory of the tip-loaded cantilever: Navier's stress, Timoshenko & Goodier's
2D solution, Euler-Bernoulli and Timoshenko beam formulas."""

from __future__ import annotations

import numpy as np

from .section import plane_elastic_constants, second_moment_of_area

ROOT_CONDITIONS = ("horizontal_element", "vertical_element")


def bending_moment(x, P: float, L: float):
    """Bending moment ``M(x) = P (L - x)`` (N m/m) of the tip-loaded cantilever.

    Sign: positive ``M`` stretches the fibres at ``y > 0``, so that
    ``sigma_x = M y / I`` (the paper's Eq. 22).  The paper writes
    ``M(x) = (x - L) F``, which is the same moment when ``F`` is the signed
    upward force component (``F = -P``).
    """
    return P * (L - np.asarray(x, dtype=float))


def navier_stress(x, y, P: float, L: float, I: float):
    """Navier's bending stress ``sigma_x = M(x) y / I = P (L - x) y / I`` (Pa).

    Parameters
    ----------
    x, y : array_like
        Position along the beam from the clamp and above the neutral axis (m).
    P : float
        Downward tip force (N per m of thickness).
    L : float
        Beam length (m).
    I : float
        Second moment of area (m^4 per m of thickness).

    Returns
    -------
    ndarray
        Tension (positive) in the upper fibres for a downward load.
    """
    return bending_moment(x, P, L) * np.asarray(y, dtype=float) / I


def timoshenko_goodier_stress(x, y, P: float, L: float, H: float):
    """Exact 2D stress field of the end-loaded cantilever (T&G art. 21), in the paper's frame.

    Returns
    -------
    sigma_x, sigma_y, tau_xy : ndarray
        ``P (L - x) y / I``, ``0`` and ``-P (c^2 - y^2) / (2 I)`` (Pa), with
        ``c = H / 2``.  The shear traction on the tip face sums to ``-P``
        (downward); it is the parabolic distribution the solution needs at
        the loaded end.
    """
    x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    inertia, half_height = second_moment_of_area(H), H / 2.0
    sigma_x = navier_stress(x, y, P, L, inertia)
    tau_xy = -P * (half_height**2 - y**2) / (2.0 * inertia)
    return sigma_x, np.zeros_like(sigma_x), tau_xy


def timoshenko_goodier_displacement(
    x, y, P: float, L: float, H: float, E: float, nu: float, root: str = "horizontal_element", plane: str = "stress"
):
    """Displacements of the end-loaded cantilever, 2D elasticity (Timoshenko & Goodier, art. 21).

    The paper's Eqs. 33-34 are T&G's formulas with the load at ``x = 0`` and
    the support at ``x = L`` and ``y`` pointing down.  Mapped to the paper's
    frame (clamp at ``x = 0``, load at ``x = L``, ``y`` up, ``P > 0`` down):

    ``u = P x (2L - x) y / (2 E I) - nu P y^3 / (6 E I) + P y^3 / (6 G I) - P c^2 y / (2 G I)``

    ``v = -P x^2 (3L - x) / (6 E I) - nu P (L - x) y^2 / (2 E I)``

    for root condition (a), plus the rigid rotation ``omega = -P c^2 / (2 G I)``
    (``u -= omega y``, ``v += omega x``) for condition (b).

    Parameters
    ----------
    x, y : array_like
        Undeformed position (m): along the beam from the root, above the neutral axis.
    P : float
        Downward tip force (N per m of thickness), applied as the parabolic
        shear traction of :func:`timoshenko_goodier_stress`.
    L, H : float
        Length and height (m).
    E, nu : float
        Young's modulus (Pa) and Poisson's ratio.
    root : {"horizontal_element", "vertical_element"}
        How the root is held (both fix ``u = v = 0`` at the root's neutral-axis point):

        * ``"horizontal_element"`` (T&G case a, the paper's Eqs. 33-34): the
          axis is horizontal at the root, ``dv/dx = 0``; the root section
          rotates by the shear angle ``P c^2 / (2 G I)`` and warps.
        * ``"vertical_element"`` (T&G case b): the vertical element of the
          root section stays vertical, ``du/dy = 0``; the axis leaves the root
          inclined by the shear angle, adding ``P c^2 L / (2 G I) = 3 P L / (2 G H)``
          to the tip deflection ("the effect of shear" of elementary texts).

        Neither is a fully clamped root (``u = v = 0`` over the whole root
        section, as a grid clamp of all nodes at ``x <= 0`` imposes): both
        leave the root section free to warp under the reaction tractions,
        which the clamp prevents, so the clamp is stiffer than case b.  It
        is softer than case a: for the paper's beam (``nu = 0``) it adds 80%
        of case b's shear term, within 2e-5 of a Timoshenko beam with
        ``k = 5/6`` (see :func:`clamped_tip_deflection_fe`).  With
        ``nu > 0`` the clamp also stops the Poisson expansion of the root
        section, a further stiffening that grows with the root moment.
    plane : {"stress", "strain"}
        The solution is T&G's plane stress one; plane strain uses
        ``E' = E / (1 - nu^2)``, ``nu' = nu / (1 - nu)``.

    Returns
    -------
    u, v : ndarray
        Horizontal and vertical displacement (m); ``v < 0`` (downward) for ``P > 0``.
    """
    if root not in ROOT_CONDITIONS:
        raise ValueError(f"root must be one of {ROOT_CONDITIONS}, not {root!r}")
    x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    modulus, poisson = plane_elastic_constants(E, nu, plane)
    shear_modulus = modulus / (2.0 * (1.0 + poisson))
    inertia, half_height = second_moment_of_area(H), H / 2.0
    bending, shearing = P / (modulus * inertia), P / (shear_modulus * inertia)

    u = (
        bending * x * (2 * L - x) * y / 2
        - poisson * bending * y**3 / 6
        + shearing * y**3 / 6
        - shearing * half_height**2 * y / 2
    )
    v = -bending * x**2 * (3 * L - x) / 6 - poisson * bending * (L - x) * y**2 / 2
    if root == "vertical_element":
        # Rigid rotation that turns the root's vertical element back upright.
        root_shear_angle = shearing * half_height**2 / 2
        u = u + root_shear_angle * y
        v = v - root_shear_angle * x
    return u, v


def timoshenko_goodier_tip_deflection(
    P: float, L: float, H: float, E: float, nu: float, root: str = "horizontal_element", plane: str = "stress"
) -> float:
    """Downward deflection (m) of the tip's neutral-axis point, T&G solution.

    ``P L^3 / (3 E I)`` for ``root="horizontal_element"`` (no shear term: the
    root's shear rotation is absorbed by the root section), and
    ``P L^3 / (3 E I) + 3 P L / (2 G H)`` for ``root="vertical_element"``
    (shear term with an effective shear coefficient 2/3).  The ``nu`` term of
    ``v`` vanishes at ``x = L``.
    """
    _, v = timoshenko_goodier_displacement(L, 0.0, P, L, H, E, nu, root=root, plane=plane)
    return float(-v)


def euler_bernoulli_tip_deflection(P: float, L: float, E: float, I: float) -> float:
    """``P L^3 / (3 E I)`` (m): downward tip deflection of a slender cantilever.

    ``E`` is the bending modulus (Pa), ``I`` in m^4 per m of thickness.
    """
    return P * L**3 / (3.0 * E * I)


def euler_bernoulli_tip_rotation(P: float, L: float, E: float, I: float) -> float:
    """``P L^2 / (2 E I)`` (rad): tip rotation, positive turning the tip downward."""
    return P * L**2 / (2.0 * E * I)


def timoshenko_beam_tip_deflection(
    P: float, L: float, E: float, G: float, A: float, I: float | None = None, shear_coefficient: float = 5.0 / 6.0
) -> float:
    """Timoshenko beam: ``P L^3 / (3 E I) + P L / (k G A)`` (m).

    Parameters
    ----------
    P : float
        Downward tip force (N per m of thickness).
    L : float
        Length (m).
    E, G : float
        Bending and shear moduli (Pa).
    A : float
        Section area (m^2 per m of thickness), ``H`` for the plane beam.
    I : float, optional
        Second moment of area; defaults to that of a rectangle of height ``A``
        (``A^3 / 12``, unit thickness).
    shear_coefficient : float
        ``k``; 5/6 for a rectangle (Cowper gives ``10 (1 + nu) / (12 + 11 nu)``,
        5/6 at ``nu = 0``).  ``k = 2/3`` reproduces T&G's root condition (b).
    """
    inertia = second_moment_of_area(A) if I is None else I
    return euler_bernoulli_tip_deflection(P, L, E, inertia) + P * L / (shear_coefficient * G * A)
