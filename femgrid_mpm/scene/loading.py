"""Scene files: reading and validating one, and the scenes shipped with the package."""

from __future__ import annotations

from pathlib import Path

from ..reading import InputRefused, read_toml
from .messages import _shown
from .models import Scene
from .validation import SceneError, validated

#: the scene files shipped with the package (also ``scenes/`` at the repository's top level)
BUNDLED_SCENES = Path(__file__).parent.parent / "scenes"


def load_scene(path, overrides: dict | None = None) -> Scene:
    """Read and validate a TOML scene file.

    Parameters
    ----------
    path : str or Path
        Anything else (a :class:`Scene`, bytes, None) is a :class:`SceneError`.
    overrides : dict, optional
        Dotted keys into the file (list items by index) and their values,
        set in the file's data before it is validated:
        ``{"grid.basis": "q2", "bodies.0.points_per_cell": 4}``.

    Raises
    ------
    SceneError
        One line: ``FILE: KEY: problem`` (the first problem found).  Besides
        pydantic's checks, a value of the wrong TOML type that pydantic
        would convert (``spacing = "0.5"``, ``spacing = true``,
        ``particles = 1``) is refused.
    """
    import os

    if not isinstance(path, (str, os.PathLike)) or isinstance(os.fspath(path), bytes):
        advice = " (a Scene is loaded already: use it, or its with_overrides)" if isinstance(path, Scene) else ""
        raise SceneError(f"load_scene: expected the path of a scene file (str or Path), "
                         f"got {type(path).__name__}{advice}")
    path = Path(path)
    try:
        data = read_toml(path, "scene file")
    except InputRefused as error:
        raise SceneError(str(error)) from None
    source = str(path)
    if overrides:
        if not isinstance(overrides, dict):
            raise SceneError(f"{source}: overrides must be a dict of dotted keys and values, "
                             f"got {type(overrides).__name__}")
        source += " (with " + ", ".join(f"{key} = {_shown(value)}" for key, value in overrides.items()) + ")"
    return validated(Scene, data, overrides or {}, source)


def bundled_scenes() -> list[str]:
    """The names of the scenes shipped with the package, sorted: each one a
    :func:`bundled_scene` and a ``SCENE`` of ``femgrid-mpm run`` as ``femgrid_mpm/scenes/NAME.toml``.

    Examples
    --------
    >>> "vibrating_bar" in bundled_scenes()
    True
    """
    return sorted(path.stem for path in BUNDLED_SCENES.glob("*.toml"))


def bundled_scene(name: str) -> Scene:
    """One of the scenes shipped with the package (``femgrid_mpm/scenes/NAME.toml``,
    also reachable as ``scenes/`` at the repository's top level).

    Parameters
    ----------
    name : str
        One of :func:`bundled_scenes`, without ``.toml``.

    Raises
    ------
    SceneError
        One line naming the scenes there are, for a name that is not one of them.
    """
    known = bundled_scenes()
    if name not in known:  # a name, not a path: "../x" or "bar.toml" is refused too
        raise SceneError(f"no bundled scene {name!r} (bundled scenes: {', '.join(known)})")
    return load_scene(BUNDLED_SCENES / f"{name}.toml")
