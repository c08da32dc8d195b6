"""The ``femgrid-mpm`` command line: ``run``, ``resume``, ``info`` and ``reproduce``.

Exit codes (:data:`EXIT_CODES`): 0 done; 2 bad input (a scene file, an
argument, an output directory that cannot be written), reported as one line
naming the file and the key, never a traceback, before anything is written;
3 the simulation stopped on a numerical event (negative mass under policy
``"error"``, a singular consistent mass, NaN, a runaway energy, a particle
leaving the grid), with every output written so far kept valid; 1 the outputs could not be
written during the run (e.g. a full disk); 130 interrupted (Ctrl-C), outputs
so far kept.  The library raises; only this module exits.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import warnings
from pathlib import Path

PROG = "femgrid-mpm"
EXIT_DONE = 0
EXIT_WRITE_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_STOPPED = 3
EXIT_INTERRUPTED = 130
EXIT_CODES = {
    EXIT_DONE: "done",
    EXIT_WRITE_FAILED: "the outputs could not be written during the run",
    EXIT_BAD_INPUT: "bad input: a scene file, an argument or an output directory",
    EXIT_STOPPED: "the simulation stopped on a numerical event; the outputs so far are valid",
    EXIT_INTERRUPTED: "interrupted; the outputs so far are valid",
}


class BadInput(Exception):
    """Input the run cannot use; the message is one line naming the file and the key."""


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (exit code 2) instead of usage + error."""

    def error(self, message):
        self.exit(EXIT_BAD_INPUT, f"{PROG}: error: {message} (see {self.prog} --help)\n")


def _parser() -> argparse.ArgumentParser:
    from .bases import BASES

    parser = _Parser(
        prog=PROG,
        description="Material point method in 2D on finite-element background grids.",
        epilog="Exit codes: " + "; ".join(f"{code} {meaning}" for code, meaning in EXIT_CODES.items()) + ".",
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="{run,resume,info,reproduce}")

    def scene_arguments(command):
        command.add_argument("scene", metavar="SCENE.toml", help="the scene file")
        command.add_argument("--basis", choices=list(BASES), help="override [grid] basis")
        command.add_argument("--mass", choices=["lumped", "consistent", "hrz"], help="override [solver] mass")
        command.add_argument(
            "--set",
            dest="settings",
            action="append",
            default=[],
            metavar="KEY=VALUE",
            help="override any key, dotted, list items by index, the value in TOML "
            "(bare words are strings): --set time.end=1 --set bodies.0.points_per_cell=4 (repeatable)",
        )

    run = commands.add_parser("run", help="run a scene and write its outputs to --out")
    scene_arguments(run)
    run.add_argument("--out", required=True, metavar="DIR", help="output directory (created if missing)")
    run.add_argument("--no-progress", action="store_true", help="no progress bar (it is shown only when stderr is a terminal)")
    run.add_argument("--checkpoint-every", type=_positive_steps, default=0, metavar="N",
                     help="write the whole state to DIR/checkpoint.npz every N steps, for femgrid-mpm resume")

    resume = commands.add_parser("resume", help="continue a run from the checkpoint in its output directory")
    resume.add_argument("directory", metavar="DIR", help="the --out directory of a run with --checkpoint-every")
    resume.add_argument("--no-progress", action="store_true", help="no progress bar (it is shown only when stderr is a terminal)")

    info = commands.add_parser("info", help="check a scene and print what a run would do")
    scene_arguments(info)

    reproduce = commands.add_parser("reproduce", help="run the paper's cases and write every figure and table")
    reproduce.add_argument("--out", default="results", metavar="DIR", help="output directory (default: results)")
    reproduce.add_argument("--case", action="append", default=[], metavar="NAME", help="only this case (repeatable; default: all)")
    return parser


def _output_directory(text: str) -> Path:
    """``--out`` as a path; raises :class:`BadInput` for an empty one (an unset
    ``$OUT`` would mean the working directory) or one that is a file."""
    if not text:  # (a name of spaces is a directory's name like any other)
        raise BadInput("--out: is empty (give a directory, e.g. --out results)")
    out = Path(text)
    if out.exists() and not out.is_dir():
        raise BadInput(f"--out {out}: exists and is not a directory")
    return out


