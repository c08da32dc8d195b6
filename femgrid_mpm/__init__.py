"""femgrid-mpm: the material point method on finite-element background grids."""

from . import _runtime

_runtime.configure()  # before numpy is imported: one BLAS thread, a malloc that keeps memory

__version__ = "0.1.0"
__all__ = ["Grid", "__version__"]


def __getattr__(name: str):
    # Grid on first use: importing the package (as the command line does, before it can
    # catch a Ctrl-C) then loads no numpy, scipy or scikit-fem
    if name == "Grid":
        from .grid import Grid

        return Grid
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
