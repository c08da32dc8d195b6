"""Section and material helpers: second moment of area, plane strain or stress constants."""

from __future__ import annotations


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
