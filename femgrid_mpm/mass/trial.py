"""What "auto" measures of the kept factors and of CG during a run, to choose between them.

:class:`RefactorRate` counts how often the kept factors (:mod:`.reused`) are made again and
what their solves cost, :class:`FactoredRate` what systems factored every step cost with the
analyses of the layouts the points' motion makes, :class:`CgTrial` what CG costs over its first
steps instead of either (:mod:`.gauss_seidel`'s work model); :class:`.layout.RunChoices` keeps
them to the run's end and in its checkpoints.  All three count the run's steps and iterations,
not the machine's time, so that a run and its resumption choose alike.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from .gauss_seidel import cg_work
from .reused import REFACTOR_ITERATIONS

if TYPE_CHECKING:
    from .ldl import SymbolicLDL


#: steps over which :class:`RefactorRate` counts the refactorizations of the kept factors ...
RATE_WINDOW = 20
#: ... and the share of them at or above which the kept factors count as stale for the run
RATE_LIMIT = 0.4


#: a refactorization of kept factors in solves with them: SuperLU's factorization and its
#: conversion took 33-59 times one solve of two columns with the factors it made (q1, q2,
#: serendipity at 5e3 and 1e4 points, quadratic splines at 1e4; 2-6 ms)
REFACTOR_SOLVES = 35

#: a layout's analysis (:meth:`.ldl.SymbolicLDL.analyse`: SuperLU's ordering and the structure
#: of ``L``) in products with the matrix: 120-150 for q1, q2, serendipity, gimp and the splines'
#: blocks at 1e3 and 2.5e3 points (0.8-2.6 ms)
ANALYSIS_WORK = 140
#: the compiled ``L D L^T``'s factorization per ``sum c_j^2 / 2 nnz`` products, and a solve of
#: two columns with it per ``(2 entries of L + n) / nnz`` products: measured 0.35-0.68 and
#: 0.48-0.90 on the same systems
FACTOR_SHARE = 0.5
SOLVE_SHARE = 0.65
#: CG's iterations a solve whose work :class:`FactoredRate`'s must exceed for CG to be tried
#: (q1's block at 1e4 points took 3.5, its velocity 2 and its acceleration 5; gimp's at 1e3
#: 4.2): 19.4 products a step of two solves, above what systems factored on one layout cost
#: (q1, q2 and serendipity at 1e3 points 6-8, gimp's with its weak nodes lumped 16.7)
TRY_ITERATIONS = 5.5


@dataclass
class RefactorRate:
    """How often the kept factors are made again, and what they cost; once they are made again
    in :data:`RATE_LIMIT` of :data:`RATE_WINDOW` steps (``stale``), CG's iterations on factors
    that keep going stale buy nothing: for the rest of the run the small systems that factor
    cheaply enough (:data:`.ldl.STALE_WORK`) are factored every step, and the others are solved
    by CG without factors while it costs less (:func:`.layout.make_systems`, :class:`CgTrial`).

    ``per_step``: the work of the kept factors' solves and refactorizations a step over the
    last full window, in products with the matrix (:meth:`observe`), against which CG is tried.

    GIMP's block made its kept factors again at 93 of 200 steps at 1e3 points, at ~85 of 200
    from 2.5e3 to 1e4 (a solve took more than :data:`REFACTOR_ITERATIONS`, or the weak nodes
    changed); cubic splines' at 16 of 200, q2's at 26 of 200 at 5e3 points, q1's at 1e4 points
    once.  The count is of the run's steps, not of the machine's speed, and it is in the
    checkpoint: a run and its resumption decide alike."""

    steps: int = 0
    refactors: int = 0
    stale: bool = False
    start: int | None = None  # the mass's CG iterations when the count of iterations began
    per_step: float | None = None
    counted: int = 0  # the steps whose iterations are in the count (observed at a step's start)

    def observe(self, refactored: bool, iterations: int = 0, solves: int = 2, fill: float = 0.0) -> None:
        """One step of systems on kept factors, at its start: whether they were made again, the
        mass's CG iterations so far, the solves a step and the factors' entries per matrix entry."""
        if self.stale:
            return
        if self.start is None:  # this step's own iterations are not in yet
            self.start, self.counted = iterations, -1
        self.steps += 1
        self.counted += 1
        self.refactors += bool(refactored)
        if self.steps == RATE_WINDOW:
            self.stale = self.refactors >= RATE_LIMIT * RATE_WINDOW
            # the run's first window: its first step made the factors the run needs whatever follows
            remade = self.refactors - (self.per_step is None and self.refactors > 0)
            if self.counted > 0:
                work = kept_work(solves * self.counted, iterations - self.start,
                                 remade * self.counted / RATE_WINDOW, fill)
                self.per_step = work / self.counted
            self.steps, self.refactors, self.start, self.counted = 0, 0, iterations, 0

    def restart(self) -> None:
        """The kept factors taken up again after CG: a new window (CG's iterations not in it)."""
        self.steps, self.refactors, self.start, self.counted = 0, 0, None, 0

    def values(self) -> list:
        """A checkpoint's values (:meth:`restored`)."""
        return [self.steps, self.refactors, self.stale, self.start, self.per_step, self.counted]

    @classmethod
    def restored(cls, values: list | None) -> "RefactorRate":
        if values is None:
            return cls()
        if len(values) <= 3:  # (an older checkpoint: the iterations of its window so far are not known)
            return cls(int(values[0]), int(values[1]), bool(values[2]))
        return cls(int(values[0]), int(values[1]), bool(values[2]), _or_none(int, values[3]),
                   _or_none(float, values[4]), int(values[5]))


#: an entry of the kept factors in a solve with them, in entries of the matrix in a product (the
#: triangular solves go column by column through both permutations).  Fitted as
#: :data:`.gauss_seidel.START_WORK`: 1.0-1.1 on q1's cantilever at h = 0.0625 (fill 3.1), 1.1-1.2
#: on serendipity's block at 1e4 points (fill 4.0), 1.4-1.7 on quadratic splines' (fill 10).  The
#: trials then price CG against the factors at 28.9 against 30.6 and 83.0 against 96.0 products
#: a step on the two blocks (CG took 2.05-2.22 against 2.38-2.47 and 7.9 against 11.1 ms a step,
#: interleaved), 13.8 against 13.0 on the cantilever (2.78 against 2.54 ms)
FACTOR_ENTRY_WORK = 1.1


def kept_work(solves: int, iterations: int, refactors: int, fill: float) -> float:
    """The work of solves on kept factors holding ``fill`` entries per matrix entry, in products
    with the matrix: each solve a product and a solve with the factors (:data:`FACTOR_ENTRY_WORK`
    a factor's entry), and as many again for each of its ``iterations``; each refactorization
    :data:`REFACTOR_SOLVES` solves."""
    solve = FACTOR_ENTRY_WORK * fill
    return (solves + iterations) * (solve + 1.0) + refactors * REFACTOR_SOLVES * solve


def factored_work(layout: "SymbolicLDL", solves: int) -> float:
    """A step's work on a system factored every step, in products with its matrix: one
    factorization and ``solves`` solves (:data:`FACTOR_SHARE`, :data:`SOLVE_SHARE`)."""
    n = len(layout.order)
    entries = 2 * len(layout.upper_rows) + n  # the free rows' stored entries (the strict upper half twice)
    if entries == 0:  # a component the supports hold at every node: nothing to factor or solve
        return 0.0
    return (FACTOR_SHARE * layout.work * layout.factor_entries / (2 * entries)
            + solves * SOLVE_SHARE * (2 * layout.factor_entries + n) / entries)


@dataclass
class FactoredRate:
    """What systems factored every step (:mod:`.ldl`) cost a step, in products with the matrix:
    their factorizations and solves (:func:`factored_work`) and the analyses of their layouts
    (:data:`ANALYSIS_WORK` a system, but for the first layout), averaged over all the run's steps on them
    and updated every :data:`RATE_WINDOW` of those steps (``per_step``).  Where the points keep
    changing the active or weak nodes, each new layout is analysed afresh, which CG does not
    need: CG is tried (:class:`CgTrial`) once ``per_step`` exceeds CG's work at
    :data:`TRY_ITERATIONS`, if the last step was factored every step.  The layouts come in bursts
    as the points cross the nodes' supports back and forth, so the average is of the whole run,
    not of the last window.

    GIMP's block at 1e3 points with ``dt = "auto"`` made 74 layouts in 455 steps (their analyses
    took 218 of the run's 470 ms); CG solved the run in 259-273 ms against 389-448.  q1, q2 and
    serendipity at 1e3 points analyse once and cost 6-8 products a step."""

    steps: int = 0
    analyses: int = 0
    work: float = 0.0  # the factorizations' and solves' so far
    per_step: float | None = None
    layout: str | None = None  # the last layout observed (:meth:`.layout.SystemsLayout.key`)
    last: bool = False  # whether the last step solved directly was factored every step

    def observe(self, layout: str, systems: int, work: float) -> None:
        """One step of ``systems`` systems factored every step on ``layout`` (its key), with the
        work of its factorizations and solves; a layout other than the last observed one was
        analysed in it (the first observed is not counted: any solver's first step needs it).
        The key, not the layout object, is compared: a resumed run makes its layout afresh."""
        if self.layout is not None and layout != self.layout:
            self.analyses += systems
        self.layout, self.last = layout, True
        self.steps += 1
        self.work += work
        if self.steps % RATE_WINDOW == 0:
            self.per_step = (self.work + ANALYSIS_WORK * self.analyses) / self.steps

    def pays_to_try(self, solves: int) -> bool:
        """Whether the last step was factored every step and CG at :data:`TRY_ITERATIONS` a solve
        would cost less than these systems do."""
        return self.last and self.per_step is not None and self.per_step > cg_work(solves, TRY_ITERATIONS * solves)

    def values(self) -> list:
        return [self.steps, self.analyses, self.work, self.per_step, self.layout, self.last]

    @classmethod
    def restored(cls, values: list | None) -> "FactoredRate":
        if values is None:  # (an older checkpoint: counted from here)
            return cls()
        return cls(int(values[0]), int(values[1]), float(values[2]), _or_none(float, values[3]),
                   _or_none(str, values[4]), bool(values[5]))


@dataclass
class CgTrial:
    """Whether CG, tried instead of the kept factors (:func:`.layout.make_systems`), is cheaper than
    they were: over its first :data:`RATE_WINDOW` steps, CG's work
    (:func:`.gauss_seidel.cg_work`) may be at most the kept factors' over their last window
    (:attr:`RefactorRate.per_step`, their remaking counted); more, and the run goes back
    to kept factors.  CG is tried after the kept factors' first window where it would take
    symmetric Gauss-Seidel (:mod:`.gauss_seidel`), and again, once, if the kept factors go stale
    after that trial was lost.  A CG on Jacobi or the tensor preconditioner (tried only where the
    factors went stale), and a trial from an older checkpoint, may take at most as many
    iterations a solve as the kept factors cost at their most in products (:meth:`limit`).

    Measured, ms a step on kept factors against CG, and the verdict: q1's block at 1e4 points
    1.79 against 1.18, CG; the cantilever at h = 0.0625, whose kept factors take one iteration
    an acceleration, q1 2.71 against 2.95 and open-knot quadratic splines 4.9 against 7.6, kept
    factors; the drifting bar at h = 0.05, q1 2.23 against 1.47-1.59, CG; with ``dt = "auto"``,
    serendipity's block at 1e4 points 2.38-2.47 against 2.05-2.22 and quadratic splines' 11.1
    against 7.9, CG."""

    fill: float = 0.0  # entries of the last kept factors per entry of their matrix
    start: int | None = None  # the mass's CG iterations when the trial began (None: not begun)
    steps: int = 0
    verdict: bool | None = None  # True: CG for the rest of the run; False: kept factors
    sweeps: bool = True  # the CG tried is symmetric Gauss-Seidel's (else judged by :meth:`limit`)
    stale: bool = False  # begun because the kept factors went stale
    factored: bool = False  # tried instead of systems factored every step (:class:`FactoredRate`)

    def limit(self) -> float:
        """CG's iterations a solve at which it costs what the kept factors did at their most,
        counting a CG iteration as one product and a factor's entry as one matrix entry (not
        :data:`FACTOR_ENTRY_WORK`: a Jacobi or tensor-preconditioned iteration costs more than
        the one product it is counted as, too)."""
        return (REFACTOR_ITERATIONS + 1) * self.fill + REFACTOR_ITERATIONS

    def begin(self, iterations: int, sweeps: bool, stale: bool, factored: bool = False) -> None:
        """A step on CG instead of kept factors (or, ``factored``, of systems factored every
        step) with the mass's CG iterations so far: the trial's first, if not begun."""
        if self.start is None:
            self.start, self.sweeps, self.stale, self.factored = iterations, sweeps, stale, factored

    def observe(self, iterations: int, solves_per_step: int, kept_per_step: float | None) -> None:
        """At a step's start, once begun: the mass's CG iterations so far."""
        if self.start is None or self.verdict is not None:
            return
        self.steps += 1
        if self.steps == RATE_WINDOW:
            taken = iterations - self.start
            if self.sweeps and kept_per_step is not None:
                self.verdict = bool(cg_work(solves_per_step * RATE_WINDOW, taken) <= kept_per_step * RATE_WINDOW)
            else:  # Jacobi or the tensor preconditioner, or an older checkpoint (no fill measured: CG stays)
                self.verdict = bool(not self.fill or taken <= self.limit() * RATE_WINDOW * solves_per_step)

    def values(self) -> list:
        return [self.fill, self.start, self.steps, self.verdict, self.sweeps, self.stale, self.factored]

    @classmethod
    def restored(cls, values: list | None) -> "CgTrial":
        if values is None:
            return cls()
        sweeps, stale = (bool(values[4]), bool(values[5])) if len(values) > 4 else (False, True)  # (older: stale, limit)
        factored = bool(values[6]) if len(values) > 6 else False
        return cls(float(values[0]), _or_none(int, values[1]), int(values[2]), _or_none(bool, values[3]), sweeps, stale,
                   factored)


def _or_none(cast, value):
    """A checkpoint's value as ``cast`` (JSON keeps ints, floats and bools apart only loosely), None kept."""
    return None if value is None else cast(value)

