"""A run, described: the :class:`Scene` and the TOML file that maps onto it one to one.

Every table of a scene file is a model here, every key a field; unknown
keys, wrong types, NaN and infinities are refused on construction, so a
scene that validates can be built.  Effects (supports, loads, damping) are
their own classes in :mod:`femgrid_mpm.effects` and appear here as fields.

Examples
--------
>>> scene = Scene.model_validate({
...     "grid": {"basis": "q1", "lower": [0, 0], "upper": [2, 1], "spacing": 0.5},
...     "time": {"dt": 0.01, "end": 0.1},
...     "bodies": [{"name": "block", "lower": [0, 0], "upper": [1, 1],
...                 "material": {"E": 1e4, "nu": 0.3, "density": 1e3}}],
... })
>>> scene.bodies[0].points_per_cell, scene.solver.mass
(2, 'lumped')
"""

from __future__ import annotations

import math
import re
from typing import Annotated, Literal, Union

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    NonNegativeFloat,
    PositiveFloat,
    PositiveInt,
    field_validator,
    model_validator,
)

from .bases import BASES
from .effects import Contact, Gravity, MassDamping, PointLoad, Support
from .expressions import compile_expression
from .grid import MAX_NODES, length_problem, node_count
from .particles import count_rectangle

#: Largest number of material points accepted, checked before allocating.
MAX_POINTS = 100_000_000
#: a run of more steps is a mistake (dt in the wrong unit): at ~10 us a step, 1e9 take three hours
MAX_STEPS = 1_000_000_000

Pair = tuple[float, float]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class GridSpec(_Model):
    """``[grid]``: the background grid (see :class:`femgrid_mpm.Grid`)."""

    basis: Literal["q1", "q2", "serendipity", "bspline3", "bspline3_open"] = "q1"
    lower: Pair
    upper: Pair
    spacing: PositiveFloat

    @model_validator(mode="after")
    def _extent(self):
        if self.upper[0] <= self.lower[0] or self.upper[1] <= self.lower[1]:
            raise ValueError(f"upper {list(self.upper)} must exceed lower {list(self.lower)} in both directions")
        return self


class TimeSpec(_Model):
    """``[time]``: step ``dt`` (s, or ``"auto"``: ``safety`` x the critical step) and ``end`` (s).

    ``rest_speed`` (m/s), optional: end the run early, once ``t >= rest_after``
    (s), when the grid's mass-weighted RMS speed falls below it: the end of a
    quasi-static (dynamic relaxation) protocol.
    """

    dt: Union[PositiveFloat, Literal["auto"]]
    end: PositiveFloat
    safety: Annotated[float, Field(gt=0, le=1)] = 0.5
    rest_speed: Union[PositiveFloat, None] = None
    rest_after: NonNegativeFloat = 0.0


class SolverSpec(_Model):
    """``[solver]``: mass kind and what to do when masses misbehave.

    ``mass``: ``"lumped"`` (row sums), ``"consistent"`` or ``"hrz"`` (a
    positive diagonal for every basis, :class:`femgrid_mpm.mass.HrzMass`).
    ``negative_mass`` (lumped mass): ``"error"`` stops the run at the first
    negative lumped grid mass, ``"warn"`` records it and goes on,
    ``"threshold"`` records it and, at every node whose volume fraction is
    below ``mass_threshold``, divides by the absolute mass ``sum m_p |N_ip|``
    instead (see :class:`femgrid_mpm.mass.LumpedMass`).
    ``consistent_fallback``: ``"error"`` or ``"blend"`` when the consistent
    mass matrix is singular (see :mod:`femgrid_mpm.mass`), with ``blend``
    the lumped weight; ``weak_fraction`` the volume fraction under which a
    node is lumped; ``linear_solver`` how the consistent system is solved
    (``"auto"``: SuperLU up to 5000 active nodes, CG beyond);
    ``cg_tolerance`` CG's relative residual; ``engine``
    the implementation of the step's transfers (:mod:`femgrid_mpm.kernels`).
    """

    mass: Literal["lumped", "consistent", "hrz"] = "lumped"
    negative_mass: Literal["error", "warn", "threshold"] = "error"
    #: negative_mass = "threshold": below this fraction of a node's full share, its absolute mass is used
    mass_threshold: Annotated[float, Field(ge=0, lt=1)] = 0.01
    consistent_fallback: Literal["error", "blend"] = "error"
    blend: Annotated[float, Field(gt=0, le=1)] = 0.1
    weak_fraction: Annotated[float, Field(ge=0, lt=1)] = 0.01
    linear_solver: Literal["auto", "direct", "cg"] = "auto"
    cg_tolerance: Annotated[float, Field(gt=0, lt=1)] = 1e-6
    #: the step's transfers: compiled kernels, or scipy.sparse (the reference)
    engine: Literal["numba", "scipy"] = "numba"
    #: numba engine: threads for the tensor-product and serendipity kernels (1: serial, reproducible bit for bit)
    threads: Annotated[int, Field(ge=1, le=256)] = 1