def _positive_steps(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of steps, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1 (got {value})")
    return value


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code (see :data:`EXIT_CODES`)."""
    try:
        try:
            args = _parser().parse_args(argv)
        except SystemExit as exit_:  # --help (0) or a usage error (2, printed as one line)
            return exit_.code if isinstance(exit_.code, int) else EXIT_BAD_INPUT
    except KeyboardInterrupt:  # while the libraries load (about a second)
        _say("interrupted", "stopped by the user")
        return EXIT_INTERRUPTED
    handlers = {"run": _run, "resume": _resume, "info": _info, "reproduce": _reproduce}
    with warnings.catch_warnings():
        warnings.showwarning = _show_warning
        try:
            return handlers[args.command](args)
        except BadInput as error:
            _say("error", str(error))
            return EXIT_BAD_INPUT
        except KeyboardInterrupt:  # outside a run (a run writes its outputs first)
            _say("interrupted", "stopped by the user")
            return EXIT_INTERRUPTED


def _say(kind: str, message: str) -> None:
    """One line on stderr: ``femgrid-mpm: KIND: message``."""
    print(f"{PROG}: {kind}: {' '.join(str(message).split())}", file=sys.stderr, flush=True)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    _say("warning", str(message))


# -- building a scene from the arguments -------------------------------------------------


def _overrides(args) -> dict:
    """``--basis``, ``--mass`` and ``--set KEY=VALUE`` as dotted keys for :func:`load_scene`."""
    import tomllib

    overrides = {}
    for setting in args.settings:
        key, equals, text = setting.partition("=")
        key = key.strip()
        if not equals or not key:
            raise BadInput(f"--set {setting}: expected KEY=VALUE, e.g. --set time.end=1.5")
        try:
            value = tomllib.loads(f"value = {text.strip()}")["value"]
        except tomllib.TOMLDecodeError:
            value = text.strip()  # a bare word: a string (--set grid.basis=q2)
        overrides[key] = value
    if args.basis:
        overrides["grid.basis"] = args.basis
    if args.mass:
        overrides["solver.mass"] = args.mass
    return overrides


def _load(args):
    """The scene of the arguments, validated; raises :class:`BadInput`."""
    from .scene import SceneError, load_scene

    overrides = _overrides(args)
    try:
        return load_scene(args.scene, overrides), overrides
    except SceneError as error:
        raise BadInput(str(error)) from None


def _build(scene, path, observers):
    """The :class:`Simulation`, with the checks that need it built; raises :class:`BadInput`.

    Building selects support nodes and seeds points; a support that selects
    no node, ``dt = "auto"`` without a stable step or an initial velocity that
    evaluates to NaN are problems of the scene file.
    """
    from .solver import Simulation

    need, available = _memory_need(scene), _available_memory()
    if available is not None and need > available:
        raise BadInput(f"{path}: the scene needs at least {need / 1e9:.3g} GB of memory, more than the "
                       f"{available / 1e9:.3g} GB this machine has available")
    try:
        simulation = Simulation(scene, observers=observers)
    except MemoryError:
        raise BadInput(f"{path}: the scene does not fit in this machine's memory") from None
    except ValueError as error:  # including an initial velocity that is NaN or infinite (it names its key)
        raise BadInput(f"{path}: {_key_of_build_error(scene, str(error))}{error}") from None
    return simulation


#: the least memory a run takes per point and per node (bytes): measured peaks are
#: 317-887 B per point (benchmarks/step.py); a scene needing more than the machine has
#: would be killed by the system mid-allocation, with no message
BYTES_PER_POINT, BYTES_PER_NODE = 300, 100


def _memory_need(scene) -> float:
    """A lower bound of the bytes a run of ``scene`` needs (counted, nothing allocated)."""
    points = sum(scene.point_count(index) for index in range(len(scene.bodies)))
    return BYTES_PER_POINT * points + BYTES_PER_NODE * scene.node_count()


def _available_memory() -> float | None:
    """Bytes the system can give without swapping (Linux ``MemAvailable``), or None if unknown."""
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except (OSError, ValueError, IndexError):
        pass
    return None


def _critical_dt(simulation) -> float | None:
    """The estimated critical time step, or None (with a warning) if estimating it needs
    more memory than there is."""
    try:
        return simulation.critical_dt
    except MemoryError:
        warnings.warn("the critical time step could not be estimated: not enough memory for its eigenvalue problem",
                      RuntimeWarning)
        return None


def _key_of_build_error(scene, message: str) -> str:
    """``"KEY: "`` for the errors building a simulation is known to raise, else ``""``.

    The library's messages name the value (``support where = 'x < -1'
    selects no grid node``); the command line adds the key in the file.
    """
    if scene.time.dt == "auto" and "auto" in message:
        return "time.dt: "
    for index, support in enumerate(scene.supports):
        if repr(support.where) in message:
            return f"supports[{index}].where: "
    return ""


def _warn_time_step(simulation) -> None:
    dt, critical = simulation.dt, _critical_dt(simulation)
    if critical is None:
        return
    if critical <= 0:
        warnings.warn(
            f"{simulation.scene.grid.basis} with {simulation.scene.solver.mass} mass has no stable time step "
            "(negative lumped masses, or a singular consistent mass): expect the run to grow unboundedly",
            RuntimeWarning,
        )
    elif dt > critical:
        warnings.warn(
            f"dt = {dt:.6g} s exceeds the estimated critical time step {critical:.6g} s: the run will likely blow up",
            RuntimeWarning,
        )


# -- info --------------------------------------------------------------------------------


def _info(args) -> int:
    """Print what a run of the scene would do: counts, active effects, time steps."""
    from .output import declared_observers

    scene, overrides = _load(args)
    simulation = _build(scene, args.scene, declared_observers(scene, Path(".")))
    bodies = ", ".join(
        f"{body.name} {members.stop - members.start}" for body, members in zip(scene.bodies, simulation.body_slices)
    )
    grid = scene.grid
    lines = {
        "title": scene.title,
        "scene": args.scene + (" (with " + ", ".join(f"{k} = {v!r}" for k, v in overrides.items()) + ")" if overrides else ""),
        "basis": grid.basis,
        "mass": scene.solver.mass,
        "grid": f"[{grid.lower[0]:g}, {grid.lower[1]:g}] to [{simulation.grid.upper[0]:g}, {simulation.grid.upper[1]:g}], spacing {grid.spacing:g} m",
        "points": f"{simulation.particles.n} ({bodies})",
        "nodes": str(simulation.grid.n_nodes),
        "effects": ", ".join(["internal_force (always)", *simulation.active_effects]),
        "dt": f"{simulation.dt:.6g} s" + (" (auto)" if scene.time.dt == "auto" else ""),
        "critical_dt": "not estimated (not enough memory)" if (critical := _critical_dt(simulation)) is None
        else f"{critical:.6g} s (estimated)",
        "steps": f"{simulation.n_steps} to t = {scene.time.end:g} s",
        "records": f"every {simulation.every} steps" if simulation.every else "none (no [output])",
    }
    width = max(map(len, lines)) + 1
    for key, value in lines.items():
        print(f"{key + ':':<{width}} {value}")
    _warn_time_step(simulation)
    return EXIT_DONE


# -- run ---------------------------------------------------------------------------------


def _run(args) -> int:
    """Run a scene into ``--out``; see the module docstring for the exit codes."""
    from .output import RunOutputs

    scene, overrides = _load(args)
    out = _output_directory(args.out)
    outputs = RunOutputs(out, scene, source=args.scene, overrides=overrides, checkpoint_every=args.checkpoint_every)
    simulation = _build(scene, args.scene, outputs.observers)
    try:
        source_bytes = Path(args.scene).read_bytes()
    except OSError as error:
        raise BadInput(f"{args.scene}: cannot be read: {error.strerror}") from None
    _warn_time_step(simulation)
    try:
        outputs.start(simulation, source_bytes)
    except OSError as error:
        raise BadInput(f"--out {out}: cannot write there: {error.strerror or error}") from None
    return _execute(simulation, outputs, progress_bar=not args.no_progress)


def _resume(args) -> int:
    """Continue the run in ``DIR`` from ``DIR/checkpoint.npz`` with the scene ``DIR/scene.toml``."""
    from .checkpoint import CHECKPOINT_FILE, CheckpointError, read_checkpoint, scene_digest
    from .output import SCENE_FILE, RunOutputs
    from .scene import SceneError, load_scene

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
    status = _run_status(directory)
    if status is not None and status.get("status") in ("completed", "stopped"):
        # it would end the same way (same scene, same state), after cutting the finished outputs
        # back to the checkpoint: an interrupt on the way would leave less than there is now
        raise BadInput(f"{directory}: the run {status['status']} at step {status.get('steps', '?')}; nothing to "
                       f"resume (to run it again: femgrid-mpm run {scene_path} --out DIR)")
    try:
        outputs = RunOutputs.resumed(directory, scene, values["outputs"])
    except (KeyError, TypeError, ValueError) as error:
        raise BadInput(f"{directory / CHECKPOINT_FILE}: not a readable checkpoint (outputs: {error!r})") from None
    simulation = _build(scene, scene_path, outputs.observers)
    # before the state is put back, as the interrupted run did before its first step:
    # the critical step is estimated at the start (it is in the summary)
    _warn_time_step(simulation)
    try:
        simulation.restore(arrays, values["simulation"])
    except (KeyError, TypeError, ValueError) as error:
        raise BadInput(f"{directory / CHECKPOINT_FILE}: does not fit {scene_path} ({type(error).__name__}: {error})") from None
    try:
        outputs.resume(simulation)
    except OSError as error:
        raise BadInput(f"{directory}: cannot write there: {error.strerror or error}") from None
    return _execute(simulation, outputs, progress_bar=not args.no_progress)


def _run_status(directory: Path) -> dict | None:
    """The run's ``summary.json``, or None if there is none that reads."""
    import json

    from .output import SUMMARY_FILE

    try:
        summary = json.loads((directory / SUMMARY_FILE).read_text())
    except (OSError, ValueError):
        return None
    return summary if isinstance(summary, dict) else None


