"""Observers: effects that only read the state, at record steps (the ``observe`` stage).

``energy.py``  :class:`EnergyBookkeeping`, the paper's energies and errors (Eqs. 25-32)
``probe.py``   :class:`Probe`, one number of the state per record (e.g. a modal amplitude)

The ParaView series are written by observers of the output (:class:`femgrid_mpm.output.ParticleSeries`,
:class:`femgrid_mpm.output.GridSeries`), bound only when the scene's ``[output]`` asks for them.
"""

from .energy import COLUMNS, EnergyBookkeeping, energy_drift, energy_drift_of_ends, kinetic_energy
from .probe import Probe

__all__ = ["COLUMNS", "EnergyBookkeeping", "Probe", "energy_drift", "energy_drift_of_ends", "kinetic_energy"]
