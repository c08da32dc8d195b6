"""Effects a scene can declare; the step runs only the ones it declares.

:data:`REGISTRY` lists every effect once: the scene table it is declared in
and, in a table of several kinds, its ``kind``.  The scene's tables are built
from it (:mod:`femgrid_mpm.scene`), and its order is the order in which the
step runs the effects of one stage: loads, then damping, then contact and
supports (both constrain the grid velocity; supports have the last word), and
the observers a scene declares (the exact reference).
Adding an effect: its file here, one line in :data:`REGISTRY`.  See
:mod:`femgrid_mpm.effects.base` for the protocol and the stages.

Examples
--------
>>> kinds("loads")
('point', 'gravity', 'body_force')
>>> tables()
('loads', 'damping', 'contact', 'supports', 'reference')
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Annotated, Callable, Union

from pydantic import Field

from .base import ForceNotFinite, Stage, StepContext
from .body_force import BodyForce
from .contact import Contact
from .damping import MassDamping
from .gravity import Gravity
from .point_load import PointLoad
from .reference import ExactReference
from .supports import Support


@dataclass(frozen=True)
class Entry:
    """One effect of the registry.

    effect : type
        The effect's class; its fields are its scene keys.
    table : str
        The scene table (a field of :class:`femgrid_mpm.scene.Scene`) that declares it.
    kind : str, optional
        Its ``kind`` in a table of several kinds (the discriminator of that table).
    acts : callable, optional
        Whether a declared effect runs any code in the step; every declared one does if omitted.
    """

    effect: type
    table: str
    kind: str | None = None
    acts: Callable[[object], bool] | None = None


#: every effect, in the order the step runs those of one stage
REGISTRY = (
    Entry(PointLoad, "loads", kind="point"),
    Entry(Gravity, "loads", kind="gravity"),
    Entry(BodyForce, "loads", kind="body_force"),
    Entry(MassDamping, "damping", kind="mass"),
    # shared contact is the single-field step itself: it runs no code of its own
    Entry(Contact, "contact", acts=lambda contact: contact.fields_per_body),
    Entry(Support, "supports"),
    # an observer: it runs at records, before the energy bookkeeping (which reads its error)
    Entry(ExactReference, "reference"),
)


def check_registry(scene_tables: tuple[str, ...]) -> None:
    """Raise TypeError or ValueError naming the first entry of :data:`REGISTRY` that the scene
    could not declare: not an :class:`~femgrid_mpm.effects.base.Effect`, without a ``name`` or a
    ``bind``, listed twice, in a table the scene does not have (``scene_tables``), or without a
    ``kind`` of its own in a table of several."""
    from .base import Effect, has_name

    seen: set = set()
    for entry in REGISTRY:
        effect = entry.effect
        if not (isinstance(effect, type) and issubclass(effect, Effect)):  # (its stage: Effect checks it)
            raise TypeError(f"effects.REGISTRY: {effect!r} is not an Effect class (femgrid_mpm.effects.base.Effect)")
        # without these the scene's validation or the simulation's set-up failed with a traceback
        if not has_name(effect):
            raise TypeError(f"effects.REGISTRY: {effect.__name__} has no name (a str: its key in the work ledger)")
        if inspect.isabstract(effect):
            raise TypeError(f"effects.REGISTRY: {effect.__name__} has no {', '.join(sorted(effect.__abstractmethods__))}")
        if effect in seen:
            raise ValueError(f"effects.REGISTRY: {effect.__name__} is listed twice")
        seen.add(effect)
        if entry.table not in scene_tables:
            raise ValueError(f"effects.REGISTRY: {effect.__name__}: the scene has no table {entry.table!r} "
                             f"(its tables: {', '.join(scene_tables)})")
    for table in tables():
        several = kinds(table)
        if len(entries(table)) > 1 and (len(several) != len(entries(table)) or len(set(several)) != len(several)):
            raise ValueError(f"effects.REGISTRY: the effects of {table!r} need a kind each, none twice (got {several})")


def tables() -> tuple[str, ...]:
    """The scene tables that declare effects, in step order."""
    return tuple(dict.fromkeys(entry.table for entry in REGISTRY))


def entries(table: str) -> tuple[Entry, ...]:
    """The registry's entries of one scene table, in registry order."""
    return tuple(entry for entry in REGISTRY if entry.table == table)


def kinds(table: str) -> tuple[str, ...]:
    """The ``kind`` values of a table of several kinds (``()`` for a table of one effect)."""
    return tuple(entry.kind for entry in entries(table) if entry.kind is not None)


def scene_key(scene, effect) -> str:
    """The key that declares ``effect`` (the very object) in ``scene``: ``loads[1]``, ``damping``;
    its name if the scene does not declare it."""
    for table in tables():
        value = getattr(scene, table)
        for index, item in enumerate(value if isinstance(value, tuple) else (value,)):
            if item is effect:
                return f"{table}[{index}]" if isinstance(value, tuple) else table
    return effect.name


def table_type(table: str):
    """The type of one item of a scene table: its effect's class, or, for several,
    their union discriminated on ``kind`` (members in registry order)."""
    classes = tuple(entry.effect for entry in entries(table))
    if len(classes) == 1:
        return classes[0]
    return Annotated[Union[classes], Field(discriminator="kind")]


def acts(table: str, effect) -> bool:
    """Whether ``effect``, declared in ``table``, runs code in the step."""
    (entry,) = [entry for entry in entries(table) if isinstance(effect, entry.effect)]
    return entry.acts is None or entry.acts(effect)


__all__ = [
    "REGISTRY",
    "BodyForce",
    "Contact",
    "Entry",
    "ExactReference",
    "ForceNotFinite",
    "Gravity",
    "MassDamping",
    "PointLoad",
    "Stage",
    "StepContext",
    "Support",
    "acts",
    "check_registry",
    "entries",
    "kinds",
    "scene_key",
    "table_type",
    "tables",
]