class Material(_Model):
    """``material = {...}``: ``"linear_elastic"`` (the paper's incremental law) or
    ``"neo_hookean"`` (finite strain, plane strain only); see :mod:`femgrid_mpm.materials`."""

    model: Literal["linear_elastic", "neo_hookean"] = "linear_elastic"
    # bounds far beyond any material (steel: 2e11 Pa, 7.8e3 kg/m^3) that keep the moduli,
    # masses and wave speeds finite floats (E = 1e308 overflowed in the critical step estimate)
    E: Annotated[float, Field(gt=0, le=1e30)]
    nu: Annotated[float, Field(gt=-1, lt=0.5)]
    density: Annotated[float, Field(ge=1e-30, le=1e30)]
    plane: Literal["strain", "stress"] = "strain"

    @model_validator(mode="after")
    def _plane(self):
        if self.model == "neo_hookean" and self.plane != "strain":
            raise ValueError("model 'neo_hookean' is implemented in plane strain only; set plane = \"strain\"")
        return self


class Body(_Model):
    """``[[bodies]]``: a rectangle of material points.

    ``points_per_cell`` points per direction in every grid cell (a cell is
    ``spacing`` wide); ``velocity`` two expressions in ``x``, ``y`` (or
    numbers) for the initial velocity (m/s).
    """

    name: Annotated[str, Field(min_length=1)]
    lower: Pair
    upper: Pair
    points_per_cell: PositiveInt = 2
    velocity: tuple[Union[float, str], Union[float, str]] = (0.0, 0.0)
    material: Material

    @field_validator("velocity")
    @classmethod
    def _velocity_expressions(cls, value):
        for component in value:
            if isinstance(component, str):
                compile_expression(component, ("x", "y"))
        return value

    @model_validator(mode="after")
    def _extent(self):
        if self.upper[0] <= self.lower[0] or self.upper[1] <= self.lower[1]:
            raise ValueError(f"body {self.name!r} has no points: upper {list(self.upper)} must exceed lower {list(self.lower)}")
        return self


Load = Annotated[Union[PointLoad, Gravity], Field(discriminator="kind")]
LOAD_KINDS = ("point", "gravity")


class Output(_Model):
    """``[output]``: a record every ``every`` steps; ``energy`` bookkeeping; ``particles`` for ParaView."""

    every: PositiveInt = 1
    energy: bool = True
    particles: bool = False


