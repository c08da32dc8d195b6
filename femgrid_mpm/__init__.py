"""femgrid-mpm: the material point method on finite-element background grids.

What a user needs, from the package itself:

:class:`Grid`
    A background grid of one basis (``q1``, ``q2``, ``serendipity``, ``bspline3``,
    ``bspline3_open``) and its shape functions.
:class:`Scene`, :func:`load_scene`, :func:`bundled_scene`, :func:`bundled_scenes`, :class:`SceneError`
    A run, described: read from a TOML file, or one of the scenes shipped with the package.
:class:`Simulation`
    A scene, built and run (:meth:`Simulation.run` returns a :class:`RunResult`).

Examples
--------
>>> import femgrid_mpm
>>> "cantilever" in femgrid_mpm.bundled_scenes()
True
>>> femgrid_mpm.bundled_scene("vibrating_bar").grid.basis
'q1'
"""

from . import _runtime

_runtime.configure()  # before numpy is imported: one BLAS thread, a malloc that keeps memory

__version__ = "0.1.0"

#: each public name and the module it comes from, loaded on first use: importing the package
#: (as the command line does, before it can catch a Ctrl-C) then loads no numpy, scipy,
#: scikit-fem or pydantic
_LAZY = {
    "Grid": "grid",
    "Scene": "scene",
    "SceneError": "scene",
    "load_scene": "scene",
    "bundled_scene": "scene",
    "bundled_scenes": "scene",
    "Simulation": "solver",
    "RunResult": "solver",
}

__all__ = ["Grid", "RunResult", "Scene", "SceneError", "Simulation", "__version__", "bundled_scene",
           "bundled_scenes", "load_scene"]


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value  # once: later look-ups do not come here
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})
