"""Independent references for the paper's cantilever (Andersen & Andersen 2007, sections 3.3 and 4.1).

Geometry and signs used throughout (the paper's, Fig. 1): the beam occupies
``0 <= x <= L``, ``-H/2 <= y <= H/2`` (``y`` measured upward from the neutral
axis), unit thickness, clamped at ``x = 0``, loaded at ``x = L`` by a vertical
force ``P``.  **``P > 0`` is a downward force**; downward displacements are
negative ``v``.  Scalar "tip deflection" functions return the magnitude of
the downward tip displacement (positive for ``P > 0``).

Units are any consistent set; the paper's are SI-like: lengths (m), forces
per unit thickness (N/m), moduli (Pa), density (kg/m^3), time (s).

Plane strain versus plane stress: the 2D elasticity formulas are written for
plane stress with ``(E, nu)``; plane strain is the same solution with
``E' = E / (1 - nu^2)`` and ``nu' = nu / (1 - nu)`` (the shear modulus is
unchanged).  Beam formulas take the bending modulus explicitly: pass
``E / (1 - nu^2)`` for a plate strip in plane strain.  With the paper's
``nu = 0`` the two coincide.

Examples
--------
>>> round(euler_bernoulli_tip_deflection(100.0, 8.0, 3e5, 1.0 / 12), 6)
0.682667
>>> tip = elastica_tip(800.0, 8.0, 3e5, 1.0 / 12)
>>> round(load_parameter(800.0, 8.0, 3e5, 1.0 / 12), 3), round(float(np.degrees(tip.rotation)), 1)
(2.048, 45.5)
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq
from scipy.special import ellipe, ellipeinc, ellipkinc, ellipkm1

ROOT_CONDITIONS = ("horizontal_element", "vertical_element")


# --------------------------------------------------------------------------- #
# Section and material helpers
# --------------------------------------------------------------------------- #


def second_moment_of_area(H: float) -> float:
    """``I = H^3 / 12`` (m^4 per m of thickness) of a rectangular section of height ``H`` (m)."""
    return H**3 / 12.0


def plane_elastic_constants(E: float, nu: float, plane: str) -> tuple[float, float]:
    """In-plane ``(E', nu')`` that turn plane-stress formulas into the requested idealisation.

    Parameters
    ----------
    E : float
        Young's modulus (Pa).
    nu : float
        Poisson's ratio (-).
    plane : {"stress", "strain"}

    Returns
    -------
    (E', nu') : tuple of float
        ``(E, nu)`` in plane stress, ``(E / (1 - nu^2), nu / (1 - nu))`` in plane strain.
    """
    if plane == "stress":
        return E, nu
    if plane == "strain":
        return E / (1.0 - nu**2), nu / (1.0 - nu)
    raise ValueError(f"plane must be 'stress' or 'strain', not {plane!r}")


def bending_modulus(E: float, nu: float, plane: str) -> float:
    """Modulus of a bent strip (Pa): ``E`` in plane stress, ``E / (1 - nu^2)`` in plane strain."""
    return plane_elastic_constants(E, nu, plane)[0]


# --------------------------------------------------------------------------- #
# Linear theory: Navier, Timoshenko & Goodier, beam formulas
# --------------------------------------------------------------------------- #


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


# --------------------------------------------------------------------------- #
# Large deflection: the inextensible elastica under a dead vertical tip load
# --------------------------------------------------------------------------- #


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


# --------------------------------------------------------------------------- #
# First bending period
# --------------------------------------------------------------------------- #


def clamped_free_eigenvalue() -> float:
    """``beta_1 L = 1.87510...``, the first root of ``cos(z) cosh(z) = -1`` (clamped-free beam)."""
    return float(brentq(lambda z: np.cos(z) * np.cosh(z) + 1.0, 1.5, 2.5, xtol=1e-15))


def cantilever_bending_period(L: float, H: float, E: float, nu: float, rho: float, plane: str = "strain") -> float:
    """First bending period (s) of a clamped-free Euler-Bernoulli beam.

    ``T = 2 pi / ((beta_1 / L)^2 sqrt(E' I / (rho A)))`` with ``beta_1 L = 1.8751``,
    ``A = H`` and ``I = H^3 / 12`` per unit thickness and ``E'`` the bending
    modulus of :func:`bending_modulus`.  Shear and rotary inertia are
    neglected, so the true period is slightly longer (about 1% at ``L/H = 8``).
    """
    modulus = bending_modulus(E, nu, plane)
    wavenumber = clamped_free_eigenvalue() / L
    return float(2 * np.pi / (wavenumber**2 * np.sqrt(modulus * second_moment_of_area(H) / (rho * H))))


def _clamped_beam_basis(L: float, H: float, elements_along: int):
    import skfem

    across = max(2, 2 * round(elements_along * H / (2 * L)))  # even: a node row on the neutral axis
    mesh = skfem.MeshQuad.init_tensor(np.linspace(0, L, elements_along + 1), np.linspace(-H / 2, H / 2, across + 1))
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementQuad2()))
    clamped = basis.get_dofs(lambda p: np.isclose(p[0], 0.0)).all()
    return basis, clamped


def _plane_lame(E: float, nu: float, plane: str) -> tuple[float, float]:
    from skfem.models.elasticity import lame_parameters

    modulus, poisson = plane_elastic_constants(E, nu, plane)
    # Plane stress with (E', nu') is plane strain with (E, nu): one set of plane-stress Lame constants serves both.
    lam, mu = lame_parameters(modulus, poisson)
    return 2 * lam * mu / (lam + 2 * mu), mu


def cantilever_bending_period_fe(
    L: float, H: float, E: float, nu: float, rho: float, plane: str = "strain", elements_along: int = 32
) -> float:
    """First bending period (s) of the 2D clamped-free beam by an FE modal analysis.

    An independent reference including shear, rotary inertia and the 2D
    root: scikit-fem vector Q2 elements, consistent mass, every degree of
    freedom on ``x = 0`` fixed, ``elements_along`` elements along the beam
    (32 is converged to about 1e-5 for the paper's beam: 23.1065 s, 1.0%
    above Euler-Bernoulli, as a Timoshenko beam with ``k = 5/6`` and rotary
    inertia predicts).
    """
    import skfem
    from scipy.sparse.linalg import eigsh
    from skfem.helpers import dot
    from skfem.models.elasticity import linear_elasticity

    basis, clamped = _clamped_beam_basis(L, H, elements_along)

    @skfem.BilinearForm
    def mass(u, v, w):
        return rho * dot(u, v)

    stiffness = skfem.asm(linear_elasticity(*_plane_lame(E, nu, plane)), basis)
    K, M, _, _ = skfem.condense(stiffness, skfem.asm(mass, basis), D=clamped)
    eigenvalues = eigsh(K, k=1, M=M, sigma=0.0, return_eigenvectors=False)
    return float(2 * np.pi / np.sqrt(eigenvalues[0]))


def clamped_tip_deflection_fe(
    P: float, L: float, H: float, E: float, nu: float, plane: str = "stress", elements_along: int = 32
) -> float:
    """Downward tip deflection (m) of the fully clamped 2D cantilever, static FE.

    The root section is held completely (``u = v = 0`` at every node on
    ``x = 0``, like a grid clamp), the tip carries T&G's parabolic shear
    traction summing to ``P`` downward, and the deflection is read at the
    tip's neutral-axis point.  Q2 elements: about 1e-5 relative at 32
    elements along the paper's beam (the clamped root corners are singular
    and converge slowly).  This measures where a real clamp sits between
    T&G's root conditions: 0.68905 for the paper's beam at ``P = 100``,
    against 0.68267 (case a) and 0.69067 (case b).
    """
    import skfem
    from skfem.models.elasticity import linear_elasticity

    basis, clamped = _clamped_beam_basis(L, H, elements_along)
    stiffness = skfem.asm(linear_elasticity(*_plane_lame(E, nu, plane)), basis)
    tip_facets = basis.mesh.facets_satisfying(lambda p: np.isclose(p[0], L))
    tip_basis = skfem.FacetBasis(basis.mesh, basis.elem, facets=tip_facets)
    inertia = second_moment_of_area(H)

    @skfem.LinearForm
    def tip_shear(v, w):
        return -P * ((H / 2) ** 2 - w.x[1] ** 2) / (2 * inertia) * v[1]

    displacement = skfem.solve(*skfem.condense(stiffness, skfem.asm(tip_shear, tip_basis), D=clamped))
    vertical_dofs = basis.nodal_dofs[1]
    nodes = basis.mesh.p
    tip_axis_node = np.flatnonzero(np.isclose(nodes[0], L) & np.isclose(nodes[1], 0.0))[0]
    return float(-displacement[vertical_dofs[tip_axis_node]])