class Scene(_Model):
    """A whole run.  Maps one to one onto a TOML scene file."""

    title: str = ""
    grid: GridSpec
    time: TimeSpec
    solver: SolverSpec = SolverSpec()
    bodies: Annotated[tuple[Body, ...], Field(min_length=1)]
    supports: tuple[Support, ...] = ()
    loads: tuple[Load, ...] = ()
    damping: Union[MassDamping, None] = None
    contact: Union[Contact, None] = None
    output: Union[Output, None] = None

    @model_validator(mode="after")
    def _consistent(self):
        # Each message starts with the key it is about: these checks span
        # several tables, so pydantic cannot locate them itself.
        names = [body.name for body in self.bodies]
        for index, name in enumerate(names):
            if name in names[:index]:
                raise ValueError(f"bodies[{index}].name: {name!r} is already the name of bodies[{names.index(name)}]")
        for index, load in enumerate(self.loads):
            if isinstance(load, PointLoad) and load.body not in names:
                raise ValueError(f"loads[{index}].body: there is no body named {load.body!r} (bodies: {', '.join(names)})")
            if isinstance(load, PointLoad) and not all(l <= a <= u for l, a, u in zip(self.grid.lower, load.at, self.grid.upper)):
                # far away, every point is as near in floating point (at 1e300 the first was taken)
                raise ValueError(f"loads[{index}].at: {list(load.at)} lies outside the grid "
                                 f"[{list(self.grid.lower)}, {list(self.grid.upper)}]")
        grid = self.grid
        problem = length_problem(grid.lower, grid.upper, grid.spacing)
        if problem is not None:
            raise ValueError(f"grid.{problem[0]}: {problem[1]}")
        # Sizes are counted arithmetically, before anything is allocated.
        nodes = self.node_count()
        if nodes > MAX_NODES:
            raise ValueError(
                f"grid.spacing: {grid.spacing:g} over [{list(grid.lower)}, {list(grid.upper)}] would make about "
                f"{nodes:.3g} nodes, more than the limit of {MAX_NODES:.0e}"
            )
        points = 0
        for index, body in enumerate(self.bodies):
            if any(bl < gl for bl, gl in zip(body.lower, grid.lower)) or any(bu > gu for bu, gu in zip(body.upper, grid.upper)):
                raise ValueError(
                    f"bodies[{index}]: body {body.name!r} [{list(body.lower)}, {list(body.upper)}] lies outside the grid "
                    f"[{list(grid.lower)}, {list(grid.upper)}]"
                )
            count = self.point_count(index)
            points += count
            if points > MAX_POINTS:
                raise ValueError(
                    f"bodies[{index}].points_per_cell: body {body.name!r} would have {count:.3g} points, "
                    f"{points:.3g} in all, more than the limit of {MAX_POINTS:.0e}"
                )
        for index, support in enumerate(self.supports):
            try:
                compile_expression(support.where, ("x", "y"))
            except ValueError as error:
                raise ValueError(f"supports[{index}].where: {error}") from None
        if isinstance(self.time.dt, float) and self.time.end / self.time.dt > MAX_STEPS:
            raise ValueError(f"time.dt: {self.time.dt:g} s to t = {self.time.end:g} s would be "
                             f"{self.time.end / self.time.dt:.3g} steps, more than the limit of {MAX_STEPS:.0e}")
        if self.contact is not None and self.contact.kind == "shared" and (self.contact.friction or self.contact.gap):
            which = "friction" if self.contact.friction else "gap"
            raise ValueError(f"contact.{which}: applies to kind = 'frictional' only (one shared field has no "
                             "surfaces between the bodies)")
        if self.contact is not None and self.contact.kind == "frictional" and self.solver.mass != "lumped":
            raise ValueError("contact.kind: 'frictional' contact needs solver.mass = \"lumped\" (one lumped field per body)")
        if self.solver.negative_mass == "threshold" and self.solver.mass == "lumped":
            if self.grid.basis == "serendipity":
                raise ValueError(
                    "solver.negative_mass: 'threshold' cannot help serendipity: its corner functions integrate to "
                    "-1/12 of each element, so a full share is negative and no fraction of it is a threshold; "
                    "use solver.mass = \"hrz\""
                )
            if self.contact is not None and self.contact.kind == "frictional":
                raise ValueError("solver.negative_mass: 'threshold' is implemented for one shared field, not for 'frictional' contact")
        return self

    def declared_effects(self) -> list:
        """The scene's acting effects in step order: loads, damping, contact (frictional only:
        shared contact is the single-field step itself), supports.  Contact before supports:
        both constrain the grid velocity, supports have the last word."""
        contact = [self.contact] if self.contact is not None and self.contact.kind == "frictional" else []
        return [*self.loads, *([self.damping] if self.damping else []), *contact, *self.supports]

    def node_count(self) -> float:
        """About how many grid nodes the scene makes (counted, nothing allocated)."""
        return node_count(self.grid.lower, self.grid.upper, self.grid.spacing, BASES[self.grid.basis].cells_per_element)

    def point_count(self, index: int) -> int:
        """How many points body ``index`` is seeded with (counted, nothing allocated)."""
        body = self.bodies[index]
        return count_rectangle(body.lower, body.upper, self.grid.spacing, body.points_per_cell)

    def with_overrides(self, **changes) -> "Scene":
        """A copy with dotted keys replaced, validated again.

        Keys are paths into the scene file, list items by index:
        ``scene.with_overrides(**{"grid.basis": "q2", "bodies.0.points_per_cell": 4})``.

        Raises
        ------
        SceneError
            One line naming the key, as for a scene file (a wrong type included).
        """
        data = self.model_dump(mode="json", exclude_none=True)
        source = "with " + ", ".join(f"{key} = {_shown(value)}" for key, value in changes.items())
        return _validated(data, changes, source)


class SceneError(ValueError):
    """A scene file that cannot be used; the message is one line naming file and key."""