def _execute(simulation, outputs, progress_bar: bool) -> int:
    """Run a built simulation into its outputs (started or resumed), writing
    checkpoints if asked; the exit code (see the module docstring)."""
    from .checkpoint import CHECKPOINT_FILE, scene_digest, write_checkpoint
    from .diagnostics import SimulationStopped
    from .output import SCENE_FILE

    out = outputs.directory
    checkpoint = None
    if outputs.checkpoint_every:
        digest = scene_digest(out / SCENE_FILE)

        def checkpoint(simulation):
            arrays, values = simulation.state()
            write_checkpoint(out / CHECKPOINT_FILE, arrays,
                             {"scene_sha256": digest, "simulation": values, "outputs": outputs.state()})

    bar, progress = _progress_bar(simulation, enabled=progress_bar and sys.stderr.isatty())
    try:
        try:
            result = simulation.run(progress=progress, checkpoint=checkpoint, checkpoint_every=outputs.checkpoint_every)
        finally:
            if bar is not None:
                bar.close()
        with _uninterrupted():
            outputs.finish(result)
    except SimulationStopped as stop:
        try:
            with _uninterrupted():
                outputs.finish(stop.result, stop)
        except OSError as error:
            return _write_failed(out, error, f"after {stop}")
        _say("stopped", f"{stop}; the outputs so far are in {out}")
        return EXIT_STOPPED
    except KeyboardInterrupt:
        where = f"at step {simulation.step_index} (t = {simulation.time:.6g} s)"
        try:
            with _uninterrupted():  # a second Ctrl-C must not leave the summary saying "running"
                outputs.finish(simulation.result("interrupted", f"interrupted {where}"))
        except OSError as error:
            return _write_failed(out, error, f"after an interrupt {where}")
        _say("interrupted", f"{where}; the outputs so far are in {out}")
        return EXIT_INTERRUPTED
    except OSError as error:
        return _write_failed(out, error)
    print(f"{result.message}: {simulation.step_index} steps in {simulation.wall_time:.3g} s; outputs in {out}")
    return EXIT_DONE


