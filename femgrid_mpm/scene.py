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
from .effects import Gravity, MassDamping, PointLoad, Support
from .expressions import compile_expression
from .grid import MAX_NODES
from .particles import count_rectangle

#: Largest number of material points accepted, checked before allocating.
MAX_POINTS = 100_000_000

Pair = tuple[float, float]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class GridSpec(_Model):
    """``[grid]``: the background grid (see :class:`femgrid_mpm.Grid`)."""

    basis: Literal["q1", "q2", "serendipity", "bspline3"] = "q1"
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

    ``negative_mass``: ``"error"`` stops the run at the first negative
    lumped grid mass, ``"warn"`` records it and goes on.
    ``consistent_fallback``: ``"error"`` or ``"blend"`` when the consistent
    mass matrix is singular (see :mod:`femgrid_mpm.mass`), with ``blend``
    the lumped weight; ``weak_fraction`` the volume fraction under which a
    node is lumped; ``cg_tolerance`` CG's relative residual.
    """

    mass: Literal["lumped", "consistent"] = "lumped"
    negative_mass: Literal["error", "warn"] = "error"
    consistent_fallback: Literal["error", "blend"] = "error"
    blend: Annotated[float, Field(gt=0, le=1)] = 0.1
    weak_fraction: Annotated[float, Field(ge=0, lt=1)] = 0.01
    cg_tolerance: Annotated[float, Field(gt=0, lt=1)] = 1e-10


class Material(_Model):
    """``material = {...}``: linear elasticity in the paper's incremental form."""

    model: Literal["linear_elastic"] = "linear_elastic"
    E: PositiveFloat
    nu: Annotated[float, Field(gt=-1, lt=0.5)]
    density: PositiveFloat
    plane: Literal["strain", "stress"] = "strain"


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


class Contact(_Model):
    """``[contact]``: how bodies meet.  ``"shared"``: one velocity field for all (the paper's)."""

    kind: Literal["shared"] = "shared"


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
        names = [body.name for body in self.bodies]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ValueError(f"body names must be unique: {duplicates}")
        for index, load in enumerate(self.loads):
            if isinstance(load, PointLoad) and load.body not in names:
                raise ValueError(f"loads[{index}] acts on body {load.body!r}, which does not exist (bodies: {names})")
        grid = self.grid
        width = grid.spacing * BASES[grid.basis].cells_per_element
        nodes = math.prod(math.ceil((u - l) / width) * BASES[grid.basis].cells_per_element + 3 for l, u in zip(grid.lower, grid.upper))
        if nodes > MAX_NODES:
            raise ValueError(f"the grid would have about {nodes:.3g} nodes, more than the limit of {MAX_NODES:.0e}")
        points = 0
        for body in self.bodies:
            if any(bl < gl for bl, gl in zip(body.lower, grid.lower)) or any(bu > gu for bu, gu in zip(body.upper, grid.upper)):
                raise ValueError(
                    f"body {body.name!r} [{list(body.lower)}, {list(body.upper)}] lies outside the grid "
                    f"[{list(grid.lower)}, {list(grid.upper)}]"
                )
            points += count_rectangle(body.lower, body.upper, grid.spacing, body.points_per_cell)
            if points > MAX_POINTS:
                raise ValueError(f"the bodies would have more than the limit of {MAX_POINTS:.0e} material points")
        for index, support in enumerate(self.supports):
            compile_expression(support.where, ("x", "y"))
        return self

    def with_overrides(self, **changes) -> "Scene":
        """A copy with dotted keys replaced, validated again.

        Keys are paths into the scene file, list items by index:
        ``scene.with_overrides(**{"grid.basis": "q2", "bodies.0.points_per_cell": 4})``.
        """
        data = self.model_dump(mode="json", exclude_none=True)
        for dotted, value in changes.items():
            *parents, key = dotted.split(".")
            target = data
            for parent in parents:
                target = target[int(parent)] if isinstance(target, list) else target.setdefault(parent, {})
            if isinstance(target, list):
                target[int(key)] = value
            else:
                target[key] = value
        return Scene.model_validate(data)


class SceneError(ValueError):
    """A scene file that cannot be used; the message is one line naming file and key."""


def load_scene(path) -> Scene:
    """Read and validate a TOML scene file.

    Raises
    ------
    SceneError
        One line: ``FILE: KEY: problem`` (the first problem found).
    """
    import tomllib
    from pathlib import Path

    from pydantic import ValidationError

    path = Path(path)
    try:
        with path.open("rb") as handle:
            data = tomllib.load(handle)
    except FileNotFoundError:
        raise SceneError(f"{path}: no such scene file") from None
    except IsADirectoryError:
        raise SceneError(f"{path}: is a directory, not a scene file") from None
    except tomllib.TOMLDecodeError as error:
        raise SceneError(f"{path}: not valid TOML: {error}") from None
    except (OSError, UnicodeDecodeError) as error:
        raise SceneError(f"{path}: cannot be read: {error}") from None
    try:
        return Scene.model_validate(data)
    except ValidationError as error:
        raise SceneError(f"{path}: {describe_validation_error(error)}") from None
    except ValueError as error:  # raised by our own checks outside pydantic's wrapping
        raise SceneError(f"{path}: {error}") from None


def describe_validation_error(error) -> str:
    """The first problem of a pydantic ``ValidationError`` as ``key: message``."""
    first = error.errors(include_url=False)[0]
    location = _dotted(first["loc"])
    message = first["msg"].removeprefix("Value error, ")
    kind = first["type"]
    if kind == "extra_forbidden":
        message = "unknown key"
    elif kind == "missing":
        message = "required key is missing"
    elif kind in ("finite_number",):
        message = "must be a finite number (not NaN or infinity)"
    text = f"{location}: {message}" if location else message
    if len(error.errors()) > 1:
        text += f" (and {len(error.errors()) - 1} more problem(s))"
    return text.replace("\n", " ")


def _dotted(location) -> str:
    parts = []
    for item in location:
        if isinstance(item, int):
            parts.append(f"[{item}]")
        elif item in LOAD_KINDS or "[" in str(item) or "(" in str(item):
            continue  # discriminator tags and validator/type names are not keys
        else:
            parts.append(("." if parts else "") + str(item))
    return "".join(parts)


def bundled_scene(name: str) -> Scene:
    """One of the scenes shipped with the package (``femgrid_mpm/scenes/NAME.toml``,
    also reachable as ``scenes/`` at the repository's top level)."""
    from pathlib import Path

    return load_scene(Path(__file__).parent / "scenes" / f"{name}.toml")