def load_scene(path, overrides: dict | None = None) -> Scene:
    """Read and validate a TOML scene file.

    Parameters
    ----------
    path : str or Path
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
    import tomllib
    from pathlib import Path

    path = Path(path)
    try:
        with path.open("rb") as handle:
            data = tomllib.load(handle)
    except FileNotFoundError:
        raise SceneError(f"{path}: no such scene file") from None
    except IsADirectoryError:
        raise SceneError(f"{path}: is a directory, not a scene file") from None
    except tomllib.TOMLDecodeError as error:
        raise SceneError(_one_line(f"{path}: not valid TOML: {error}")) from None
    except (OSError, UnicodeDecodeError) as error:
        raise SceneError(_one_line(f"{path}: cannot be read: {error}")) from None
    source = str(path)
    if overrides:
        if not isinstance(overrides, dict):
            raise SceneError(f"{source}: overrides must be a dict of dotted keys and values, "
                             f"got {type(overrides).__name__}")
        source += " (with " + ", ".join(f"{key} = {_shown(value)}" for key, value in overrides.items()) + ")"
    return _validated(data, overrides or {}, source)


def _validated(data: dict, overrides: dict, source: str) -> "Scene":
    """The scene of ``data`` (a scene file's tables) with ``overrides`` (dotted keys) set,
    checked; raises :class:`SceneError` with one line starting with ``source``."""
    from pydantic import ValidationError

    for dotted, value in overrides.items():
        try:
            _assign(data, dotted, _plain(value))
        except (KeyError, IndexError, TypeError, ValueError):
            raise SceneError(f"{source}: {dotted}: no such key to set") from None
    try:
        scene = Scene.model_validate(data)
    except ValidationError as error:
        raise SceneError(_one_line(f"{source}: {describe_validation_error(error)}")) from None
    except ValueError as error:  # raised by our own checks outside pydantic's wrapping
        raise SceneError(_one_line(f"{source}: {error}")) from None
    problem = _converted_value(data, scene.model_dump(), "")
    if problem:
        raise SceneError(_one_line(f"{source}: {problem}"))
    return scene


def _plain(value):
    """numpy scalars (and lists or tuples of them) as the Python numbers TOML would give."""
    import numpy as np

    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple)):
        return [_plain(item) for item in value]
    return value


def describe_validation_error(error) -> str:
    """The first problem of a pydantic ``ValidationError`` as one line ``key: message``.

    Echoes of a problem are dropped (a list "too short" because its only
    item failed), and the branches of a union at one key (``dt``: a number
    or ``"auto"``) are merged into one message.  An unknown key is shown
    with the nearest known one.
    """
    errors = error.errors(include_url=False)
    echoes = [
        e for e in errors
        if e["type"] == "too_short" and any(len(o["loc"]) > len(e["loc"]) and o["loc"][: len(e["loc"])] == e["loc"] for o in errors)
    ]
    problems = [(_location(e), e) for e in errors if e not in echoes] or [(_location(errors[0]), errors[0])]
    # an unknown key first: with a misspelt key, "unknown key (did you mean ...)"
    # says more than the "required key is missing" it also causes
    problems.sort(key=lambda problem: problem[1]["type"] not in _UNKNOWN_KEY)
    location, first = problems[0]
    messages: list[str] = []
    for where, e in problems:
        if where != location:
            continue
        message = _message(e)
        if messages and messages[0].startswith("must be ") and message.startswith("must be "):
            message = message.removeprefix("must be ")
        if message not in messages:
            messages.append(message)
    text = " or ".join(messages)
    if first["type"] not in ("missing", *_UNKNOWN_KEY, "value_error", "union_tag_invalid", "union_tag_not_found") and isinstance(
        first.get("input"), (str, int, float, bool)
    ):
        text += f" (got {_shown(first['input'])})"
    text = f"{location}: {text}" if location else text
    others = len({where for where, _ in problems} - {location})
    if others:
        text += f" (and {others} more problem(s))"
    return _one_line(text)


#: pydantic's error types for a key that is not a field (models; dataclasses)
_UNKNOWN_KEY = ("extra_forbidden", "unexpected_keyword_argument")
#: pydantic's name of a union branch or validator in a location: not a key
_BRANCH = re.compile(r"^(constrained-\w+|function-\w+\[.*|[\w-]+\[.*\]|int|float|str|bool|none)$")


def _location(error: dict) -> str:
    location = error["loc"]
    if error["type"] in ("union_tag_invalid", "union_tag_not_found"):
        location = (*location, error.get("ctx", {}).get("discriminator", "'kind'").strip("'"))
    return _dotted(location, keep_last=error["type"] in _UNKNOWN_KEY)


def _dotted(location, keep_last: bool = False) -> str:
    parts = []
    for position, item in enumerate(location):
        last = position == len(location) - 1
        if isinstance(item, int):
            parts.append(f"[{item}]")
        elif not (keep_last and last) and (item in LOAD_KINDS or _BRANCH.match(str(item))):
            continue  # discriminator tags and validator/type names are not keys
        else:
            parts.append(("." if parts else "") + str(item))
    return "".join(parts)


def _message(error: dict) -> str:
    kind, context = error["type"], error.get("ctx", {})
    if kind in _UNKNOWN_KEY:
        return "unknown key" + _known_keys_hint(error["loc"])
    if kind == "union_tag_not_found" or (kind == "missing" and not isinstance(error["loc"][-1], int)):
        return "required key is missing"
    if kind == "finite_number":
        return "must be a finite number (not NaN or infinity)"
    if kind == "union_tag_invalid":
        return f"unknown kind {_shown(context.get('tag'))} (expected {context.get('expected_tags')})"
    if kind in ("float_parsing", "int_parsing", "float_type", "int_type", "int_from_float"):
        return "must be a whole number" if kind.startswith("int") else "must be a number"
    if kind == "missing" and isinstance(error["loc"][-1], int):
        return "missing: the array is too short"
    if kind in ("too_long", "too_short") and "actual_length" in context:
        limit = context.get("max_length" if kind == "too_long" else "min_length")
        return f"must have {'at most' if kind == 'too_long' else 'at least'} {limit} item(s), not {context['actual_length']}"
    if kind in ("model_type", "dataclass_type", "dict_type", "model_attributes_type", "dataclass_exact_type"):
        return "must be a table"
    if kind in ("tuple_type", "list_type"):
        return "must be an array"
    bounds = {"greater_than": "gt", "greater_than_equal": "ge", "less_than": "lt", "less_than_equal": "le"}
    if kind in bounds and isinstance(context.get(bounds[kind]), float):  # 1e+30, not 30 digits
        words = {"gt": "greater than", "ge": "greater than or equal to", "lt": "less than",
                 "le": "less than or equal to"}[bounds[kind]]
        return f"must be {words} {context[bounds[kind]]:g}"
    message = error["msg"].removeprefix("Value error, ").removeprefix("Assertion failed, ")
    if message.startswith("Input should be "):
        message = "must be " + message.removeprefix("Input should be ")
    return message


def _known_keys_hint(location) -> str:
    """`` (did you mean 'spacing'?)`` or `` (known keys: ...)`` for an unknown key; "" if unresolvable."""
    import difflib
    import typing

    node: object = Scene
    for item in location[:-1]:
        while typing.get_origin(node) is Annotated:
            node = typing.get_args(node)[0]
        if typing.get_origin(node) is Union:
            members = [m for m in typing.get_args(node) if m is not type(None)]
            # a discriminated union's location names the tag: the member whose ``kind`` it is
            tagged = [m for m in members if item in typing.get_args(_fields(m).get("kind", None) or ())]
            node = tagged[0] if tagged else members[0] if len(members) == 1 else None
            if tagged:
                continue
            while typing.get_origin(node) is Annotated:
                node = typing.get_args(node)[0]
        if isinstance(item, int) and typing.get_origin(node) is tuple:
            arguments = typing.get_args(node)
            node = arguments[0] if len(arguments) == 2 and arguments[1] is Ellipsis else None
        elif isinstance(item, str) and item in _fields(node):
            node = _fields(node)[item]
        else:
            return ""
    while typing.get_origin(node) in (Annotated, Union):
        members = [m for m in typing.get_args(node) if m is not type(None)]
        node = members[0] if typing.get_origin(node) is Annotated or len(members) == 1 else None
    known = list(_fields(node))
    if not known:
        return ""
    close = difflib.get_close_matches(str(location[-1]), known, n=1)
    return f" (did you mean {close[0]!r}?)" if close else f" (known keys: {', '.join(known)})"


def _fields(node) -> dict:
    """Field name -> annotation of a pydantic model or dataclass; {} for anything else."""
    fields = getattr(node, "model_fields", None) or getattr(node, "__pydantic_fields__", None)
    if not isinstance(fields, dict):
        return {}
    return {name: info.annotation for name, info in fields.items()}


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


def _shown(value) -> str:
    """A value as it would be written in TOML (``true``, ``"q3"``, ``nan``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        import json

        return json.dumps(value)
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_shown(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{key} = {_shown(item)}" for key, item in value.items()) + "}"
    return repr(value.item() if hasattr(value, "item") else value)  # numpy scalars as Python numbers


def _one_line(text: str) -> str:
    return " ".join(text.split("\n"))


def bundled_scene(name: str) -> Scene:
    """One of the scenes shipped with the package (``femgrid_mpm/scenes/NAME.toml``,
    also reachable as ``scenes/`` at the repository's top level)."""
    from pathlib import Path

    return load_scene(Path(__file__).parent / "scenes" / f"{name}.toml")
