"""Scenes and a command-line runner shared by the tests (plain functions, importable
from module-level helpers as well as from tests; ``tests/conftest.py`` offers them as
fixtures)."""

import sys
import warnings
from pathlib import Path

from femgrid_mpm import cli
from femgrid_mpm.scene import Scene, bundled_scene

#: the block's material: soft (E = 1e4 Pa) so that a few steps deform it measurably
BLOCK_MATERIAL = {"E": 1e4, "nu": 0.3, "density": 1e3}


def block_scene(basis="q1", mass="lumped", velocity=(1.0, 0.25), end=1.0, dt=0.01, *, policy="warn",
                fallback="blend", upper=(1.75, 1.5), points_per_cell=3, material=None, engine=None, every=10,
                **extra) -> Scene:
    """A block at [0.75, upper[0]] x [0.5, upper[1]] (1 x 1 by default: its edges inside
    q2 elements) in a 4 x 3 grid of spacing 0.5, 3 x 3 points per cell, no loads.

    ``policy`` is ``solver.negative_mass``, ``fallback`` ``solver.consistent_fallback``
    (``None``: the scene's default), ``engine`` ``solver.engine`` (``None``: the default),
    ``every`` ``output.every`` (``None``: no ``[output]``).  Any other keyword replaces
    that top-level table (``loads=[...]``, ``supports=[...]``, ``bodies=[...]``,
    ``solver={...}``).
    """
    solver = {"mass": mass, "negative_mass": policy}
    if fallback is not None:
        solver["consistent_fallback"] = fallback
    if engine is not None:
        solver["engine"] = engine
    data = {
        "grid": {"basis": basis, "lower": [0, 0], "upper": [4, 3], "spacing": 0.5},
        "time": {"dt": dt, "end": end},
        "solver": solver,
        "bodies": [
            {
                "name": "block",
                "lower": [0.75, 0.5],
                "upper": list(upper),
                "points_per_cell": points_per_cell,
                "velocity": list(velocity),
                "material": material or BLOCK_MATERIAL,
            }
        ],
    }
    if every is not None:
        data["output"] = {"every": every}
    data.update(extra)
    return Scene.model_validate(data)


def bundled_variant(name, basis, mass, policy="warn", **overrides) -> Scene:
    """The bundled scene ``name`` with another basis, mass and negative-mass policy, and
    any dotted ``overrides`` (``**{"time.end": 0.1}``)."""
    settings = {"grid.basis": basis, "solver.mass": mass, "solver.negative_mass": policy, **overrides}
    return bundled_scene(name).with_overrides(**settings)


def run_cli(argv, capsys):
    """``femgrid-mpm ARGV`` in process: ``(exit code, stdout, stderr)``."""
    code = cli.main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def benchmark_block(basis: str, mass: str, n: int, **solver) -> Scene:
    """The benchmarks' block (``benchmarks/step.py``) of about ``n`` points; ``solver``: further
    ``[solver]`` keys."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from step import block_scene  # noqa: E402

    return block_scene(basis, mass, n, **solver)


def advanced_benchmark_block(basis, linear_solver="auto", steps=6, n=100):
    """The benchmarks' block (``benchmarks/step.py``) of about ``n`` points with consistent mass
    and this ``linear_solver``, advanced ``steps`` steps (its warnings silenced)."""
    from femgrid_mpm.solver import Simulation

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        simulation = Simulation(benchmark_block(basis, "consistent", n).with_overrides(
            **{"solver.linear_solver": linear_solver}))
        for _ in range(steps):
            simulation.advance()
    return simulation
