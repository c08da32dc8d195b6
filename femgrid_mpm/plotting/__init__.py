"""Pictures of a run's directory (``femgrid-mpm plot``): the points at a record coloured
by a field, the energies against time, the particle series as an animation.

``run_directory.py``  :class:`RunDirectory`: a run's files read back and checked
``figures.py``        the figures (matplotlib, no display needed) and their atomic writing
"""

from .figures import DPI, SIZE, energy_figure, points_figure, save, series_picture, write_animation
from .run_directory import FIELDS, Frame, RunDirectory, RunUnreadable, energy_table

__all__ = ["DPI", "FIELDS", "SIZE", "Frame", "RunDirectory", "RunUnreadable", "energy_figure", "energy_table",
           "points_figure", "save", "series_picture", "write_animation"]
