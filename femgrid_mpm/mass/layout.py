"""The systems a consistent mass solves in one step, and their layout kept over the steps.

A system is the matrix for one or both velocity components with its excluded degrees of
freedom (empty nodes, and fixed ones) as identity rows (:class:`.system._System`).  What the
systems are, which nodes each excludes and how each is solved follows from the active and
weak nodes alone (the supports are fixed for the run), which most steps leave as they were:
:class:`SystemsLayout` holds it, with what is worth keeping while it holds (the small
systems' orderings and structures for the compiled ``L D L^T``, :mod:`.ldl`, and CG's test of
singularity near the edges, :mod:`.singular`).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from .exclusion import _exclude_in_place
from .gauss_seidel import sweeps_apply
from .ldl import small_layouts
from .reused import KeptFactors
from .sparse import _CompiledCSR
from .system import _System
from .trial import CgTrial, FactoredRate, RefactorRate, factored_work

#: largest number of active nodes for which "auto" factors the matrix
DIRECT_LIMIT = 5000

#: ... unless CG has the tensor preconditioner (cubic splines) and SuperLU's factors hold more
#: than this many entries per nonzero entry of the free rows: then CG on it solves faster than
#: CG on the kept factors.  Measured (ms a step, kept factors against CG; fill): the block of
#: benchmarks/step.py at 1089, 1681, 2304, 2809 active nodes 2.9 vs 3.8 (4.55), 6.1 vs 5.0
#: (5.50), 8.7 vs 5.8 (5.57), 13.6 vs 7.9 (5.85); the bar at h = 0.0625, 1577 nodes, 5.0 vs 5.6
#: (4.39); the cantilever at h = 0.125 and 0.0625, 737 and 2489 nodes, 2.1 vs 6.1 (2.43) and
#: 10.2 vs 15.3 (3.62); the manufactured solution at h = 1/32 and 1/64, 1225 and 4489 nodes,
#: 2.6 vs 3.6 (4.82) and 15.5 vs 11.3 (7.46).  The factors' entries per row grow with the
#: width of the body (a square fills more than a beam of as many nodes).
FILL_LIMIT = 5.2


@dataclass
class SystemsLayout:
    """One step's systems' layout: ``excluded`` (n, 2), the ``groups`` of columns solved
    together (one system for both components when they are fixed alike), whether they are
    factored (``direct``), the small systems' ``L D L^T`` layouts and CG's edge blocks."""

    active: np.ndarray
    weak: np.ndarray
    excluded: np.ndarray
    groups: list
    direct: bool
    small: dict | None = None  # {columns: SymbolicLDL}; None: not analysed yet
    fill: float | None = None  # SuperLU's fill, where make_systems measured it (:func:`_fill`)
    stale_cg: bool = False  # solved by CG instead of kept factors (make_systems, CgTrial)
    edges: dict = field(default_factory=dict)  # {columns: SymbolicLDL or None} (.singular)
    _key: str | None = field(default=None, compare=False, repr=False)  # (key(), made once)
    # what every_step() and factored_work() found for the small layouts they were given (`small` is
    # replaced, never changed in place; the set and the sum took ~3 us a step at 1e3 points)
    _of_small: tuple | None = field(default=None, compare=False, repr=False)

    @classmethod
    def of(cls, active: np.ndarray, weak: np.ndarray, fixed: np.ndarray | None, linear_solver: str) -> "SystemsLayout":
        excluded = ~active[:, None] if fixed is None else (~active[:, None] | fixed)
        # column by column in memory: each system's column is then a contiguous array, so the
        # kernels it reaches compile once (a strided column was a second specialisation of each)
        excluded = np.broadcast_to(np.asfortranarray(excluded), (len(active), 2))
        groups = [(0, 1)] if np.array_equal(excluded[:, 0], excluded[:, 1]) else [(0,), (1,)]
        direct = linear_solver == "direct" or (linear_solver == "auto" and np.count_nonzero(active) <= DIRECT_LIMIT)
        return cls(active.copy(), weak.copy(), excluded, groups, direct)

    def key(self) -> str:
        """A digest of the excluded and weak nodes, the same for the same layout in a resumed run."""
        if self._key is None:
            nodes = np.packbits(self.excluded).tobytes() + np.packbits(self.weak).tobytes()
            self._key = hashlib.blake2b(nodes, digest_size=8).hexdigest()
        return self._key

    def every_step(self, stale: bool = False) -> frozenset:
        """The columns of the systems factored every step (:attr:`.ldl.SymbolicLDL.every_step`; with
        ``stale``, kept factors made again at most steps, :attr:`.ldl.SymbolicLDL.every_step_when_stale`)."""
        found = self._found()
        if stale not in found:
            found[stale] = frozenset(columns for columns, layout in (self.small or {}).items()
                                     if (layout.every_step_when_stale if stale else layout.every_step))
        return found[stale]

    def factored_work(self) -> float:
        """A step's work on the small systems factored every step (:func:`.trial.factored_work`,
        two solves each)."""
        found = self._found()
        if "work" not in found:
            found["work"] = sum(factored_work(symbolic, 2) for symbolic in (self.small or {}).values())
        return found["work"]

    def _found(self) -> dict:
        """The cache of :meth:`every_step` and :meth:`factored_work` for the current ``small``."""
        if self._of_small is None or self._of_small[0] is not self.small:
            self._of_small = (self.small, {})
        return self._of_small[1]



@dataclass
class RunChoices:
    """What "auto" measured during the run and keeps to its end (and in checkpoints, so that a
    resumed run chooses alike): whether cubic splines solve by CG on the tensor preconditioner
    (``tensor_cg``, decided at the run's first SuperLU factorization: :data:`FILL_LIMIT`; the fill
    moves with the points, so it is not measured again), how often the kept factors were made
    again (:class:`.trial.RefactorRate`; too often: cheap small systems are factored every step,
    the others solved by CG, see :func:`make_systems`), what the systems factored every step cost
    with their layouts' analyses (:class:`.trial.FactoredRate`) and whether CG instead of either
    pays (:class:`CgTrial`)."""

    tensor_cg: bool | None = None
    rate: RefactorRate = field(default_factory=RefactorRate)
    trial: CgTrial = field(default_factory=CgTrial)
    factored: FactoredRate = field(default_factory=FactoredRate)

    def layout(self, active: np.ndarray, weak: np.ndarray, fixed, linear_solver: str) -> SystemsLayout:
        layout = SystemsLayout.of(active, weak, fixed, linear_solver)
        layout.direct &= not self.tensor_cg
        return layout

    def systems(self, matrix, diagonal_index, layout: SystemsLayout, kept: KeptFactors, weak: np.ndarray,
                auto: bool, tensor_preconditioner: bool, iterations: int) -> tuple[list, tuple | None, KeptFactors]:
        """:func:`make_systems` with these choices, which it updates (``auto``: ``linear_solver``
        is "auto"; ``iterations``: the mass's CG iterations so far)."""
        stale = self.rate.stale
        solves = 2 * len(layout.groups)  # velocity and acceleration
        self.trial.observe(iterations, solves, self.factored.per_step if self.trial.factored else self.rate.per_step)
        if layout.stale_cg and self.trial.verdict is False:  # CG took more than the kept factors did
            layout.direct, layout.stale_cg = True, False
            self.rate.restart()
        if stale and self.trial.verdict is False and not self.trial.stale:  # lost before they went stale: again
            self.trial = CgTrial(fill=self.trial.fill)
        keeps_factors = auto and layout.direct
        # CG is tried where the factors went stale, or once they were measured over a window if CG
        # would sweep (symmetric Gauss-Seidel: a third of Jacobi's iterations); the scipy path's
        # systems are new CSR matrices, sorted, every diagonal stored
        sweeps = not tensor_preconditioner and (sweeps_apply(matrix) or not isinstance(matrix, _CompiledCSR))
        # systems factored every step whose layouts the points keep changing (each analysed afresh)
        instead_of_factored = (sweeps and self.trial.verdict is not False and self.factored.pays_to_try(solves)
                               and (self.trial.start is None or self.trial.factored))
        try_cg = ((stale or (sweeps and self.rate.per_step is not None)) and self.trial.verdict is not False
                  or instead_of_factored)
        systems, correction, kept = make_systems(matrix, diagonal_index, layout, kept, weak, keeps_factors,
                                                 tensor_preconditioner and self.tensor_cg is None, stale, try_cg,
                                                 instead_of_factored)
        if layout.stale_cg:
            self.trial.begin(iterations, sweeps, stale, instead_of_factored)
        if layout.fill is not None and self.tensor_cg is None:
            self.tensor_cg = not layout.direct
        if keeps_factors and layout.direct:
            if layout.small and set(layout.groups) <= layout.every_step(stale):
                self.factored.observe(layout.key(), len(layout.small), layout.factored_work())
            else:  # on kept factors: a trial from here is theirs
                self.factored.last = False
        on_kept = keeps_factors and layout.direct and not stale
        every_step = layout.every_step()
        on_kept_factors = [system for system in systems if tuple(system.columns) not in every_step]
        if keeps_factors and layout.direct:  # the fill of the factors made this step, for the trial's limit
            for system in on_kept_factors:  # (or of those kept, where none was measured: a checkpoint without it)
                factors = kept.get(tuple(system.columns)) if system.kept is None else system.kept
                if factors is not None and (system.kept is None or not self.trial.fill):
                    self.trial.fill = factors.entries / max(int(np.count_nonzero(system.matrix.data)), 1)
        if on_kept and on_kept_factors:  # were their factors made again (this step's own L D L^T or SuperLU's)?
            refactored = any(system.ldl is not None or system.factors is not None for system in on_kept_factors)
            self.rate.observe(refactored, iterations, solves, self.trial.fill)
        return systems, correction, kept

    def values(self) -> dict:
        return {"refactor_rate": self.rate.values(), "tensor_cg": self.tensor_cg, "cg_trial": self.trial.values(),
                "factored_rate": self.factored.values()}

    @classmethod
    def restored(cls, values: dict) -> "RunChoices":
        return cls(values.get("tensor_cg"), RefactorRate.restored(values.get("refactor_rate")),
                   CgTrial.restored(values.get("cg_trial")), FactoredRate.restored(values.get("factored_rate")))


def make_systems(matrix, diagonal_index: np.ndarray | None, layout: SystemsLayout, kept: KeptFactors,
                 weak: np.ndarray, keeps_factors: bool, fill_test: bool = False,
                 stale: bool = False, try_cg: bool = False,
                 instead_of_factored: bool = False) -> tuple[list, tuple | None, KeptFactors]:
    """The step's systems of the assembled ``matrix``: ``(systems, correction, kept)``, the
    entries the exclusion overwrote if it was made into the one system in place, and the
    factors kept for the next steps (``kept``: those that fit the layout).

    Below DIRECT_LIMIT, "auto" (``keeps_factors``) factors a small system by the compiled
    ``L D L^T`` on its layout (:mod:`.ldl`), every step where that is cheap, and a larger one
    by SuperLU; factors not made every step are kept while they fit (:mod:`.reused`).  With
    ``fill_test`` (CG has the tensor preconditioner, and the run has not decided yet) SuperLU's
    factors are measured (``layout.fill``) and, above :data:`FILL_LIMIT`, the layout is solved by
    that CG instead (not direct): :class:`RunChoices` keeps the decision for the run, since the
    fill moves with the points (their couplings' zeros) while the layout stays.
    ``stale``: the kept factors were made again at too many steps (:class:`.trial.RefactorRate`):
    the small systems that factor cheaply are factored every step.  ``try_cg`` (stale, or CG
    would sweep, and :class:`CgTrial` has not found CG dearer): a layout with systems not
    factored every step (SuperLU's, or small ones that factor slowly) is solved by CG instead
    (not direct).  ``instead_of_factored`` (:meth:`.trial.FactoredRate.pays_to_try`): so are the
    systems factored every step, and the layout is not analysed.  GIMP's block, whose solves on
    kept factors took more than :data:`.reused.REFACTOR_ITERATIONS` iterations at ~45% of the
    steps, at 2.5e3 and 5e3 points (small systems that factor slowly) 1.74 and 3.6 ms a step on
    kept factors, 1.41 and 2.5-2.9 on CG; at 1e4 (SuperLU's) 10.2-13.2 against 4.8-5.1."""
    if keeps_factors and (layout.small is None or diagonal_index is None) and not instead_of_factored:
        # (the scipy path's structure is its product's, of this step)
        layout.small = small_layouts(matrix, layout.excluded, layout.groups, diagonal_index, layout.small)
    excluded, small = layout.excluded, layout.small or {}
    every_step = layout.every_step(stale)
    if keeps_factors and try_cg and layout.direct and (instead_of_factored or not set(layout.groups) <= every_step):
        # these systems cost too much to factor every step, and the kept factors went stale or
        # CG would sweep: CG, while it pays (CgTrial)
        layout.direct, layout.stale_cg = False, True
    kept = KeptFactors({columns: factors for columns, factors in kept.items() if columns not in every_step})
    correction = None
    if diagonal_index is not None and len(layout.groups) == 1:
        # the one system is made from the assembled matrix in place (a copy of its data was
        # ~25 ns per point-step for cubic splines at 1e5 points); M is R with the entries the
        # exclusion overwrote put back
        correction = _exclude_in_place(matrix.indptr, matrix.indices, matrix.data, diagonal_index, excluded[:, 0])
        systems = [_System.build(matrix, [0, 1], excluded[:, 0], layout.direct and not kept and not small,
                                 diagonal_index, in_place=True)]
    else:
        systems = [_System.build(matrix, list(columns), excluded[:, columns[0]],
                                 layout.direct and columns not in kept and columns not in small, diagonal_index)
                   for columns in layout.groups]
    if keeps_factors and fill_test and any(system.factors is not None for system in systems):
        layout.fill = max(_fill(system) for system in systems)
        if layout.fill > FILL_LIMIT:
            layout.direct = False
            for system in systems:
                system.factors = None
            return systems, correction, KeptFactors()
    if not layout.direct:
        return systems, correction, KeptFactors()
    for system in systems:
        columns = tuple(system.columns)
        if columns in small and (columns in every_step or columns not in kept):
            system.factor_now(small[columns], matrix.data)  # its free rows and columns are the system's
    if keeps_factors:
        for system in systems:
            system.kept = kept.get(tuple(system.columns))
            if system.kept is None and tuple(system.columns) not in every_step:
                kept.keep(system, weak)
    return systems, correction, kept


def _fill(system: _System) -> float:
    """Entries of a system's SuperLU factors per nonzero entry of its free rows (0 without
    factors); the excluded rows count one each in both."""
    if system.factors is None:
        return 0.0
    excluded = int(np.count_nonzero(system.excluded))
    return (system.factors.nnz - excluded) / max(int(np.count_nonzero(system.matrix.data)) - excluded, 1)
