"""The engines of the step's transfers: scipy (the readable definition) and numba (the default).

``engine.py``        :class:`Engine`, the interface the step is written against
``scipy_engine.py``  :class:`ScipyTransfer` (the paper's sparse algebra) and
                     :class:`PerBodyTransfer` (the same, one field per body)
``numba_engine.py``  :class:`CompiledTransfer`: the kernels of :mod:`femgrid_mpm.kernels`
``reconstructed.py`` :class:`ReconstructedForce`, :class:`ReconstructedMass`: another engine's
                     passes with the internal force, or the mass and momentum, by Gauss
                     quadrature of fields reconstructed from the points
"""

from __future__ import annotations

from .engine import Engine
from .numba_engine import CompiledTransfer
from .reconstructed import ReconstructedForce, ReconstructedMass
from .scipy_engine import PerBodyTransfer, ScipyTransfer

#: ``[solver] engine`` -> engine
ENGINES = {"scipy": ScipyTransfer, "numba": CompiledTransfer}

__all__ = ["ENGINES", "CompiledTransfer", "Engine", "PerBodyTransfer", "ReconstructedForce", "ReconstructedMass", "ScipyTransfer", "engine_for"]


def engine_for(simulation) -> Engine:
    """The engine of a simulation: the scene's, or the per-body one for a mass model with
    one field per body (which only the scipy algebra implements);
    wrapped in :class:`ReconstructedForce` for ``force_quadrature = "reconstructed"`` and in
    :class:`ReconstructedMass` for ``mass_quadrature = "reconstructed"``."""
    if simulation.mass.assembly.per_body:
        return PerBodyTransfer(simulation)
    engine = ENGINES[simulation.scene.solver.engine](simulation)
    if simulation.scene.solver.force_quadrature == "reconstructed":
        engine = ReconstructedForce(engine, simulation)
    if simulation.scene.solver.mass_quadrature == "reconstructed":
        engine = ReconstructedMass(engine, simulation)
    return engine
