"""The scene of the arguments, loaded, checked and built; every problem a :class:`BadInput`."""

from __future__ import annotations

import re
import warnings

from .parser import BadInput


def overrides(args) -> dict:
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
        except RecursionError:
            raise BadInput(f"--set {key}: the value is nested too deeply (no scene key is)") from None
        overrides[key] = value
    if args.basis:
        overrides["grid.basis"] = args.basis
    if args.mass:
        overrides["solver.mass"] = args.mass
    return overrides


def load(args):
    """The scene of the arguments, validated, and its overrides; raises :class:`BadInput`."""
    from ..scene import SceneError, load_scene

    changes = overrides(args)
    try:
        return load_scene(args.scene, changes), changes
    except SceneError as error:
        raise BadInput(str(error)) from None


def build(scene, path, observers):
    """The :class:`Simulation`, with the checks that need it built; raises :class:`BadInput`.

    Building selects support nodes and seeds points; a support that selects
    no node, ``dt = "auto"`` without a stable step or an initial velocity that
    evaluates to NaN are problems of the scene file.
    """
    from ..scene.limits import check_records
    from ..solver import Simulation

    need, available = memory_need(scene), available_memory()
    if available is not None and need > available:
        raise BadInput(f"{path}: the scene needs at least {need / 1e9:.3g} GB of memory, more than the "
                       f"{available / 1e9:.3g} GB this machine has available")
    try:
        simulation = Simulation(scene, observers=observers)
    except MemoryError:
        raise BadInput(f"{path}: the scene does not fit in this machine's memory") from None
    except ValueError as error:  # including an initial velocity that is NaN or infinite (it names its key)
        raise BadInput(f"{path}: {key_of_build_error(scene, str(error))}{error}") from None
    try:  # a run goes to its end: its records must fit
        check_records(scene, simulation.n_steps, simulation.particles.n, simulation.grid.n_nodes)
    except ValueError as error:
        raise BadInput(f"{path}: {error}") from None
    return simulation


#: the least memory a run takes per point and per node (bytes): measured peaks are
#: 317-887 B per point (benchmarks/step.py); a scene needing more than the machine has
#: would be killed by the system mid-allocation, with no message
BYTES_PER_POINT, BYTES_PER_NODE = 300, 100


def memory_need(scene) -> float:
    """A lower bound of the bytes a run of ``scene`` needs (counted, nothing allocated)."""
    points = sum(scene.point_count(index) for index in range(len(scene.bodies)))
    # threads: each chunk of points sums into its own copy of 8 numbers a node
    threads = scene.solver.threads if scene.solver.threads > 1 else 0
    return BYTES_PER_POINT * points + (BYTES_PER_NODE + 64 * threads) * scene.node_count()


def available_memory() -> float | None:
    """Bytes the system can give without swapping (Linux ``MemAvailable``), and no more than
    this process may still map under its address-space limit (``ulimit -v``), or None if unknown."""
    limits = [_proc_kilobytes("/proc/meminfo", "MemAvailable:")]
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        mapped = _proc_kilobytes("/proc/self/status", "VmSize:")
        if soft != resource.RLIM_INFINITY and mapped is not None:
            limits.append(max(0.0, soft - mapped))
    except (ImportError, OSError, ValueError):
        pass
    known = [limit for limit in limits if limit is not None]
    return min(known) if known else None


def _proc_kilobytes(path: str, field: str) -> float | None:
    """A ``kB`` field of a /proc file, in bytes, or None."""
    try:
        with open(path) as lines:
            for line in lines:
                if line.startswith(field):
                    return float(line.split()[1]) * 1024.0
    except (OSError, ValueError, IndexError):
        pass
    return None


def critical_dt(simulation) -> float | None:
    """The estimated critical time step, or None (with a warning) if estimating it needs
    more memory than there is."""
    try:
        return simulation.critical_dt
    except MemoryError:
        warnings.warn("the critical time step could not be estimated: not enough memory for its eigenvalue problem",
                      RuntimeWarning)
        return None


def key_of_build_error(scene, message: str) -> str:
    """``"KEY: "`` for the errors building a simulation is known to raise, else ``""``.

    The library's messages name the value (``support where = 'x < -1'
    selects no grid node``); the command line adds the key in the file.
    """
    if re.match(r"^[a-z_]+(\.[a-z_]+|\[\d+\])*: ", message):  # it names its key already
        return ""
    if scene.time.dt == "auto" and "auto" in message:
        return "time.dt: "
    for index, support in enumerate(scene.supports):
        if repr(support.where) in message:
            return f"supports[{index}].where: "
    return ""


def warn_time_step(simulation) -> None:
    """A warning if the time step is above the estimated critical one, or if there is none."""
    dt, critical = simulation.dt, critical_dt(simulation)
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
