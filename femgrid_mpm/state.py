"""The state of a simulation between steps, for checkpoints: what carries from one step to the next.

Everything else is rebuilt from the scene, or recomputed from these at every
step; a run continued from a restored state repeats the original bit for bit.
"""

from __future__ import annotations

import numpy as np


def simulation_state(simulation, now: float) -> tuple[dict, dict]:
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
    arrays = {f"particles.{name}": getattr(p, name) for name in p.__dataclass_fields__}
    values = {
        "step": simulation.step_index,
        "time": simulation.time,
        "dt": simulation.dt,
        "wall_time": simulation.wall_time + (now - simulation._run_started if simulation._run_started else 0.0),
        "work": [[name, value] for name, value in simulation.context.work.items()],
        "energy_guard": {"initial": simulation.energy_guard.initial, "floor": simulation.energy_guard.floor},
        "negative_mass": simulation.negative_mass.state(),
    }
    if simulation.energy is not None:
        values["energy_initial"], arrays["energy.rows"] = simulation.energy.state()
    arrays.update((f"records.{index}", recorder.state()) for index, recorder in enumerate(simulation.recorders))
    history = simulation.mass.state()
    if history is not None:
        mass_arrays, values["mass"] = history
        arrays.update({f"mass.{name}": array for name, array in mass_arrays.items()})
    return arrays, values


def restore_state(simulation, arrays: dict, values: dict) -> None:
    """Take back :func:`simulation_state` into a simulation built from the same scene.

    Raises
    ------
    ValueError
        If the state does not fit this simulation (another scene).
    """
    p = simulation.particles
    # everything is checked before anything is taken back: a refused state leaves this one as it was
    saved = {name: np.asarray(arrays[f"particles.{name}"]) for name in p.__dataclass_fields__}
    for name, array in saved.items():
        current = getattr(p, name)
        if array.shape != current.shape or array.dtype != current.dtype:
            raise ValueError(f"particles.{name}: shape {array.shape} {array.dtype}, this scene has {current.shape} {current.dtype}")
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
    body = saved["body"]
    if body.size and not 0 <= int(body.min()) <= int(body.max()) < len(simulation.scene.bodies):
        raise ValueError(f"particles.body: indices {int(body.min())} to {int(body.max())}, "
                         f"this scene has {len(simulation.scene.bodies)} bodies")
    if simulation.energy is not None:
        rows = np.asarray(arrays["energy.rows"])
        width = len(simulation.energy.columns)
        if rows.size and (rows.ndim != 2 or rows.shape[1] != width):
            raise ValueError(f"energy.rows: shape {rows.shape}, the energy record has {width} columns")
    records = [np.asarray(arrays[f"records.{index}"]) for index in range(len(simulation.recorders))]
    for recorder, rows in zip(simulation.recorders, records):
        recorder.restore(rows)  # checks the shape first; these go back whole or not at all
    for name, array in saved.items():
        np.copyto(getattr(p, name), array)  # in place: effects and engines may hold the arrays
    simulation.step_index, simulation.time = int(values["step"]), float(values["time"])
    simulation.wall_time = float(values["wall_time"])
    simulation.context.work.clear()
    simulation.context.work.update((str(name), float(value)) for name, value in values["work"])
    simulation.energy_guard.initial = float(values["energy_guard"]["initial"])
    simulation.energy_guard.floor = float(values["energy_guard"]["floor"])
    simulation.negative_mass.restore(values["negative_mass"])
    if simulation.energy is not None:
        simulation.energy.restore(values["energy_initial"], arrays["energy.rows"])
    if "mass" in values:
        prefix = "mass."
        simulation.mass.restore({k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)}, values["mass"])
