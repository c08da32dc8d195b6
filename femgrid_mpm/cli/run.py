"""``femgrid-mpm run`` and ``femgrid-mpm resume``: a simulation into its output directory.

The exit codes are those of :data:`femgrid_mpm.cli.parser.EXIT_CODES`: a stop,
an interrupt or a failed write each end the run with every output written so
far kept valid.
"""

from __future__ import annotations

import errno
import signal
import sys
from pathlib import Path

from .parser import EXIT_DONE, EXIT_STOPPED, EXIT_WRITE_FAILED, BadInput, StdoutFailed, emit, output_directory, say
from .progress import progress_bar
from .scene_input import build, load, warn_time_step
from .signals import Interrupted, RunSignals


def run(args) -> int:
    """Run a scene into ``--out``; see :data:`~femgrid_mpm.cli.parser.EXIT_CODES` for the exit codes."""
    from ..output import OutputRefused, RunOutputs
    from ..reading import read_regular_file

    scene, overrides = load(args)
    out = output_directory(args.out)
    outputs = RunOutputs(out, scene, source=args.scene, overrides=overrides, checkpoint_every=args.checkpoint_every)
    try:
        outputs.check()
    except OutputRefused as error:
        raise BadInput(f"--out {out}: {error}") from None
    simulation = build(scene, args.scene, outputs.observers)
    try:
        source_bytes = read_regular_file(args.scene)
    except OSError as error:
        raise BadInput(f"{args.scene}: cannot be read: {error.strerror or error}") from None
    warn_time_step(simulation)
    return execute(simulation, outputs, progress=not args.no_progress,
                   begin=lambda: outputs.start(simulation, source_bytes), place=f"--out {out}")


def resume(args) -> int:
    """Continue the run in ``DIR`` from ``DIR/checkpoint.npz`` with the scene ``DIR/scene.toml``."""
    from ..checkpoint import CHECKPOINT_FILE, CheckpointError, read_checkpoint, scene_digest
    from ..output import SCENE_FILE, OutputRefused, RunOutputs
    from ..scene import SceneError, load_scene

    directory = Path(args.directory)
    try:
        if not directory.is_dir():
            what = "no such directory" if not directory.exists() else (
                "is a file, not a run's directory" if directory.is_file() else "is not a directory")
            raise BadInput(f"{directory}: {what} (resume takes the --out directory of a run)")
    except OSError as error:  # e.g. a name longer than the file system allows
        raise BadInput(f"{directory}: cannot be used: {error.strerror or error}") from None
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
    except (KeyError, TypeError, ValueError, ArithmeticError) as error:
        raise BadInput(f"{directory / CHECKPOINT_FILE}: not a readable checkpoint (outputs: {type(error).__name__}: {error})") from None
    try:
        outputs.check(starting=False)
    except OutputRefused as error:
        raise BadInput(str(error)) from None
    simulation = build(scene, scene_path, outputs.observers)
    # before the state is put back, as the interrupted run did before its first step:
    # the critical step is estimated at the start (it is in the summary)
    warn_time_step(simulation)
    try:
        simulation.restore(arrays, values["simulation"])
    except (KeyError, TypeError, ValueError, ArithmeticError) as error:
        raise BadInput(f"{directory / CHECKPOINT_FILE}: does not fit {scene_path} ({type(error).__name__}: {error})") from None
    return execute(simulation, outputs, progress=not args.no_progress,
                   begin=lambda: outputs.resume(simulation), place=str(directory))


def run_status(directory: Path) -> dict | None:
    """The run's ``summary.json``, or None if there is none that reads."""
    import json

    from ..output import SUMMARY_FILE
    from ..reading import read_regular_file

    try:
        summary = json.loads(read_regular_file(directory / SUMMARY_FILE))
    except (OSError, ValueError, RecursionError):
        return None
    return summary if isinstance(summary, dict) else None


#: what a directory refuses whole: bad input, not a write that failed part way
REFUSED_PLACE = (errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOTDIR, errno.EISDIR, errno.ENAMETOOLONG, errno.ENOENT)


