"""A scene file's data, with overrides set, validated against the scene model.

pydantic checks the model; this adds what a file needs besides: dotted keys
set before validation (``bodies.0.points_per_cell``), values of the wrong
TOML type that pydantic would convert, and one-line errors
(:class:`SceneError`) naming the file and the key.
"""

from __future__ import annotations

from contextvars import ContextVar

from .messages import _one_line, _shown, describe_validation_error


class SceneError(ValueError):
    """A scene file that cannot be used; the message is one line naming file and key."""


#: set while :func:`validated` builds a model: the Scene's own ``__init__`` (which pydantic's
#: validation calls) then only builds it; called directly, it checks its data as a file first
CHECKING: ContextVar[bool] = ContextVar("femgrid_mpm_scene_checking", default=False)


def validated(model, data: dict, overrides: dict, source: str):
    """The ``model`` (the :class:`~femgrid_mpm.scene.Scene`) of ``data`` (a scene file's
    tables) with ``overrides`` (dotted keys) set, checked; raises :class:`SceneError`
    with one line starting with ``source``."""
    from pydantic import ValidationError

    data = _plain(data)  # a copy: the caller's data is left as it is
    for dotted, value in overrides.items():
        try:
            _assign(data, dotted, _plain(value))
        except (KeyError, IndexError, TypeError, ValueError):
            raise SceneError(f"{source}: {dotted}: no such key to set") from None
    deep = _nested_too_deep(data)
    if deep is not None:
        raise SceneError(f"{source}: {deep}: nested more than {MAX_DEPTH} levels deep (no scene key is)")
    checking = CHECKING.set(True)
    try:
        # pydantic's own validation (the model's ``model_validate`` comes back here)
        scene = model.__pydantic_validator__.validate_python(data)
    except ValidationError as error:
        raise SceneError(_one_line(f"{source}: {describe_validation_error(error, model)}")) from None
    except ValueError as error:  # raised by our own checks outside pydantic's wrapping
        raise SceneError(_one_line(f"{source}: {error}")) from None
    finally:
        CHECKING.reset(checking)
    problem = _converted_value(data, scene.model_dump(), "")
    if problem:
        raise SceneError(_one_line(f"{source}: {problem}"))
    return scene


#: the deepest nesting of tables and arrays accepted (a scene's deepest key is 4 levels down)
MAX_DEPTH = 32


def _plain(value, depth: int = 0):
    """A copy of ``value`` with numpy arrays and scalars as the lists and Python numbers
    TOML would give (nesting beyond :data:`MAX_DEPTH` is kept as it is, to be refused)."""
    import numpy as np

    if depth > MAX_DEPTH:
        return value
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(item, depth + 1) for item in value]
    if isinstance(value, dict):
        return {key: _plain(item, depth + 1) for key, item in value.items()}
    return value


def _nested_too_deep(data) -> str | None:
    """The key of the first value nested more than :data:`MAX_DEPTH` levels deep, or None
    (iteratively: a deeper structure than Python's recursion limit is found too)."""
    pending = [(data, "", 0)]
    while pending:
        value, location, depth = pending.pop()
        if isinstance(value, (dict, list, tuple)) and depth >= MAX_DEPTH:
            return location or "(top)"
        if isinstance(value, dict):
            pending += [(item, f"{location}.{key}" if location else str(key), depth + 1) for key, item in value.items()]
        elif isinstance(value, (list, tuple)):
            pending += [(item, f"{location}[{index}]", depth + 1) for index, item in enumerate(value)]
    return None


def _converted_value(raw, validated, location: str) -> str | None:
    """The first value pydantic converted across TOML types, as ``key: message``.

    pydantic's lax mode turns ``"0.5"`` and ``true`` into numbers and ``1``
    into ``true``; in a scene file those are mistakes.  ``raw`` is the file's
    data, ``validated`` the model dumped to Python; containers that differ
    in shape are not compared.
    """
    if isinstance(raw, dict) and isinstance(validated, dict):
        for key, value in raw.items():
            if key in validated:
                problem = _converted_value(value, validated[key], f"{location}.{key}" if location else key)
                if problem:
                    return problem
        return None
    if isinstance(raw, list) and isinstance(validated, (list, tuple)):
        for index, (item, checked) in enumerate(zip(raw, validated)):
            problem = _converted_value(item, checked, f"{location}[{index}]")
            if problem:
                return problem
        return None
    if isinstance(validated, bool) and not isinstance(raw, bool):
        return f"{location}: must be true or false (got {_shown(raw)})"
    is_number = isinstance(validated, (int, float)) and not isinstance(validated, bool)
    if is_number and (isinstance(raw, (str, bool)) or not isinstance(raw, (int, float))):
        return f"{location}: must be a number (got {_shown(raw)})"
    return None


def _assign(data: dict, dotted: str, value) -> None:
    """Set ``data[a][b][0][c] = value`` for ``dotted = "a.b.0.c"``, creating missing tables."""
    if not isinstance(dotted, str):
        raise KeyError(dotted)
    *parents, key = dotted.split(".")
    target = data
    for parent in parents:
        if isinstance(target, list):
            target = target[_list_index(parent)]
        elif isinstance(target, dict):
            target = target.setdefault(parent, {})
        else:
            raise KeyError(dotted)
    if isinstance(target, list):
        target[_list_index(key)] = value
    elif isinstance(target, dict) and key:
        target[key] = value
    else:
        raise KeyError(dotted)


def _list_index(text: str) -> int:
    """A list item's index in a dotted key: digits only (``bodies.-1`` is no key of the file)."""
    if not text.isdigit():
        raise KeyError(text)
    return int(text)
