"""Guards that stop a run with a clear message, and the events they record.

Every stop is a :class:`SimulationStopped` naming the step, the time and the
place (a node or a particle); the run's outputs written so far stay valid.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from .kernels.compiled import compiled


class SimulationStopped(RuntimeError):
    """A run could not go on.  ``result`` holds what was computed so far."""

    def __init__(self, message: str, step: int, time: float, reason: str):
        super().__init__(message)
        self.step = step
        self.time = time
        self.reason = reason
        self.result = None


class NegativeMassWarning(RuntimeWarning):
    """Negative lumped grid masses under the ``warn`` policy."""


class ScaleWarning(RuntimeWarning):
    """A scene whose sizes or times look like a units slip: a body with fewer points across
    than the basis needs, a time step longer than the run."""


def warn_of_a_long_step(dt: float, time, end_time: float) -> None:
    """A :class:`ScaleWarning` if the step ``dt`` (s) is longer than the run (``time``, the
    scene's ``[time]``); ``end_time``, the time the run ends at."""
    if dt > time.end:
        warnings.warn(
            f"dt = {dt:.6g} s{' (auto)' if time.dt == 'auto' else ''} exceeds time.end = {time.end:g} s: the run "
            f"takes one step, to t = {end_time:.6g} s (are the time, the spacing and the material in the same "
            "units?)", ScaleWarning, stacklevel=3)


def describe_point(particles, bodies, index: int) -> str:
    """``point I of body 'NAME' at (x, y), seeded at (x0, y0)``."""
    x, x0 = particles.x[index], particles.x0[index]
    return (f"point {index} of body {bodies[particles.body[index]].name!r} at ({x[0]:.6g}, {x[1]:.6g}), "
            f"seeded at ({x0[0]:.6g}, {x0[1]:.6g})")


def fastest_point(particles, bodies) -> str:
    """Where a runaway stands out: the point of largest kinetic energy (for a stop's message)."""
    p = particles
    return f"the most kinetic energy at {describe_point(p, bodies, int(np.argmax(p.mass * np.sum(p.v**2, axis=1))))}"


def first_not_finite(particles, bodies) -> str:
    """``; first at POINT``: the first point whose position, velocity or stress is NaN or Inf
    (for a stop's message); ``; first at POINT (its volume)`` where only another of the points'
    arrays is (a volume can overflow while the motion stays finite); "" if none is."""
    p = particles
    bad = ~(np.isfinite(p.x).all(axis=1) & np.isfinite(p.v).all(axis=1) & np.isfinite(p.stress).all(axis=1))
    found = np.flatnonzero(bad)
    if found.size:
        return f"; first at {describe_point(p, bodies, int(found[0]))}"
    for name, values in {**p.arrays(), "volume": p.volume}.items():  # the volume: mass over a density that may be 0
        if values.dtype.kind == "f" and values.ndim and len(values) == p.n:
            found = np.flatnonzero(~np.isfinite(values.reshape(p.n, -1)).all(axis=1))
            if found.size:
                return f"; first at {describe_point(p, bodies, int(found[0]))} (its {name})"
    return ""


class EnergyDriftWarning(RuntimeWarning):
    """A run that ended with its energy balance off by more than :data:`ENERGY_DRIFT_LIMIT`."""


#: the ``|energy_drift|`` above which a completed run warns: the paper's runs end within
#: 0.03 (box impact with shared contact, dt = 0.005); an error of a tenth of the energy
#: is no longer a discretization detail
ENERGY_DRIFT_LIMIT = 0.1


def warn_of_energy_drift(drift: float | None) -> None:
    """One :class:`EnergyDriftWarning` if ``|drift|`` (see
    :func:`femgrid_mpm.observers.energy_drift`) exceeds :data:`ENERGY_DRIFT_LIMIT`."""
    if drift is not None and abs(drift) > ENERGY_DRIFT_LIMIT:
        warnings.warn(
            f"the energy balance is off by {drift:.3g} of the run's energy at its end (energy_drift, above "
            f"{ENERGY_DRIFT_LIMIT:g}): a finer grid or a smaller time step (time.safety with dt = 'auto', or dt) lowers it",
            EnergyDriftWarning, stacklevel=3)


@dataclass
class NegativeMassMonitor:
    """Checks the lumped (row-sum) grid masses every step.

    A mass counts as negative below ``-1e-12`` of a full cell's mass
    (rounding in shape functions that are exactly zero must not count).
    The mass ratio reported is ``m_i / scale_i``, the nodal mass over the
    mass of one full lattice cell of the material there (``spacing^2 *
    density`` of the heaviest body touching the node,
    :meth:`femgrid_mpm.mass.CellMasses.at_nodes`).

    Parameters
    ----------
    policy : {"error", "warn", "threshold"}
        Stop the run at the first negative mass, record it and go on, or
        record it and go on quietly because the mass model does not divide
        by such masses (:class:`femgrid_mpm.mass.LumpedMass` ``threshold``);
        then the nodes below the threshold are counted too
        (:meth:`record_below_threshold`).
    applies : bool
        False for consistent and HRZ mass, which never divide by a row sum:
        negative row sums are still recorded but never stop the run.
    """

    policy: str = "error"
    applies: bool = True
    steps_with_negative: int = 0
    first_step: int | None = None
    min_ratio: float = field(default=np.inf)
    max_nodes: int = 0
    steps_below_threshold: int = 0
    first_step_below_threshold: int | None = None
    max_below_threshold: int = 0

    def check(self, lumped: np.ndarray, scale, step: int, time: float, nodes: np.ndarray,
              smallest: float | None = None) -> None:
        """Record (and under "error" or "warn", report) negative masses in ``lumped``
        against ``scale``, a full cell's mass (kg), one or per node; ``smallest``, the
        minimum of ``lumped`` if known."""
        if np.ndim(scale) == 0:
            ratio = (lumped.min() if smallest is None else smallest) / scale
        else:  # per node: nodes no body touches (scale 0) have no mass to compare
            ratio = np.divide(lumped, scale, out=np.zeros_like(lumped), where=scale > 0).min(initial=np.inf)
        self.min_ratio = min(self.min_ratio, float(ratio))
        if ratio >= -1e-12:
            return
        negative = np.flatnonzero(lumped < -1e-12 * scale)
        self.steps_with_negative += 1
        self.max_nodes = max(self.max_nodes, len(negative))
        if self.first_step is None:
            self.first_step = step
        if not self.applies or self.policy == "threshold" or (self.policy != "error" and self.steps_with_negative > 1):
            return  # nothing to say: the message is built only when it is raised or warned
        ratios = lumped[negative] / (scale if np.ndim(scale) == 0 else scale[negative])
        worst = negative[np.argmin(ratios)]
        message = (
            f"step {step} (t = {time:.6g} s): negative grid mass at {len(negative)} node(s), "
            f"the most negative is node {worst} at ({nodes[worst, 0]:g}, {nodes[worst, 1]:g}) "
            f"with {ratios.min():.3g} of a full cell's mass"
        )
        if self.policy == "error":
            raise SimulationStopped(message, step, time, "negative_mass")
        if self.steps_with_negative == 1:
            warnings.warn(message + " (policy 'warn': going on)", NegativeMassWarning, stacklevel=3)

    def record_below_threshold(self, count: int, step: int) -> None:
        """Count the nodes below the mass threshold at ``step``."""
        if count:
            self.steps_below_threshold += 1
            self.max_below_threshold = max(self.max_below_threshold, count)
            if self.first_step_below_threshold is None:
                self.first_step_below_threshold = step

    def summary(self) -> dict:
        summary = {
            "steps_with_negative_mass": self.steps_with_negative,
            "first_step": self.first_step,
            "min_mass_ratio": None if not np.isfinite(self.min_ratio) else self.min_ratio,
            "max_negative_nodes": self.max_nodes,
        }
        if self.policy == "threshold":
            summary.update(
                steps_below_threshold=self.steps_below_threshold,
                first_step_below_threshold=self.first_step_below_threshold,
                max_nodes_below_threshold=self.max_below_threshold,
            )
        return summary

    def state(self) -> dict:
        """The counters, for a checkpoint (:meth:`restore` takes them back)."""
        return {name: getattr(self, name) for name in _MONITOR_COUNTERS}

    def restore(self, state: dict) -> None:
        """Take back :meth:`state`; ValueError naming a counter that is not a count (or a step
        where one may be None, or a ratio where the smallest one goes)."""
        for name in _MONITOR_COUNTERS:
            value = state[name]
            if name == "min_ratio":
                ok = isinstance(value, (int, float)) and not isinstance(value, bool) and not np.isnan(value)
            else:
                ok = (value is None and name.startswith("first_")) or (
                    isinstance(value, int) and not isinstance(value, bool) and value >= 0)
            if not ok:
                raise ValueError(f"negative_mass.{name}: {value!r} is not a {'ratio' if name == 'min_ratio' else 'count'}")
        for name in _MONITOR_COUNTERS:
            setattr(self, name, state[name])


_MONITOR_COUNTERS = ("steps_with_negative", "first_step", "min_ratio", "max_nodes",
                     "steps_below_threshold", "first_step_below_threshold", "max_below_threshold")


#: the ``solver.weak_fraction`` that a runaway with consistent mass suggests (below it)
WEAK_HINT = 0.1
RUNAWAY_CAUSES = "a time step above the critical one, or an unstable model"


def runaway_causes(solver, nonnegative: bool, time=None, damping_step: float = 0.0) -> str:
    """What a runaway's stop suggests for a scene's ``[solver]`` (and ``[time]``): with consistent
    mass on a basis whose weak nodes are lumped, also ``weak_fraction``.  A body whose edge crosses
    a node line leaves the next node a sliver of its function's volume and a mode of almost no
    mass: q1 and gimp on the drifting bar ran away at steps 24 and 21 at the default 0.01 and
    completed at 0.1.  With ``dt = "auto"``, also ``safety``: the step is the first
    configuration's, and such modes lower the critical step as the points move (consistent cubic
    splines' block of 4e5 points: below the run's step by step 1080 of 1143, docs/time_step.md).
    ``damping_step``, mass damping's ``c dt``: above 2 the damping alone amplifies a motion by
    ``c dt - 1`` a step, which no time step below the critical one cures."""
    causes = RUNAWAY_CAUSES
    if damping_step > 2.0:
        causes += f"; damping.coefficient x dt = {damping_step:.6g} is above 2, where mass damping itself is unstable"
    if solver.mass == "consistent" and nonnegative and solver.weak_fraction < WEAK_HINT:
        causes += (f"; with consistent mass, nodes a body reaches by their function's tail: "
                   f"solver.weak_fraction = {WEAK_HINT:g} lumps them")
    if time is not None and time.dt == "auto":
        causes += (f"; dt = \"auto\" is time.safety = {time.safety:g} times the first configuration's critical "
                   f"step, which moving points can lower: a smaller time.safety, dearer, keeps a margin")
    return causes


@dataclass
class EnergyGuard:
    """Stops a run whose energy runs away (an unstable time step, a blow-up).

    The run stops when its energy exceeds ``factor * (initial + sum max(W_k, 0)
    + floor)``: ``initial`` the total energy (kinetic + strain) at the start,
    ``W_k`` the work done so far by each declared force (loads, damping,
    contact), and ``floor`` a small energy that keeps bodies starting at rest
    from tripping on round-off.  The balance ``E = initial + sum W_k`` is at
    most ``initial + sum max(W_k, 0)``: work that took energy out (damping,
    friction) allows no more energy.  It once counted ``|W_k|``, and then
    the damping that a growing mode feeds (its work is ~2c/lambda of the
    kinetic energy for growth rate lambda) raised the bound with the mode: a
    damped cantilever ran away to 260 J from 2e-5 J unseen.  A stable run
    stays within a few percent of its energy balance; an unstable mode grows
    by orders of magnitude, so it is caught well before the state overflows.

    Checked on what is cheap, every step: the ``total`` of the step's
    energy record (when ``[output] energy`` is declared and the step is
    recorded), else the points' kinetic energy, which alone cannot exceed the
    bound in a run that keeps its energy balance (one compiled pass over the
    points, :func:`points_kinetic_energy`: ~0.8 ns per point, 1% of a lumped
    step).  Every step, because at 3x the critical step the energy grows
    ~1000-fold per step: the vibrating bar's points leave the grid at step 4
    (the guard stops it at step 1).
    """

    initial: float
    floor: float
    factor: float = 10.0
    causes: str = RUNAWAY_CAUSES  # what the stop suggests (:func:`runaway_causes`)
    #: the work ledger's names of forces that only take energy out (damping): positive work of
    #: theirs is the instability itself (mass damping with c dt = 3 grew the bar's energy
    #: 6e5-fold in 10 steps, its own work raising the bound in step), so it allows no more energy
    dissipative: tuple[str, ...] = ()
    #: the largest energy a check saw, or that the balance gives (initial + work), plus the work
    #: done by then: the scale of ``energy_drift`` without energy records (the ends alone missed a
    #: peak between them: the manufactured solution's drift was 0.10 against its records' 0.039)
    peak: float = 0.0

    @classmethod
    def of(cls, simulation, acting: list, initial: float) -> "EnergyGuard":
        """The guard of a simulation at set-up (``acting``, its declared effects; ``initial``, its
        energy): a floor of 1e-9 x sum E V, the strain energy of a strain ~4.5e-5 throughout every body."""
        from .effects.damping import MassDamping

        scene = simulation.scene
        stiffness_volume = sum(body.material.E * float(simulation.particles.volume[members].sum())
                               for body, members in zip(scene.bodies, simulation.body_slices))
        # the mass damping's, from the effects: another kind of [damping] (one class and one registry
        # line, docs/extending.md) need not have a coefficient, nor one of this meaning
        damping_step = sum(float(effect.coefficient) for effect in acting if isinstance(effect, MassDamping)) * simulation.dt
        return cls(initial=initial, floor=1e-9 * stiffness_volume,
                   causes=runaway_causes(scene.solver, simulation.grid.nonnegative, scene.time, damping_step),
                   dissipative=tuple(effect.name for effect in acting if effect.dissipative))

    def bound(self, work: dict) -> float:
        """The energy (J per unit thickness) above which the run has run away."""
        return self.factor * (self.initial + self.energy_in(work) + self.floor)

    def energy_in(self, work: dict) -> float:
        """``sum max(W_k, 0)`` over the forces that are not :attr:`dissipative`: the energy the
        declared forces can have put in (J per unit thickness)."""
        return sum(w for name, w in work.items() if w > 0.0 and name not in self.dissipative) if work else 0.0

    def check(self, energy: float, what: str, work: dict, step: int, time: float, place=None) -> None:
        """Raise :class:`SimulationStopped` (reason ``runaway_energy``) if ``energy`` is above the bound;
        ``place()``, if given, says where (computed only then)."""
        # the energy checked, or the balance's initial + work where strain holds it (not checked)
        done = sum(work.values())
        self.peak = max(self.peak, energy + abs(done), self.initial + done + abs(done))  # (NaN leaves it)
        bound = self.bound(work)
        if not energy > bound:  # also NaN: the finiteness check names that
            return
        where = f"; {place()}" if place is not None else ""
        raise SimulationStopped(
            f"step {step} (t = {time:.6g} s): the energy ran away: {what} {energy:.6g} J/m exceeds "
            f"{self.factor:g} x (initial total {self.initial:.6g} + work put in {self.energy_in(work):.6g} + floor "
            f"{self.floor:.3g}) = {bound:.6g} J/m ({self.causes}){where}",
            step, time, "runaway_energy",
        )


@compiled()
def points_kinetic_energy(mass: np.ndarray, velocity: np.ndarray) -> float:
    """``1/2 sum m_p v_p.v_p`` in one compiled pass (for the guard; the energy
    records use :func:`femgrid_mpm.observers.kinetic_energy`)."""
    total = 0.0
    for p in range(mass.shape[0]):
        total += mass[p] * (velocity[p, 0] * velocity[p, 0] + velocity[p, 1] * velocity[p, 1])
    return 0.5 * total


def at_rest(time_spec, time: float, mass, velocity: np.ndarray) -> bool:
    """Whether the grid's mass-weighted RMS speed is below ``time.rest_speed`` (after
    ``time.rest_after``): the grid velocity moves the points (Eq. 20), while FLIP leaves noise on
    the points' own that damping on the grid never removes (cubic B-splines: ~1e-6 m/s);
    weighting by mass (``mass.nodal_masses()``) ignores nodes with a tiny share."""
    rest_speed = time_spec.rest_speed
    if rest_speed is None or time < time_spec.rest_after:
        return False
    lumped = np.maximum(mass.nodal_masses(), 0.0)
    mean_square = np.sum(lumped[:, None] * velocity**2) / np.sum(lumped)
    return bool(np.sqrt(mean_square) < rest_speed)
