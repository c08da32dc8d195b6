"""femgrid-mpm: the material point method on finite-element background grids."""

from . import _runtime

_runtime.configure()  # before numpy is imported: one BLAS thread, a malloc that keeps memory

from .grid import Grid  # noqa: E402

__version__ = "0.1.0"
__all__ = ["Grid", "__version__"]
