"""The state of a simulation between steps, for checkpoints: what carries from one step to the next.

Everything else is rebuilt from the scene, or recomputed from these at every
step; a run continued from a restored state repeats the original bit for bit.
"""

from __future__ import annotations

import copy

import numpy as np


def simulation_state(simulation, now: float, copy_arrays: bool = True) -> tuple[dict, dict]:
    """Everything that carries from one step to the next, as ``(arrays, values)``:
    numpy arrays, and plain JSON values (numbers keep every bit through
    ``repr``); ``now`` is the clock (``time.perf_counter``) for the wall time of a
    run under way.

    The points (every array of :class:`Particles`), the step, the work
    ledger (in its order: the energy sums it in that order), the energy
    records and their initial values, the records of the observers that keep
    one (:class:`~femgrid_mpm.effects.base.Recorder`), the runaway guard's bound, the
    negative-mass counters and the mass model's own history (CG's warm
    start).  Everything else is rebuilt from the scene, or recomputed
    from these at every step.
    """
    p = simulation.particles
    # copies: the step updates the points' arrays in place, and a state kept in memory (a
    # checkpoint callback's) then held later positions under this step's number; a writer that
    # saves them at once need not pay for them (``copy_arrays=False``)
    taken = np.array if copy_arrays else np.asarray
    arrays = {f"particles.{name}": taken(array) for name, array in p.arrays().items()}
    values = {
        "step": simulation.step_index,
        "time": simulation.time,
        "dt": simulation.dt,
        "wall_time": simulation.wall_time + (now - simulation._run_started if simulation._run_started else 0.0),
        "work": [[name, value] for name, value in simulation.context.work.items()],
        "energy_guard": {"initial": simulation.energy_guard.initial, "floor": simulation.energy_guard.floor,
                         "peak": simulation.energy_guard.peak},
        "negative_mass": simulation.negative_mass.state(),
    }
    if simulation.energy is not None:
        values["energy_initial"], arrays["energy.rows"] = simulation.energy.state()
    arrays.update((f"records.{index}", recorder.state()) for index, recorder in enumerate(simulation.recorders))
    history = simulation.mass.state()
    if history is not None:
        mass_arrays, values["mass"] = history
        arrays.update({f"mass.{name}": taken(array) for name, array in mass_arrays.items()})
    return arrays, values


def restore_state(simulation, arrays: dict, values: dict) -> None:
    """Take back :func:`simulation_state` into a simulation built from the same scene.

    Everything is checked before anything is taken back, and a state that fails part way (a
    value of the wrong type where the checks do not look) is undone: a refused state leaves
    this simulation as it was.

    Raises
    ------
    ValueError
        If the state does not fit this simulation (another scene), or a value is missing or
        of the wrong type; the message names it.
    """
    _check(simulation, arrays, values)
    before = simulation_state(simulation, simulation._run_started or 0.0)  # its own wall time, no more
    before = ({name: np.array(array, copy=True) for name, array in before[0].items()}, copy.deepcopy(before[1]))
    try:
        _take_back(simulation, arrays, values)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, ArithmeticError) as error:
        _take_back(simulation, *before)
        what = f"no {error.args[0]!r}" if isinstance(error, KeyError) and error.args else str(error)
        raise ValueError(f"the state does not fit this scene: {' '.join(what.split())[:200]}") from None


def _check(simulation, arrays: dict, values: dict) -> None:
    """Raise ValueError naming what of ``(arrays, values)`` does not fit ``simulation``."""
    if simulation.outcome is not None:  # its result holds the arrays a restore would overwrite
        raise ValueError(f"this simulation's run has {simulation.outcome}: restore into a new Simulation of the scene")
    p = simulation.particles
    for name, current in p.arrays().items():
        if f"particles.{name}" not in arrays:
            raise ValueError(f"particles.{name}: missing")
        array = np.asarray(arrays[f"particles.{name}"])
        if array.shape != current.shape or array.dtype != current.dtype:
            raise ValueError(f"particles.{name}: shape {array.shape} {array.dtype}, this scene has {current.shape} {current.dtype}")
    missing = [key for key in ("step", "time", "dt", "wall_time", "work", "energy_guard", "negative_mass")
               + (("energy_initial",) if simulation.energy is not None else ()) if key not in values]
    if missing:
        raise ValueError(f"{missing[0]}: missing")
    # dt = "auto": another version's estimate of the same step may differ in its last bits; the
    # run goes on with this version's step
    dt = values["dt"]
    near = isinstance(dt, float) and simulation.scene.time.dt == "auto" and abs(dt - simulation.dt) <= 1e-12 * simulation.dt
    if dt != simulation.dt and not near:
        raise ValueError(f"dt {values['dt']!r} s, this scene has {simulation.dt!r} s")
    step, time = values["step"], values["time"]
    if isinstance(step, bool) or not isinstance(step, int) or not 0 <= step <= simulation.n_steps:
        raise ValueError(f"step {step!r}, this scene runs steps 0 to {simulation.n_steps}")
    if isinstance(time, bool) or not isinstance(time, (int, float)) or not np.isfinite(time):
        raise ValueError(f"time {time!r}: not a finite number of seconds")
    if abs(time - step * dt) > 1e-9 * max(abs(step * dt), dt):  # the clock is step * dt after every step
        raise ValueError(f"time {time!r} s: step {step} of {dt!r} s ends at {step * dt!r} s")
    wall = values["wall_time"]
    if isinstance(wall, bool) or not isinstance(wall, (int, float)) or not 0 <= wall < np.inf:
        raise ValueError(f"wall_time {wall!r}: not a number of seconds, at least 0")
    body = np.asarray(arrays["particles.body"])
    if body.size and not 0 <= int(body.min()) <= int(body.max()) < len(simulation.scene.bodies):
        raise ValueError(f"particles.body: indices {int(body.min())} to {int(body.max())}, "
                         f"this scene has {len(simulation.scene.bodies)} bodies")
    if simulation.energy is not None:
        rows = np.asarray(arrays.get("energy.rows", np.zeros((0, 0))))
        width = len(simulation.energy.columns)
        if rows.size and (rows.ndim != 2 or rows.shape[1] != width):
            raise ValueError(f"energy.rows: shape {rows.shape}, the energy record has {width} columns")


def _take_back(simulation, arrays: dict, values: dict) -> None:
    p = simulation.particles
    for index, recorder in enumerate(simulation.recorders):
        recorder.restore(np.asarray(arrays[f"records.{index}"]))  # checks the shape first
    for name, current in p.arrays().items():
        np.copyto(current, np.asarray(arrays[f"particles.{name}"]))  # in place: effects and engines hold them
    simulation.step_index, simulation.time = int(values["step"]), float(values["time"])
    simulation.wall_time = float(values["wall_time"])
    work = [(str(name), float(value)) for name, value in values["work"]]
    simulation.context.work.clear()
    simulation.context.work.update(work)
    guard = values["energy_guard"]
    simulation.energy_guard.initial, simulation.energy_guard.floor = float(guard["initial"]), float(guard["floor"])
    peak = float(guard.get("peak", guard["initial"]))  # (a checkpoint from before it was kept: its initial energy)
    if not 0.0 <= peak < np.inf:
        raise ValueError(f"energy_guard.peak {peak!r}: not a finite energy of at least 0")
    simulation.energy_guard.peak = peak
    simulation.negative_mass.restore(values["negative_mass"])
    if simulation.energy is not None:
        simulation.energy.restore(values["energy_initial"], arrays["energy.rows"])
    if "mass" in values:
        prefix = "mass."
        simulation.mass.restore({k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)}, values["mass"])
