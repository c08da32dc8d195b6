"""The effect protocol: what a scene may add to the step, and where.

An effect is a frozen (pydantic) dataclass whose fields are its scene keys:
unknown keys are errors and values are validated on construction.  It names
the one :class:`~femgrid_mpm.step.Stage` it acts at, and
``bind(simulation)`` returns the action the step calls there with the
:class:`~femgrid_mpm.step.StepContext`, after any set-up (selecting nodes,
finding a point) is done once.  An effect that holds degrees of freedom at
zero for the whole run says so in :meth:`Effect.fixed`: a consistent mass
couples the nodes, so its solve must leave them out rather than zero them
after, and the critical time step must leave them out too.  One that ties nodes to
their mirror images (:meth:`Effect.mirror`) makes the mass solve on the reduced velocity.

Adding an effect: one class here in ``effects/``, one line in
``effects/__init__.py``'s registry, one test that runs it alone.
"""

from __future__ import annotations

import abc
from collections.abc import Iterable
from typing import ClassVar

import numpy as np

from ..step import Action, Stage, StepContext

__all__ = ["Action", "Effect", "ForceNotFinite", "Recorder", "Stage", "StepContext"]


class Effect(abc.ABC):
    """A declared effect (loads, damping, contact, supports) or an observer.

    Attributes
    ----------
    name : str
        Its key in the work ledger and in the list of active effects.
    stage : Stage
        Where in the step its action runs.
    dissipative : bool
        Its force can only take energy out in the continuous problem (damping): work it books
        as put in is the step's instability, which the runaway guard does not allow for.
    """

    name: ClassVar[str]
    stage: ClassVar[Stage]
    dissipative: ClassVar[bool] = False

    def __init_subclass__(cls, **kwargs):
        # the step files every effect by its stage: one without (or with a string) would fail at
        # the first step, inside the simulation
        super().__init_subclass__(**kwargs)
        try:
            stage = cls.stage
        except AttributeError:
            raise TypeError(f"effect {cls.__name__}: no stage (a femgrid_mpm.effects.Stage)") from None
        if not isinstance(stage, Stage):
            raise TypeError(f"effect {cls.__name__}: stage {stage!r} is not a Stage")

    @abc.abstractmethod
    def bind(self, simulation) -> Action:
        """The action the step calls at :attr:`stage`, set up for ``simulation``."""

    def fixed(self, grid) -> np.ndarray | None:
        """(n_nodes, 2) bool: the degrees of freedom held at zero for the whole run, or
        None if this effect holds none."""
        return None

    def mirror(self, grid) -> tuple[np.ndarray, np.ndarray] | None:
        """``(image, sign)``, each (n_nodes, 2) (a wall of mirrored ghost nodes, the
        velocity ``v[n, c] = sign * v[image, c]``: :class:`femgrid_mpm.mass.NodeConstraint`),
        or None if this effect ties no node to another."""
        return None


class Recorder(abc.ABC):
    """An observer's action that keeps a record of the run (e.g. the error against an
    exact solution): the simulation puts it into the summary, offers its columns to
    the energy record and carries it through a checkpoint.

    An effect's :meth:`Effect.bind` may return one; the step calls it like any action.
    """

    @abc.abstractmethod
    def __call__(self, ctx: StepContext) -> None:
        """Take one record."""

    def columns(self) -> dict:
        """Columns it adds to each energy record: name -> the value of the record just taken
        (it runs before the energy bookkeeping, which is an observer of the simulation's own)."""
        return {}

    @abc.abstractmethod
    def summary(self) -> dict:
        """Entries of the run's summary."""

    @abc.abstractmethod
    def state(self) -> np.ndarray:
        """The record so far, one row per record, for a checkpoint."""

    @abc.abstractmethod
    def restore(self, rows: np.ndarray) -> None:
        """Take back :meth:`state`; ValueError if it does not fit."""


class ForceNotFinite(ArithmeticError):
    """Raised by an effect's action whose forces are NaN or infinite at some points (an
    expression that overflows or has no value there); the simulation stops on it, naming
    the effect's key in the scene (:meth:`message`)."""

    def __init__(self, effect: Effect, key: str, points: np.ndarray, time: float):
        super().__init__(f"{effect.name}.{key}: NaN or infinity at {len(points)} point(s) at t = {time:g} s")
        self.effect, self.key, self.points, self.time = effect, key, points, time

    def message(self, scene, particles) -> str:
        """``loads[N].KEY: gives NaN or infinity ...``, the first point described."""
        from ..diagnostics import describe_point
        from . import scene_key

        return (f"{scene_key(scene, self.effect)}.{self.key}: gives NaN or infinity (or a force beyond 1e308 N) at "
                f"{len(self.points)} point(s) at t = {self.time:.6g} s; first at "
                f"{describe_point(particles, scene.bodies, int(self.points[0]))}")


def has_name(effect) -> bool:
    """Whether an Effect (class or instance) has the ``name`` it declares (a str): a class that
    leaves it out fails only when the set-up files its action, so the registry and the observers'
    check ask first."""
    return isinstance(getattr(effect, "name", None), str)


def checked_observers(observers) -> list:
    """``Simulation(observers=...)`` as a list of :class:`Effect` s (each with its :class:`Stage`,
    checked when its class is made); TypeError naming the first entry that is not one."""
    if observers is None:
        return []
    if isinstance(observers, (str, bytes, Effect)) or not isinstance(observers, Iterable):
        raise TypeError(f"observers: a list of Effect objects, got {type(observers).__name__}")
    listed = list(observers)
    for index, observer in enumerate(listed):
        if not isinstance(observer, Effect):
            raise TypeError(f"observers[{index}]: a {type(observer).__name__}, not an Effect "
                            "(femgrid_mpm.effects.Effect: a name, a stage and bind)")
        if not has_name(observer):  # the set-up files its action by it
            raise TypeError(f"observers[{index}]: a {type(observer).__name__} without a name (a str)")
    return listed


def bound(effect: Effect, simulation) -> Action:
    """``effect.bind(simulation)``, checked to be an action the step can call."""
    action = effect.bind(simulation)
    if not callable(action):
        raise TypeError(f"effect {effect.name!r}: bind() returned a {type(action).__name__}, not an action "
                        "(a callable of the step's context)")
    return action