@contextlib.contextmanager
def _uninterrupted():
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


def _write_failed(out: Path, error: OSError, when: str = "") -> int:
    _say("error", f"cannot write the outputs in {out}{' ' + when if when else ''}: {error}")
    return EXIT_WRITE_FAILED


def _progress_bar(simulation, enabled: bool):
    """A tqdm bar of steps, simulated time and ETA on stderr, and its update callback; (None, None) if not enabled."""
    if not enabled:
        return None, None
    from tqdm import tqdm

    end = simulation.n_steps * simulation.dt
    try:  # a terminal that reports no size (some ptys) would get no bar at all
        sized = min(os.get_terminal_size(sys.stderr.fileno())) > 0
    except (OSError, ValueError):
        sized = False
    bar = tqdm(
        total=simulation.n_steps,
        initial=simulation.step_index,  # a resumed run starts at its checkpoint
        unit="step",
        file=sys.stderr,
        dynamic_ncols=sized,
        ncols=None if sized else 100,
        nrows=None if sized else 24,
        bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} steps{postfix} [{elapsed}<{remaining}]",
    )
    bar.set_postfix_str(f"t = 0/{end:.4g} s", refresh=False)

    def progress(step: int, time: float) -> None:
        bar.set_postfix_str(f"t = {time:.4g}/{end:.4g} s", refresh=False)
        bar.update(step - bar.n)

    return bar, progress


# -- reproduce ---------------------------------------------------------------------------


def _reproduce(args) -> int:
    """Run the paper's cases (:data:`femgrid_mpm.reproduce.CASES`) into ``--out``."""
    from .output import probe_writable
    from .reproduce import CASES

    unknown = [name for name in args.case if name not in CASES]
    if unknown:
        raise BadInput(f"--case {unknown[0]}: no such case (cases: {', '.join(CASES)})")
    out = _output_directory(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe_writable(out)
    except OSError as error:
        raise BadInput(f"--out {out}: cannot write there: {error.strerror or error}") from None
    warnings.simplefilter("ignore")  # expected events (negative masses under "warn") are in the tables
    for name, run in CASES.items():
        if args.case and name not in args.case:
            continue
        print(f"{name} ...", file=sys.stderr, flush=True)
        run(out / name)
        table = out / name / "table.md"
        if table.exists():
            print(table.read_text())
    return EXIT_DONE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
