"""The engines of the step's transfers: scipy (the readable definition) and numba (the default).

``engine.py``        :class:`Engine`, the interface the step is written against
``scipy_engine.py``  :class:`ScipyTransfer` (the paper's sparse algebra) and
                     :class:`PerBodyTransfer` (the same, one field per body)
``numba_engine.py``  :class:`CompiledTransfer`: the kernels of :mod:`femgrid_mpm.kernels`
"""

from __future__ import annotations

from ..kernels.compiled import note_compilation
from .engine import Engine
from .numba_engine import CompiledTransfer
from .scipy_engine import PerBodyTransfer, ScipyTransfer

#: ``[solver] engine`` -> engine
ENGINES = {"scipy": ScipyTransfer, "numba": CompiledTransfer}

__all__ = ["ENGINES", "CompiledTransfer", "Engine", "PerBodyTransfer", "ScipyTransfer", "engine_for"]


def engine_for(simulation) -> Engine:
    """The engine of a simulation: the scene's, or the per-body one for a mass model with
    one field per body (which only the scipy algebra implements).  The first in a process
    whose kernel cache is cold says that they are being compiled (:func:`note_compilation`)."""
    note_compilation()
    if simulation.mass.assembly.per_body:
        return PerBodyTransfer(simulation)
    return ENGINES[simulation.scene.solver.engine](simulation)
