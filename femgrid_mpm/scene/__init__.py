"""A run, described: the :class:`Scene` and the TOML file that maps onto it one to one.

``models``
    The scene's tables as pydantic models (:class:`Scene` and its parts); the
    effects' tables come from the registry of :mod:`femgrid_mpm.effects`.
``loading``
    Reading a scene file (:func:`load_scene`), the bundled scenes (:func:`bundled_scenes`, :func:`bundled_scene`).
``validation``
    Overrides set by dotted key, checks beyond pydantic's, :class:`SceneError`.
``messages``
    A validation error as one line naming the key (:func:`describe_validation_error`).

Examples
--------
>>> scene = bundled_scene("vibrating_bar")
>>> scene.with_overrides(**{"grid.basis": "q2"}).grid.basis
'q2'
"""

from .loading import BUNDLED_SCENES, bundled_scene, bundled_scenes, load_scene
from .messages import describe_validation_error
from .models import (
    LOAD_KINDS,
    MAX_POINTS,
    MAX_STEPS,
    Body,
    ContactSpec,
    DampingSpec,
    GridSpec,
    Load,
    Material,
    Output,
    Pair,
    Scene,
    SolverSpec,
    SupportSpec,
    TimeSpec,
)
from .validation import SceneError

__all__ = [
    "BUNDLED_SCENES",
    "LOAD_KINDS",
    "MAX_POINTS",
    "MAX_STEPS",
    "Body",
    "ContactSpec",
    "DampingSpec",
    "GridSpec",
    "Load",
    "Material",
    "Output",
    "Pair",
    "Scene",
    "SceneError",
    "SolverSpec",
    "SupportSpec",
    "TimeSpec",
    "bundled_scene",
    "bundled_scenes",
    "describe_validation_error",
    "load_scene",
]
