"""The explicit MPM step of the paper (section 3.2), composed from declared effects.

Examples
--------
A block moving rigidly moves exactly:

>>> from femgrid_mpm.scene import Scene
>>> scene = Scene.model_validate({
...     "grid": {"basis": "q1", "lower": [0, 0], "upper": [4, 2], "spacing": 0.5},
...     "time": {"dt": 0.01, "end": 1.0},
...     "bodies": [{"name": "block", "lower": [0.5, 0.5], "upper": [1.5, 1.5], "velocity": [1.0, 0.25],
...                 "material": {"E": 1e4, "nu": 0.3, "density": 1e3}}]})
>>> result = Simulation(scene).run()
>>> bool(abs(result.particles.x - result.particles.x0 - [1.0, 0.25]).max() < 1e-12)
True
"""

from __future__ import annotations

import functools
import math
import time as clock
from typing import Callable

import numpy as np

from .diagnostics import (EnergyGuard, NegativeMassMonitor, SimulationStopped, at_rest, fastest_point, first_not_finite,
                          points_kinetic_energy, warn_of_a_long_step, warn_of_energy_drift)
from .observers import EnergyBookkeeping, kinetic_energy
from .effects.base import ForceNotFinite, Recorder, bound, checked_observers
from .engines import engine_for
from .grid import Grid
from .mass import CellMasses, MassModel, NodeConstraint, SingularMassError, build_mass_model
from .materials import make_material
from .particles import seed_bodies, warn_of_overlaps, warn_of_thin_bodies
from .result import RunResult, run_result
from .scene import Scene
from .scene.limits import run_steps
from .schemes import SCHEMES
from .stability import critical_time_step
from .state import restore_state, simulation_state
from .step import Stage, StepContext


