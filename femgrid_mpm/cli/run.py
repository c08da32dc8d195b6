"""``femgrid-mpm run`` and ``femgrid-mpm resume``: a simulation into its output directory.

The exit codes are those of :data:`femgrid_mpm.cli.parser.EXIT_CODES`: a stop,
an interrupt or a failed write each end the run with every output written so
far kept valid.
"""

from __future__ import annotations

import contextlib
import sys
from pathlib import Path

from .parser import (EXIT_DONE, EXIT_INTERRUPTED, EXIT_STOPPED, EXIT_WRITE_FAILED, BadInput, output_directory,
                     say)
from .progress import progress_bar
from .scene_input import build, load, warn_time_step


def run(args) -> int:
    """Run a scene into ``--out``; see :data:`~femgrid_mpm.cli.parser.EXIT_CODES` for the exit codes."""
    from ..output import RunOutputs

    scene, overrides = load(args)
    out = output_directory(args.out)
    outputs = RunOutputs(out, scene, source=args.scene, overrides=overrides, checkpoint_every=args.checkpoint_every)
    simulation = build(scene, args.scene, outputs.observers)
    try:
        source_bytes = Path(args.scene).read_bytes()
    except OSError as error:
        raise BadInput(f"{args.scene}: cannot be read: {error.strerror}") from None
    warn_time_step(simulation)
    try:
        outputs.start(simulation, source_bytes)
    except OSError as error:
        raise BadInput(f"--out {out}: cannot write there: {error.strerror or error}") from None
    return execute(simulation, outputs, progress=not args.no_progress)


def resume(args) -> int:
    """Continue the run in ``DIR`` from ``DIR/checkpoint.npz`` with the scene ``DIR/scene.toml``."""
    from ..checkpoint import CHECKPOINT_FILE, CheckpointError, read_checkpoint, scene_digest
    from ..output import SCENE_FILE, RunOutputs
    from ..scene import SceneError, load_scene

    directory = Path(args.directory)
    if not directory.is_dir():
        raise BadInput(f"{directory}: no such directory")
    try:
        arrays, values = read_checkpoint(directory / CHECKPOINT_FILE)
    except CheckpointError as error:
        raise BadInput(str(error)) from None
    scene_path = directory / SCENE_FILE
    try:
        scene = load_scene(scene_path)
        digest = scene_digest(scene_path)
    except SceneError as error:
        raise BadInput(str(error)) from None
    except OSError as error:
        raise BadInput(f"{scene_path}: cannot be read: {error.strerror or error}") from None
    if digest != values.get("scene_sha256"):
        raise BadInput(f"{scene_path}: is not the scene of {directory / CHECKPOINT_FILE} (changed since it was written)")
    status = run_status(directory)
    if status is not None and status.get("status") in ("completed", "stopped"):
        # it would end the same way (same scene, same state), after cutting the finished outputs
        # back to the checkpoint: an interrupt on the way would leave less than there is now
        raise BadInput(f"{directory}: the run {status['status']} at step {status.get('steps', '?')}; nothing to "
                       f"resume (to run it again: femgrid-mpm run {scene_path} --out DIR)")
    try:
        outputs = RunOutputs.resumed(directory, scene, values["outputs"])
    except (KeyError, TypeError, ValueError) as error:
        raise BadInput(f"{directory / CHECKPOINT_FILE}: not a readable checkpoint (outputs: {error!r})") from None
    simulation = build(scene, scene_path, outputs.observers)
    # before the state is put back, as the interrupted run did before its first step:
    # the critical step is estimated at the start (it is in the summary)
    warn_time_step(simulation)
    try:
        simulation.restore(arrays, values["simulation"])
    except (KeyError, TypeError, ValueError) as error:
        raise BadInput(f"{directory / CHECKPOINT_FILE}: does not fit {scene_path} ({type(error).__name__}: {error})") from None
    try:
        outputs.resume(simulation)
    except OSError as error:
        raise BadInput(f"{directory}: cannot write there: {error.strerror or error}") from None
    return execute(simulation, outputs, progress=not args.no_progress)


def run_status(directory: Path) -> dict | None:
    """The run's ``summary.json``, or None if there is none that reads."""
    import json

    from ..output import SUMMARY_FILE

    try:
        summary = json.loads((directory / SUMMARY_FILE).read_text())
    except (OSError, ValueError):
        return None
    return summary if isinstance(summary, dict) else None


def execute(simulation, outputs, progress: bool) -> int:
    """Run a built simulation into its outputs (started or resumed), writing
    checkpoints if asked; the exit code (a progress bar on stderr if ``progress``
    and stderr is a terminal)."""
    from ..checkpoint import CHECKPOINT_FILE, scene_digest, write_checkpoint
    from ..diagnostics import SimulationStopped
    from ..output import SCENE_FILE

    out = outputs.directory
    checkpoint = None
    if outputs.checkpoint_every:
        digest = scene_digest(out / SCENE_FILE)

        def checkpoint(simulation):
            arrays, values = simulation.state()
            write_checkpoint(out / CHECKPOINT_FILE, arrays,
                             {"scene_sha256": digest, "simulation": values, "outputs": outputs.state()})

    bar, update = progress_bar(simulation, enabled=progress and sys.stderr.isatty())
    try:
        try:
            result = simulation.run(progress=update, checkpoint=checkpoint, checkpoint_every=outputs.checkpoint_every)
        finally:
            if bar is not None:
                bar.close()
        with uninterrupted():
            outputs.finish(result)
    except SimulationStopped as stop:
        try:
            with uninterrupted():
                outputs.finish(stop.result, stop)
        except OSError as error:
            return write_failed(out, error, f"after {stop}")
        say("stopped", f"{stop}; the outputs so far are in {out}")
        return EXIT_STOPPED
    except KeyboardInterrupt:
        where = f"at step {simulation.step_index} (t = {simulation.time:.6g} s)"
        try:
            with uninterrupted():  # a second Ctrl-C must not leave the summary saying "running"
                outputs.finish(simulation.result("interrupted", f"interrupted {where}"))
        except OSError as error:
            return write_failed(out, error, f"after an interrupt {where}")
        say("interrupted", f"{where}; the outputs so far are in {out}")
        return EXIT_INTERRUPTED
    except OSError as error:
        return write_failed(out, error)
    print(f"{result.message}: {simulation.step_index} steps in {simulation.wall_time:.3g} s; outputs in {out}")
    return EXIT_DONE


@contextlib.contextmanager
def uninterrupted():
    """Ctrl-C ignored while the last files are written (in the main thread; elsewhere as is)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def write_failed(out: Path, error: OSError, when: str = "") -> int:
    """The one line of a failed write, and its exit code."""
    say("error", f"cannot write the outputs in {out}{' ' + when if when else ''}: {error}")
    return EXIT_WRITE_FAILED
