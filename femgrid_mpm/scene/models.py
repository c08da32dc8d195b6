"""The scene's models: every table of a scene file is a model here, every key a field.

Unknown keys, wrong types, NaN and infinities are refused on construction,
so a scene that validates can be built.  Effects (loads, damping, contact,
supports) are their own classes in :mod:`femgrid_mpm.effects`; their tables'
types come from its registry.

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

import warnings
from typing import Annotated, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, NonNegativeFloat, PositiveFloat, Strict, field_validator, model_validator

from .. import effects
from ..bases import BASES
from ..bases import check_registry as check_bases
from ..schemes import SCHEMES
from ..effects import PointLoad
from ..engines import ENGINES
from ..expressions import compile_expression
from ..grid import MAX_NODES, length_problem, node_count
from ..particles import count_rectangle
from .limits import MAX_RECORD_BYTES, MAX_STEPS, step_count
from .messages import _shown
from .validation import CHECKING, SceneError, validated

#: Largest number of material points accepted, checked before allocating.
MAX_POINTS = 100_000_000

#: a number in a scene: an integer or a float, never a boolean or a string (pydantic would
#: take ``true`` as 1 and ``"0.5"`` as 0.5); strict where the scene's own checks read the
#: value, so that the error names the key that has the wrong type
Number = Annotated[float, Strict()]
PositiveNumber = Annotated[float, Strict(), Field(gt=0)]
Pair = tuple[Number, Number]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class GridSpec(_Model):
    """``[grid]``: the background grid (see :class:`femgrid_mpm.Grid`)."""

    #: the registered bases (:data:`femgrid_mpm.bases.BASES`)
    basis: Literal[tuple(BASES)] = "q1"
    lower: Pair
    upper: Pair
    spacing: PositiveNumber

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

    dt: Union[PositiveNumber, Literal["auto"]]
    end: PositiveNumber
    safety: Annotated[float, Field(gt=0, le=1)] = 0.5
    #: a run of more steps is refused before it starts (a time step in the wrong unit)
    max_steps: Annotated[int, Field(ge=1, le=2**53)] = MAX_STEPS
    rest_speed: Union[PositiveFloat, None] = None
    rest_after: NonNegativeFloat = 0.0


class SolverSpec(_Model):
    """``[solver]``: mass kind and what to do when masses misbehave.

    ``mass``: ``"lumped"`` (row sums), ``"consistent"``, ``"hrz"`` (a positive diagonal
    for every basis, :class:`femgrid_mpm.mass.HrzMass`) or ``"iterated"`` (:mod:`femgrid_mpm.mass.iterated`).
    ``negative_mass`` (lumped mass): ``"error"`` stops the run at the first
    negative lumped grid mass, ``"warn"`` records it and goes on,
    ``"threshold"`` records it and, at every node whose volume fraction is
    below ``mass_threshold``, divides by the absolute mass ``sum m_p |N_ip|``
    instead (see :class:`femgrid_mpm.mass.LumpedMass`).
    ``consistent_fallback``: ``"error"`` or ``"blend"`` when the consistent
    mass matrix is singular (see :mod:`femgrid_mpm.mass`), with ``blend``
    the lumped weight; ``weak_fraction`` the volume fraction under which a
    node is lumped; ``linear_solver`` how the consistent system is solved
    (``"auto"``: up to 5000 active nodes factored, every step or kept as CG's
    preconditioner, CG beyond; docs/scenes.md);
    ``cg_tolerance`` CG's relative residual; ``engine``
    the implementation of the step's transfers (:mod:`femgrid_mpm.kernels`).
    ``scheme``: the time integration, ``"paper"`` (section 3.2 as written),
    ``"centred"`` (second order in dt from any start) or ``"yoshida4"`` (fourth order,
    three sub-steps a step): :mod:`femgrid_mpm.schemes`, with each one's critical step.
    ``force_quadrature``: the internal force as the sum over the points
    (``"points"``, the paper's Eq. 11) or by Gauss quadrature of a stress fitted
    to the points in each filled cell (``"reconstructed"``,
    :mod:`femgrid_mpm.quadrature`): exact at a body's edges on the grid lines.
    ``mass_quadrature``: the consistent mass and momentum as the points' sums or by Gauss
    quadrature over the filled cells (``"reconstructed"``, :mod:`femgrid_mpm.quadrature`).
    """

    mass: Literal["lumped", "consistent", "hrz", "iterated"] = "lumped"
    #: mass = "iterated": the Jacobi corrections of the lumped solution that stand for the consistent solve
    mass_corrections: Annotated[int, Field(ge=1, le=20)] = 2
    negative_mass: Literal["error", "warn", "threshold"] = "error"
    #: negative_mass = "threshold": below this fraction of a node's full share, its absolute mass is used
    mass_threshold: Annotated[float, Field(ge=0, lt=1)] = 0.01
    consistent_fallback: Literal["error", "blend"] = "error"
    blend: Annotated[float, Field(gt=0, le=1)] = 0.1
    weak_fraction: Annotated[float, Field(ge=0, lt=1)] = 0.01
    #: consistent mass, non-negative bases: a row whose M_ii / m_i is below this fraction of an interior node's is weak
    weak_ratio: Annotated[float, Field(ge=0, lt=1)] = 0.0
    #: the share of a weak row's couplings moved onto the diagonals (1: the row lumped)
    weak_mix: Annotated[float, Field(gt=0, le=1)] = 0.02
    #: consistent mass: lumped weight a of the mixed mass (1 - a) M_C + a M_L on the whole grid
    mix: Annotated[float, Field(ge=0, le=1)] = 0.0
    linear_solver: Literal["auto", "direct", "cg"] = "auto"
    cg_tolerance: Annotated[float, Field(gt=0, lt=1)] = 1e-6
    #: the step's transfers (:data:`femgrid_mpm.engines.ENGINES`): compiled kernels, or scipy.sparse (the reference)
    engine: Literal[tuple(ENGINES)] = "numba"
    #: numba engine: threads for the tensor-product and serendipity kernels (1: serial, reproducible bit for bit)
    threads: Annotated[int, Field(ge=1, le=256)] = 1
    #: the time integration (:data:`femgrid_mpm.schemes.SCHEMES`): the paper's order, the centred
    #: difference (half-step velocities), or Yoshida's fourth-order composition of it
    scheme: Literal[tuple(SCHEMES)] = "paper"
    #: the internal force's integral: the points' sum, or Gauss quadrature of a reconstructed stress
    force_quadrature: Literal["points", "reconstructed"] = "points"
    #: the consistent mass and momentum: the points' sums, or Gauss quadrature over the filled cells
    mass_quadrature: Literal["points", "reconstructed"] = "points"


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
    points_per_cell: Annotated[int, Field(gt=0, le=2**63 - 1)] = 2
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


# The effects' tables, from the registry (femgrid_mpm.effects.REGISTRY): a new kind of
# load (or of damping) is its class and one registry line, no edit here.
effects.check_registry(("loads", "damping", "contact", "supports", "reference"))
check_bases()
#: ``[[loads]]``: a union discriminated on ``kind``
Load = effects.table_type("loads")
LOAD_KINDS = effects.kinds("loads")
#: ``[damping]``
DampingSpec = effects.table_type("damping")
#: ``[contact]``
ContactSpec = effects.table_type("contact")
#: ``[[supports]]``
SupportSpec = effects.table_type("supports")
#: ``[reference]``: an exact displacement field, and the run's error against it
ReferenceSpec = effects.table_type("reference")


class Output(_Model):
    """``[output]``: a record every ``every`` steps; ``energy`` bookkeeping; ``particles`` and
    ``grid`` (nodal mass, momentum, velocity, negative-mass flag) as ParaView series."""

    every: Annotated[int, Field(gt=0, le=2**63 - 1)] = 1
    energy: bool = True
    particles: bool = False
    grid: bool = False
    #: records estimated to take more bytes than this are refused before the run starts
    max_bytes: Annotated[int, Field(ge=1, le=2**63 - 1)] = MAX_RECORD_BYTES


class Scene(_Model):
    """A whole run.  Maps one to one onto a TOML scene file."""

    title: str = ""
    grid: GridSpec
    time: TimeSpec
    solver: SolverSpec = SolverSpec()
    bodies: Annotated[tuple[Body, ...], Field(min_length=1)]
    supports: tuple[SupportSpec, ...] = ()
    loads: tuple[Load, ...] = ()
    damping: Union[DampingSpec, None] = None
    contact: Union[ContactSpec, None] = None
    reference: Union[ReferenceSpec, None] = None
    output: Union[Output, None] = None

    @model_validator(mode="after")
    def _consistent(self):
        # Each message starts with the key it is about: these checks span
        # several tables, so pydantic cannot locate them itself.
        names = [body.name for body in self.bodies]
        first_of: dict[str, int] = {}
        for index, name in enumerate(names):
            if name in first_of:
                raise ValueError(f"bodies[{index}].name: {name!r} is already the name of bodies[{first_of[name]}]")
            first_of[name] = index
        for index, load in enumerate(self.loads):
            if isinstance(load, PointLoad) and load.body not in first_of:
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
        if isinstance(self.time.dt, float):
            try:
                step_count(self.time.end, self.time.dt, self.time.max_steps)
            except ValueError as error:
                raise ValueError(f"time.dt: {error}") from None
        if self.contact is not None and self.contact.kind == "shared" and (self.contact.friction or self.contact.gap):
            which = "friction" if self.contact.friction else "gap"
            raise ValueError(f"contact.{which}: applies to kind = 'frictional' only (one shared field has no "
                             "surfaces between the bodies)")
        if self.contact is not None and SCHEMES[self.solver.scheme].passes > 1:
            raise ValueError(f"solver.scheme: {self.solver.scheme!r} composes sub-steps of several sizes, some "
                             "negative; contact's velocity corrections are of one step: use 'paper' or 'centred'")
        if self.contact is not None and self.contact.kind == "frictional" and self.solver.mass != "lumped":
            raise ValueError("contact.kind: 'frictional' contact needs solver.mass = \"lumped\" (one lumped field per body)")
        if self.solver.mass == "iterated" and not BASES[self.grid.basis].nonnegative:
            raise ValueError(f"solver.mass: 'iterated' divides by the row sums, which {self.grid.basis}'s signed functions can "
                             "make zero or negative: use a non-negative basis (q1, gimp, B-splines), or mass = \"consistent\"")
        if self.solver.negative_mass == "threshold" and self.solver.mass == "lumped":
            if not BASES[self.grid.basis].mass_threshold:
                raise ValueError(
                    f"solver.negative_mass: 'threshold' cannot help {self.grid.basis}: not all its functions "
                    "integrate to a positive share (serendipity's corner functions: -1/12 of each element), so a "
                    "full share can be negative and no fraction of it is a threshold; use solver.mass = \"hrz\""
                )
            if self.contact is not None and self.contact.kind == "frictional":
                raise ValueError("solver.negative_mass: 'threshold' is implemented for one shared field, not for 'frictional' contact")
        if self.solver.mass_quadrature == "reconstructed":
            if self.solver.mass != "consistent":
                raise ValueError("solver.mass_quadrature: 'reconstructed' integrates the consistent mass: "
                                 "give solver.mass = \"consistent\"")
            if len({body.material.density for body in self.bodies}) > 1:
                raise ValueError("solver.mass_quadrature: 'reconstructed' is implemented for bodies of one density")
            # a fit that holds the basis' fields keeps M, K the Gauss integrals (3 x 3 cubic: ran away)
            if min(body.points_per_cell for body in self.bodies) < BASES[self.grid.basis].degree + 1:
                raise ValueError(f"solver.mass_quadrature: 'reconstructed' needs points_per_cell >= {BASES[self.grid.basis].degree + 1} with {self.grid.basis} (its degree plus one: the fitted fields must hold the basis' on a cell, or the step is not stable)")  # noqa: E501
        for key, quadrature in (("force_quadrature", self.solver.force_quadrature),
                                ("mass_quadrature", self.solver.mass_quadrature)):
            if quadrature == "reconstructed":
                self._check_reconstruction(key)
        sizes = sorted({body.points_per_cell for body in self.bodies})
        if BASES[self.grid.basis].sized and len(sizes) > 1:
            # the weights are laid out for one point size (the points' initial spacing)
            raise ValueError(f"bodies: {self.grid.basis} weighs every point as a square of one size, spacing / "
                             f"points_per_cell: give every body the same points_per_cell (got {sizes})")
        return self

    def _check_reconstruction(self, key: str) -> None:
        """What a Gauss quadrature of fields fitted in the cells needs (``solver.KEY = "reconstructed"``)."""
        if BASES[self.grid.basis].sized:
            raise ValueError(f"solver.{key}: 'reconstructed' needs functions that are polynomials on "
                             f"each lattice cell; {self.grid.basis}'s depend on the points' size")
        if min(body.points_per_cell for body in self.bodies) < 2:
            raise ValueError(f"solver.{key}: 'reconstructed' fits a polynomial to a cell's points: "
                             "give every body points_per_cell >= 2")
        if self.contact is not None and self.contact.kind == "frictional":
            raise ValueError(f"solver.{key}: 'reconstructed' is implemented for one shared field, "
                             "not for 'frictional' contact")

    def __init__(self, **data):
        if not CHECKING.get():  # Scene(**tables): strict as a file (pydantic would take "1e4" for 1e4)
            validated(type(self), data, {}, "scene")
        super().__init__(**data)

    @classmethod
    def model_validate(cls, obj, **options) -> "Scene":
        """The scene of ``obj``, a dict of a scene file's tables (or a Scene), checked as a file is
        (numpy arrays and scalars taken as lists and numbers); :class:`SceneError`, one line
        naming the key (``scene: grid.spacing: must be a number``), if it does not hold."""
        if options:  # pydantic's own options (strict, context, ...): pydantic's own validation
            return super().model_validate(obj, **options)
        if isinstance(obj, cls):  # checked again: model_copy(update=...) and model_construct check nothing
            with warnings.catch_warnings():  # pydantic's warning of such a copy's unexpected types
                warnings.simplefilter("ignore")
                data = obj.model_dump(mode="json", exclude_none=True)
            checked = validated(cls, data, {}, "scene")
            return obj if checked == obj else checked  # (a dict where a table's model goes: the model)
        if not isinstance(obj, dict):
            raise SceneError(f"scene: must be a dict of the tables of a scene file, got {type(obj).__name__}")
        return validated(cls, obj, {}, "scene")

    def node_count(self) -> float:
        """About how many grid nodes the scene makes (counted, nothing allocated)."""
        return node_count(self.grid.lower, self.grid.upper, self.grid.spacing, BASES[self.grid.basis].cells_per_element)

    def point_count(self, index: int) -> int:
        """How many points body ``index`` is seeded with (counted, nothing allocated)."""
        body = self.bodies[index]
        return count_rectangle(body.lower, body.upper, self.grid.spacing, body.points_per_cell)

    def with_overrides(self, **changes) -> "Scene":
        """A copy with dotted keys replaced, validated again; :class:`SceneError`, one line naming
        the key as for a scene file (a wrong type included), if it does not hold.  Keys are paths
        into the scene file, list items by index:
        ``scene.with_overrides(**{"grid.basis": "q2", "bodies.0.points_per_cell": 4})``."""
        data = self.model_dump(mode="json", exclude_none=True)
        source = "with " + ", ".join(f"{key} = {_shown(value)}" for key, value in changes.items())
        return validated(type(self), data, changes, source)

    def declared_effects(self) -> list:
        """The effects this scene declares that act on the step, in the order the step
        runs those of one stage (:data:`femgrid_mpm.effects.REGISTRY`): the loads in
        the file's order, damping, frictional contact, the supports.

        Shared contact (the single-field step) runs no code of its own and is not listed.
        """
        acting = []
        for table in effects.tables():
            value = getattr(self, table)
            declared = value if isinstance(value, tuple) else () if value is None else (value,)
            acting += [effect for effect in declared if effects.acts(table, effect)]
        return acting