def execute(simulation, outputs, progress: bool, begin, place: str) -> int:
    """Start the outputs (``begin``: :meth:`RunOutputs.start` or ``resume``; a failure is
    bad input at ``place``), run the simulation into them, writing checkpoints if asked,
    and finish them; the exit code (a progress bar on stderr if ``progress`` and stderr
    is a terminal).  SIGINT, SIGTERM and SIGHUP interrupt the run once
    (:class:`~femgrid_mpm.cli.signals.RunSignals`); the files are then written whole."""
    with RunSignals() as signals:
        try:
            begin()  # calm: a signal meanwhile interrupts the run at its first step
        except OSError as error:
            if error.errno in REFUSED_PLACE:  # nothing could be written there: the place is the problem
                raise BadInput(f"{place}: cannot write there: {error.strerror or error}") from None
            # a full disk, an I/O error: files may have been started (resume rewrites its .pvd
            # and summary to the checkpoint first), so not exit 2's "nothing written"
            return write_failed(outputs.directory, error, "before the first step")
        outcome = run_interruptibly(simulation, outputs, progress, signals)
        return finish(simulation, outputs, outcome)


def run_interruptibly(simulation, outputs, progress: bool, signals: RunSignals):
    """The run's outcome: its result, the :class:`SimulationStopped`, the :class:`Interrupted`
    or the OSError that ended it; the signals are calm when it returns."""
    from ..checkpoint import CHECKPOINT_FILE, scene_digest, write_checkpoint
    from ..diagnostics import SimulationStopped
    from ..output import SCENE_FILE

    out = outputs.directory
    checkpoint = None
    if outputs.checkpoint_every:
        digest = scene_digest(out / SCENE_FILE)

        def checkpoint(simulation):
            arrays, values = simulation.state(copy=False)  # written before the next step: no copy of the points
            write_checkpoint(out / CHECKPOINT_FILE, arrays,
                             {"scene_sha256": digest, "simulation": values, "outputs": outputs.state()})

    bar, update = progress_bar(simulation, enabled=progress and sys.stderr.isatty())

    def step_ended(step: int, time: float) -> None:
        if update is not None:
            update(step, time)
        signals.step_ended()

    try:
        try:
            signals.arm(at_step_ends=True)
            try:
                outcome = simulation.run(progress=step_ended, checkpoint=checkpoint,
                                         checkpoint_every=outputs.checkpoint_every)
            finally:
                if bar is not None:
                    bar.close()
        except SimulationStopped as stop:
            outcome = stop
        except (OSError, MemoryError) as error:  # a full disk; an address-space limit met mid-run
            outcome = error
        signals.calm()
    except Interrupted as interrupt:  # raised once at most: any later signal is only recorded
        outcome = interrupt
    signals.calm()
    return outcome


def finish(simulation, outputs, outcome) -> int:
    """Write the last outputs of a run that ended with ``outcome``; its line and exit code."""
    from ..diagnostics import SimulationStopped

    out = outputs.directory
    if isinstance(outcome, OSError):
        return write_failed(out, outcome)
    if isinstance(outcome, MemoryError):  # nothing more is written: that would need memory too
        say("error", f"out of memory at step {simulation.step_index} (t = {simulation.time:.6g} s); the files "
                     f"written so far are in {out}")
        return EXIT_WRITE_FAILED
    if isinstance(outcome, SimulationStopped):
        try:
            outputs.finish(outcome.result, outcome)
        except OSError as error:
            return write_failed(out, error, f"after {outcome}")
        say("stopped", f"{outcome}; the outputs so far are in {out}")
        return EXIT_STOPPED
    if isinstance(outcome, Interrupted):
        where = f"at step {simulation.step_index} (t = {simulation.time:.6g} s)"
        if outcome.mid_step:
            where += f", part way through step {simulation.step_index + 1} (a second signal)"
        by = "" if outcome.signum == signal.SIGINT else f" by {outcome.name}"
        try:
            outputs.finish(simulation.result("interrupted", f"interrupted {where}{by}"))
        except OSError as error:
            return write_failed(out, error, f"after an interrupt {where}")
        say("interrupted", f"{where}{by}; the outputs so far are in {out}")
        return outcome.exit_code
    try:
        outputs.finish(outcome)
    except OSError as error:
        return write_failed(out, error)
    try:  # the outputs are complete; a script reading the exit code learns that the line was lost
        emit(f"{outcome.message}: {simulation.step_index} steps in {simulation.wall_time:.3g} s; outputs in {out}")
    except StdoutFailed as error:
        say("error", f"the run completed (outputs in {out}) but standard output cannot be written: {error}")
        return EXIT_WRITE_FAILED
    return EXIT_DONE


def write_failed(out: Path, error: OSError, when: str = "") -> int:
    """The one line of a failed write, and its exit code."""
    say("error", f"cannot write the outputs in {out}{' ' + when if when else ''}: {error}")
    return EXIT_WRITE_FAILED
