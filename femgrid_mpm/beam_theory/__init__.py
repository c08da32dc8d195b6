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

The references, one module each: :mod:`~femgrid_mpm.beam_theory.section`
(section and material helpers), :mod:`~femgrid_mpm.beam_theory.linear`
(Navier, Timoshenko & Goodier, beam formulas),
:mod:`~femgrid_mpm.beam_theory.elastica` (large deflection),
:mod:`~femgrid_mpm.beam_theory.bending_period` (Euler-Bernoulli's first
period) and :mod:`~femgrid_mpm.beam_theory.finite_element` (2D FE
references of the clamped beam).

Examples
--------
>>> import numpy as np
>>> round(euler_bernoulli_tip_deflection(100.0, 8.0, 3e5, 1.0 / 12), 6)
0.682667
>>> tip = elastica_tip(800.0, 8.0, 3e5, 1.0 / 12)
>>> round(load_parameter(800.0, 8.0, 3e5, 1.0 / 12), 3), round(float(np.degrees(tip.rotation)), 1)
(2.048, 45.5)
"""

from .bending_period import cantilever_bending_period, clamped_free_eigenvalue
from .elastica import ElasticaTip, elastica_shape, elastica_tip, load_parameter
from .finite_element import cantilever_bending_period_fe, clamped_tip_deflection_fe
from .linear import (
    ROOT_CONDITIONS,
    bending_moment,
    euler_bernoulli_tip_deflection,
    euler_bernoulli_tip_rotation,
    navier_stress,
    timoshenko_beam_tip_deflection,
    timoshenko_goodier_displacement,
    timoshenko_goodier_stress,
    timoshenko_goodier_tip_deflection,
)
from .section import bending_modulus, plane_elastic_constants, second_moment_of_area

__all__ = [
    "ROOT_CONDITIONS",
    "ElasticaTip",
    "bending_modulus",
    "bending_moment",
    "cantilever_bending_period",
    "cantilever_bending_period_fe",
    "clamped_free_eigenvalue",
    "clamped_tip_deflection_fe",
    "elastica_shape",
    "elastica_tip",
    "euler_bernoulli_tip_deflection",
    "euler_bernoulli_tip_rotation",
    "load_parameter",
    "navier_stress",
    "plane_elastic_constants",
    "second_moment_of_area",
    "timoshenko_beam_tip_deflection",
    "timoshenko_goodier_displacement",
    "timoshenko_goodier_stress",
    "timoshenko_goodier_tip_deflection",
]