class Simulation:
    """A scene, built: grid, particles, materials, mass model and bound effects.

    Parameters
    ----------
    scene : Scene
    observers : list, optional
        Extra observing effects (:class:`~femgrid_mpm.effects.Effect` s: ``name``,
        ``stage`` and ``bind``), e.g. writers of particle output; TypeError otherwise.
    """

    def __init__(self, scene: Scene, observers: list | None = None):
        self.scene = scene = Scene.model_validate(scene)  # a dict or a Scene checked (model_copy checks nothing); SceneError
        spec = scene.grid
        # the points' size, for a basis whose weights depend on it (every body then shares it)
        self.grid = Grid(spec.basis, spec.lower, spec.upper, spec.spacing, scene.bodies[0].points_per_cell)
        self.materials = [make_material(body.material) for body in scene.bodies]
        self.particles = seed_bodies(scene.bodies, self.materials, spec.spacing)
        self.body_slices = self.particles.body_slices()
        warn_of_overlaps(scene.bodies)
        # "empty" and "negative" grid masses are measured against a full cell of each node's own material
        self.cell_masses = CellMasses.of([m.density for m in self.materials], spec.spacing, self.body_slices)
        self.every = scene.output.every if scene.output else 0
        self.energy = EnergyBookkeeping() if scene.output and scene.output.energy else None
        acting = scene.declared_effects()  # in step order within each stage
        # supports must be known to a coupled mass, and to the critical time step
        held = [fixed for fixed in (effect.fixed(self.grid) for effect in acting) if fixed is not None]
        self.fixed = np.logical_or.reduce(held) if held else None
        # walls of mirrored ghost nodes: the mass solves on v = T w (None: no such wall, no cost)
        mirrors = [mirror for mirror in (effect.mirror(self.grid) for effect in acting) if mirror is not None]
        self.constraint = NodeConstraint.combine(self.grid.n_nodes, self.fixed, mirrors) if mirrors else None
        self.scheme = SCHEMES[scene.solver.scheme]
        warn_of_thin_bodies(scene.bodies, spec.spacing, self.grid.definition.support_width, spec.basis)  # before
        self.dt = self._time_step()  # a step that a body of one point leaves unbounded is refused
        self.mass: MassModel = self.mass_model(time_step=self.dt)
        self.negative_mass = NegativeMassMonitor(scene.solver.negative_mass, applies=self.mass.divides_by_row_sums)
        # within time.max_steps and output.max_bytes; at least one step: a step far longer
        # than the run would otherwise round to none
        self.n_steps = max(1, run_steps(scene, self.dt))
        warn_of_a_long_step(self.dt, scene.time, self.end_time)
        watching = [*([self.energy] if self.energy else []), *checked_observers(observers)]
        self.effects: dict[Stage, list[tuple[str, Callable]]] = {stage: [] for stage in Stage}
        for effect in [*acting, *watching]:  # observers last: they may read dt and n_steps
            self.effects[effect.stage].append((effect.name, bound(effect, self)))
        # the observers that keep a record of their own (the exact reference): in the summary,
        # in a checkpoint, and their columns in the energy record (they run before it)
        self.recorders = [action for stage in Stage for _, action in self.effects[stage] if isinstance(action, Recorder)]
        if self.energy is not None:
            for recorder in self.recorders:
                self.energy.extra.update(recorder.columns())
        self.transfer = engine_for(self)
        self.context = self.transfer.context(self, self.dt)
        self.step_index = 0
        self.time = 0.0
        self.wall_time = 0.0
        self._run_started = None
        self._run_step = False  # set by run() for its own advance()
        #: "completed" or "stopped" once :meth:`run` has returned or raised (a second call is refused)
        self.outcome: str | None = None
        self.energy_guard = EnergyGuard.of(
            self, acting, initial=kinetic_energy(self.particles.mass, self.particles.v) + self.strain_energy())

    # -- set-up -----------------------------------------------------------------

    @property
    def fields_per_body(self) -> bool:
        """One grid velocity field per body: frictional contact."""
        contact = self.scene.contact
        return contact is not None and contact.fields_per_body

    def mass_model(self, time_step: float | None = None) -> MassModel:
        """A new mass model of the scene's kind, complete with the supports' fixed degrees of
        freedom (the run's own, with its ``time_step``; the critical step estimates on one
        of its own, with None)."""
        return build_mass_model(self.scene.solver, self.grid, self.cell_masses, per_body=self.fields_per_body,
                                fixed=self.fixed, time_step=time_step, constraint=self.constraint)

    def _time_step(self) -> float:
        time = self.scene.time
        if time.dt != "auto":
            return float(time.dt)
        if not self.critical_dt > 0:
            raise ValueError(
                f"dt = 'auto' is impossible: {self.scene.grid.basis} with {self.scene.solver.mass} mass has no stable time step"
            )
        if self.critical_dt == math.inf:  # no stiffness on a free degree of freedom: nothing limits the step
            raise ValueError(
                "time.dt: dt = 'auto' has nothing to limit the step (an infinite critical step: every node fixed, a body "
                "of one point, or a stiffness that vanishes in floating point, e.g. a spacing or a body size far from metres); "
                "give dt in seconds")
        return time.safety * self.critical_dt

    @property
    def end_time(self) -> float:
        """The time the run ends at (s), ``n_steps * dt``: ``time.end`` rounded up to whole steps
        (a last step is never shortened, so a run repeats bit for bit with any end on its way)."""
        return self.n_steps * self.dt

    def strain_energy(self) -> float:
        """Stored energy of all bodies (J per unit thickness), each by its own law."""
        return sum(material.strain_energy(self.particles, members) for material, members in zip(self.materials, self.body_slices))

    @functools.cached_property
    def critical_dt(self) -> float:
        """Largest stable time step (s) at set-up, from ``M^-1 K``; 0 if none is
        (see :mod:`femgrid_mpm.stability`).  Computed when first asked for."""
        return critical_time_step(self)

    def body_index(self, name: str) -> int:
        return [body.name for body in self.scene.bodies].index(name)

    @property
    def active_effects(self) -> list[str]:
        """Names of the effects this scene runs, in stage order."""
        return [name for stage in Stage for name, _ in self.effects[stage]]

    # -- the step ------------------------------------------------------------------

    def project(self) -> StepContext:
        """Paper steps 1-3: shape functions at the points, grid mass, grid velocity (Eq. 17)."""
        ctx, p = self.context, self.particles
        ctx.step, ctx.time = self.step_index, self.time
        # Work in the frame of one point (any frame is the same in exact
        # arithmetic): a uniform motion then has zero relative velocity and
        # moves exactly, with no round-off for small or negative masses to amplify.
        ctx.frame_velocity = self.transfer.frame_velocity(p)
        try:  # P2G: N at the points, the grid mass, N.T @ (m_p (v_p - v_ref))
            relative_momentum = self.transfer.to_grid(ctx, self.mass)
        except ValueError as error:
            raise self._left_grid(error) from None
        for lumped, smallest, scale in self.mass.row_sums():  # one per field
            self.negative_mass.check(lumped, scale, ctx.step, ctx.time, self.grid.nodes, smallest)
        self.negative_mass.record_below_threshold(self.mass.nodes_below_threshold, ctx.step)
        try:  # Eq. 17: v = M^-1 p_rel + v_ref, and the momentum p_rel + m v_ref
            ctx.momentum, ctx.velocity = self.mass.grid_velocity(relative_momentum, ctx.frame_velocity)
        except SingularMassError as error:
            raise self._singular(error) from None
        self._constrain(ctx.velocity)
        return ctx

    def advance(self, record: bool = False) -> None:
        """One time step: the scheme's sub-steps (:mod:`femgrid_mpm.schemes`), each the paper's
        section 3.2 steps 1-11; the paper's scheme is one, the central difference started from v(0)."""
        if self.outcome in ("completed", "stopped") or (self.outcome == "begun" and not self._run_step):
            # its result holds these arrays: they stay its end; run() under way takes its own steps
            raise ValueError(f"this simulation's run has {self.outcome} (step {self.step_index}, t = {self.time:.6g} s): "
                             "it takes no steps but run()'s; run a new Simulation of the scene for more")
        self._run_step = False
        ctx, dt, scheme = self.project(), self.dt, self.scheme
        if record:
            self._run(Stage.OBSERVE)
        self._guard_energy(record)
        if scheme.start_kick and self.step_index == 0:
            self._start_kick(ctx, scheme.start_kick * dt)
            ctx = self.project()
        last_step = self.step_index == self.n_steps - 1
        for index, (drift, kick, at) in enumerate(zip(scheme.drifts, scheme.kicks, scheme.force_times)):
            if index:  # 1-3 again at the moved points
                ctx = self.project()
            if last_step and index == scheme.passes - 1:
                kick -= scheme.start_kick  # the last velocity: that of the end time, not beyond it
            checksum = self._substep(ctx, drift * dt, kick / drift, self.time + at * dt)
        # 11
        self.step_index += 1
        self.time = self.step_index * dt
        if not np.isfinite(checksum):
            raise self._stop(f"the state is no longer finite (NaN or Inf){first_not_finite(self.particles, self.scene.bodies)}",
                             "not_finite")

    def _substep(self, ctx: StepContext, dt: float, kick_ratio: float, force_time: float) -> float:
        """Steps 4-10 over ``dt`` (negative in a composition's middle), the velocity changed by
        ``kick_ratio * dt * N a``; returns the finiteness checksum."""
        # 4-7: strain increment from the grid velocity (Eq. 18), stress (Eq. 6), internal
        # force -(dNdx.T @ V sigma_x + dNdy.T @ V sigma_y) with the volumes of time t (Eq. 11)
        ctx.force = self.transfer.internal_force(ctx, dt, self.materials, self.body_slices)
        ctx.force_time = force_time
        ctx.external = {}  # then the declared forces
        self._run(Stage.EXTERNAL_FORCE)
        self._run(Stage.ADJUST_FORCE)
        ctx.acceleration = self._solve(ctx.force, "acceleration")
        self._constrain(ctx.acceleration)
        self._book_work(ctx, kick_ratio * dt)
        if kick_ratio != 1.0:
            ctx.acceleration *= kick_ratio
        # 8-10 (G2P): velocity v += dt N @ a (Eq. 19) with the new forces, position
        # x += dt N @ v (Eq. 20) with the grid velocity of time t, density (Eq. 21)
        return self.transfer.to_points(ctx, dt)

    def _start_kick(self, ctx: StepContext, dt: float) -> None:
        """A scheme's start, ``v += dt N @ a(0)``: the stress and forces of time t."""
        ctx.force = self.transfer.internal_force(ctx, 0.0, self.materials, self.body_slices)
        ctx.force_time = self.time
        ctx.external = {}
        self._run(Stage.EXTERNAL_FORCE)
        self._run(Stage.ADJUST_FORCE)
        acceleration = self._solve(ctx.force, "acceleration")
        self._constrain(acceleration)
        self.transfer.kick(ctx, dt, acceleration)

    def _guard_energy(self, recorded: bool) -> None:
        """The runaway-energy guard (:class:`EnergyGuard`) on what is known cheaply:
        the total of this step's energy record, else the points' kinetic energy."""
        guard, ctx = self.energy_guard, self.context
        if recorded and self.energy is not None and self.energy.rows:
            guard.check(self.energy.rows[-1]["total"], "the total energy", ctx.work, self.step_index, self.time,
                        self._fastest_point)
        else:
            kinetic = points_kinetic_energy(self.particles.mass, self.particles.v)
            guard.check(kinetic, "the kinetic energy", ctx.work, self.step_index, self.time, self._fastest_point)

    def _fastest_point(self) -> str:
        """Where a runaway stands out (for the stop's message)."""
        return fastest_point(self.particles, self.scene.bodies)

    def _solve(self, rhs: np.ndarray, kind: str) -> np.ndarray:
        try:
            return self.mass.solve(rhs, kind)
        except SingularMassError as error:
            raise self._singular(error) from None

    def _singular(self, error: SingularMassError) -> SimulationStopped:
        """The stop for a consistent mass that cannot be solved, with the node where it is weakest."""
        where = ""
        if error.node is not None:
            x, y = self.grid.nodes[error.node]
            where = f"; weakest at node {error.node} at ({x:.6g}, {y:.6g})"
        return self._stop(f"{error}{where}", "singular_mass")

    def _constrain(self, field_: np.ndarray) -> None:
        self.context.target = field_
        self._run(Stage.CONSTRAIN)
        self.context.target = None

    def _run(self, stage: Stage) -> None:
        try:
            for _, action in self.effects[stage]:
                action(self.context)
        except ForceNotFinite as error:  # a declared force with no value: its key, not "the state"
            raise self._stop(error.message(self.scene, self.particles), "not_finite") from None

    def _book_work(self, ctx: StepContext, dt: float) -> None:
        """Work of each declared force over a kick of ``dt``, at the kick's mid grid velocity."""
        if not ctx.external:
            return
        with np.errstate(over="ignore", invalid="ignore"):  # a work beyond 1e308: the state guard stops the run
            mid_velocity = ctx.velocity + 0.5 * dt * ctx.acceleration
            for name, grid_force in ctx.external.items():
                ctx.work[name] = ctx.work.get(name, 0.0) + dt * float(np.sum(grid_force * mid_velocity))

    def _left_grid(self, error: ValueError) -> SimulationStopped:
        return self._stop(f"a particle left the grid: {error}", "particle_left_grid")

    def _stop(self, message: str, reason: str) -> SimulationStopped:
        return SimulationStopped(f"step {self.step_index} (t = {self.time:.6g} s): {message}", self.step_index, self.time, reason)

    # -- running ---------------------------------------------------------------

    def run(
        self,
        progress: Callable[[int, float], None] | None = None,
        checkpoint: Callable[["Simulation"], None] | None = None,
        checkpoint_every: int = 0,
    ) -> RunResult:
        """Step to the end time, recording every ``output.every`` steps.

        Parameters
        ----------
        progress : callable, optional
            Called with ``(step, time)`` after every step.
        checkpoint : callable, optional
            Called with the simulation between steps, every ``checkpoint_every`` steps, when the
            run goes on (not after its last step): the state is then complete (:meth:`state`), and
            a run continued from it (:meth:`restore`, :meth:`run`) repeats this one bit for bit.

        The guards (the energy guard, the finiteness check) see every step's state and the final
        one; a completed run warns once (:class:`~femgrid_mpm.diagnostics.EnergyDriftWarning`) when
        its ``energy_drift`` (:func:`femgrid_mpm.observers.energy_drift`) exceeds
        :data:`~femgrid_mpm.diagnostics.ENERGY_DRIFT_LIMIT`.

        Raises
        ------
        SimulationStopped
            When a guard stops the run (a point off the grid after the last step too); its
            ``result`` holds the records and the state up to that step.
        ValueError
            If this simulation has run already, or runs (another thread's call): it runs once.
        """
        if self.outcome is not None:
            raise ValueError(
                f"this simulation's run has {self.outcome} (step {self.step_index}, t = {self.time:.6g} s): a second "
                "run() would record its final state twice; to go further, run a new Simulation of the scene with a "
                "later end (scene.with_overrides(**{'time.end': ...}))")
        self.outcome = "begun"  # a second run() meanwhile (another thread, a callback) is refused
        start = clock.perf_counter()
        self._run_started = start  # for the wall time in a checkpoint
        ending = "reached t = {time:.6g} s"
        try:
            while self.step_index < self.n_steps:
                self._run_step = True
                self.advance(record=bool(self.every) and self.step_index % self.every == 0)
                if progress is not None:
                    progress(self.step_index, self.time)
                if at_rest(self.scene.time, self.time, self.mass, self.context.velocity):
                    ending = "at rest at t = {time:.6g} s (no point faster than time.rest_speed)"
                    break
                if checkpoint is not None and checkpoint_every and self.step_index % checkpoint_every == 0 \
                        and self.step_index < self.n_steps:
                    checkpoint(self)
            if self.every or self.recorders:  # the last record: the state at the end
                self.project()
                self._run(Stage.OBSERVE)
            else:  # a point the last step took off the grid stops the run, as one a step earlier does
                try:
                    self.grid.locate(self.particles.x)
                except ValueError as error:
                    raise self._left_grid(error) from None
            # the guards see the state the run ends with, as they saw every step's start
            self._guard_energy(recorded=bool(self.every))
        except SimulationStopped as stop:
            self.wall_time += clock.perf_counter() - start
            self.outcome = "stopped"
            stop.result = self.result("stopped", str(stop))
            raise
        finally:
            self._run_started = None
            if self.outcome == "begun":  # interrupted (Ctrl-C, an error of a callback): run() may go on
                self.outcome = None
        self.wall_time += clock.perf_counter() - start
        self.outcome = "completed"
        result = self.result("completed", ending.format(time=self.time))
        warn_of_energy_drift(result.summary["energy_drift"])
        return result

    # -- state, for checkpoints -------------------------------------------------

    def __reduce_ex__(self, protocol):
        raise TypeError("a Simulation (its engine's kernels and buffers, its mass model's factors) is not "
                        "copied or pickled: take its state() and restore() it into a new Simulation of the scene")

    def state(self, copy: bool = True) -> tuple[dict, dict]:
        """What carries from one step to the next, ``(arrays, values)`` (:func:`~femgrid_mpm.state.simulation_state`);
        ``copy=False``: the points' arrays themselves, which the next step changes (to be saved at once)."""
        return simulation_state(self, clock.perf_counter(), copy)

    def restore(self, arrays: dict, values: dict) -> None:
        """Take back :meth:`state` into a simulation built from the same scene; ValueError, this one
        unchanged, for a state that does not fit (:func:`femgrid_mpm.state.restore_state`)."""
        restore_state(self, arrays, values)

    def result(self, status: str, message: str) -> RunResult:
        return run_result(self, status, message)
