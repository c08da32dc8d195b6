"""Hashes of what runs produce, to compare the code before and after a change that must keep results.

Run: ``python benchmarks/fingerprint.py > after.json`` (about 3 minutes), then
``python benchmarks/fingerprint.py --compare before.json after.json``.

* ``paper/CASE/BASIS``: the paper's three cases for q1, q2, serendipity and
  bspline3 (``negative_mass = "warn"`` so that every run goes to its end), run by
  the command line (``femgrid-mpm run``): the arrays of ``final.npz``, the bytes of
  ``energy.csv`` and the keys of ``summary.json``.
* ``block/BASIS/MASS/ENGINE``: 10 steps of a square block (the benchmark's, about
  400 points) for every basis, mass kind and engine; lumped and HRZ also with two
  threads, consistent also with CG and with the direct solver: every array of the
  points and the energy records.
* ``extra/...``: frictional contact, damping, gravity, the mass threshold, a point
  load, a checkpoint resumed half-way (it must equal the uninterrupted run).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

BASES = ("q1", "q2", "serendipity", "bspline3", "bspline3_open", "gimp", "bspline2", "bspline2_open")
PAPER_BASES = ("q1", "q2", "serendipity", "bspline3")
MASSES = ("lumped", "hrz", "consistent")
PAPER_CASES = ("vibrating_bar", "cantilever", "box_impact")


def _digest(*parts) -> str:
    hasher = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            hasher.update(str((part.dtype.str, part.shape)).encode())
            hasher.update(np.ascontiguousarray(part).tobytes())
        elif isinstance(part, bytes):
            hasher.update(part)
        else:
            hasher.update(repr(part).encode())
    return hasher.hexdigest()[:16]


def paper_runs() -> dict:
    hashes = {}
    with tempfile.TemporaryDirectory() as top:
        for case in PAPER_CASES:
            for basis in PAPER_BASES:
                out = Path(top) / case / basis
                scene = Path(__file__).resolve().parent.parent / "femgrid_mpm" / "scenes" / f"{case}.toml"
                command = [sys.executable, "-m", "femgrid_mpm.cli", "run", str(scene), "--out", str(out),
                           "--no-progress", "--set", f"grid.basis={basis}", "--set", "solver.negative_mass=warn"]
                done = subprocess.run(command, capture_output=True, text=True)
                if done.returncode not in (0, 3):  # 3: stopped by a guard, a result too
                    raise SystemExit(f"{case} {basis}: exit {done.returncode}: {done.stderr.strip()}")
                with np.load(out / "final.npz") as final:
                    arrays = [final[name] for name in sorted(final.files)]
                summary = json.loads((out / "summary.json").read_text())
                hashes[f"paper/{case}/{basis}"] = {
                    "final.npz": _digest(*arrays),
                    "energy.csv": _digest((out / "energy.csv").read_bytes()),
                    "summary keys": _digest(sorted(summary)),
                    "status": summary.get("status"),
                    "steps": summary.get("steps"),
                    "exit": done.returncode,
                }
                print(f"  {case} {basis}: {hashes[f'paper/{case}/{basis}']}", file=sys.stderr, flush=True)
    return hashes


def block(basis: str, mass: str, engine: str = "numba", threads: int = 1, **solver) -> dict:
    side = 10
    wave_speed = np.sqrt(1e4 * 0.7 / (1.3 * 0.4) / 1e3)
    return {
        "grid": {"basis": basis, "lower": [0, 0], "upper": [side + 4, side + 4], "spacing": 1.0},
        "time": {"dt": 0.1 / wave_speed, "end": 1e6},
        "solver": {"mass": mass, "negative_mass": "warn", "consistent_fallback": "blend", "engine": engine,
                   "threads": threads, **solver},
        "bodies": [{
            "name": "block", "lower": [2, 2], "upper": [side + 2, side + 2], "points_per_cell": 2,
            "velocity": [f"0.01*cos(pi*(x-2)/{side})", f"0.002*sin(pi*(y-2)/{side})"],
            "material": {"E": 1e4, "nu": 0.3, "density": 1e3},
        }],
        "output": {"every": 1, "energy": True},
    }


def _state_digest(simulation) -> str:
    p = simulation.particles
    arrays = [getattr(p, name) for name in p.__dataclass_fields__]
    rows = simulation.energy.state()[1] if simulation.energy is not None else np.zeros(0)
    return _digest(*arrays, rows)


def _steps(data: dict, steps: int = 10) -> str:
    from femgrid_mpm.scene import Scene
    from femgrid_mpm.solver import Simulation

    from femgrid_mpm.diagnostics import SimulationStopped

    simulation = Simulation(Scene.model_validate(data))
    try:
        for _ in range(steps):
            simulation.advance(record=True)
    except SimulationStopped as stop:  # a stop is a result too: where and why
        return f"{_state_digest(simulation)} stopped: {stop}"
    return _state_digest(simulation)


def block_runs() -> dict:
    hashes = {}
    for basis in BASES:
        for mass in MASSES:
            for engine in ("numba", "scipy"):
                hashes[f"block/{basis}/{mass}/{engine}"] = _steps(block(basis, mass, engine))
            if mass != "consistent":
                hashes[f"block/{basis}/{mass}/threads2"] = _steps(block(basis, mass, threads=2))
            else:
                for solver in ("cg", "direct"):
                    hashes[f"block/{basis}/{mass}/{solver}"] = _steps(block(basis, mass, linear_solver=solver))
        print(f"  block {basis} done", file=sys.stderr, flush=True)
    return hashes


def extra_runs() -> dict:
    from femgrid_mpm.scene import Scene, bundled_scene
    from femgrid_mpm.solver import Simulation

    hashes = {}
    box = bundled_scene("box_impact")
    for friction in (0.0, 0.3):
        scene = box.with_overrides(**{"contact.kind": "frictional", "contact.friction": friction, "time.end": 0.5})
        simulation = Simulation(scene)
        simulation.run()
        hashes[f"extra/frictional/{friction}"] = _state_digest(simulation)
    for basis in ("q1", "bspline3", "q2"):
        for mass in MASSES:
            data = block(basis, mass)
            data["loads"] = [{"kind": "gravity", "acceleration": [0.0, -9.81]},
                             {"kind": "point", "body": "block", "at": [12.0, 12.0], "force": [0.0, -50.0], "ramp": 0.5}]
            data["damping"] = {"kind": "mass", "coefficient": 0.5}
            data["supports"] = [{"where": "x <= 2", "fix": ["x", "y"]}]
            hashes[f"extra/loads/{basis}/{mass}"] = _steps(data, 20)
    for basis in ("q2", "serendipity"):
        data = block(basis, "lumped")
        data["solver"]["negative_mass"] = "threshold" if basis == "q2" else "warn"
        data["bodies"][0]["lower"] = [2.5, 2.5]
        hashes[f"extra/threshold/{basis}"] = _steps(data, 20)
    # a checkpoint half-way, restored into a new simulation, must give the uninterrupted run
    for basis, mass in (("bspline3", "consistent"), ("q2", "hrz"), ("q1", "lumped")):
        data = block(basis, mass, linear_solver="cg")
        whole = Simulation(Scene.model_validate(data))
        for _ in range(12):
            whole.advance(record=True)
        first = Simulation(Scene.model_validate(data))
        for _ in range(6):
            first.advance(record=True)
        arrays, values = first.state()
        arrays = {key: np.array(value) for key, value in arrays.items()}
        values = json.loads(json.dumps(values))
        second = Simulation(Scene.model_validate(data))
        second.restore(arrays, values)
        for _ in range(6):
            second.advance(record=True)
        hashes[f"extra/checkpoint/{basis}/{mass}"] = [_state_digest(whole), _state_digest(second)]
    return hashes


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"), help="compare two saved outputs")
    parser.add_argument("--only", choices=("paper", "block", "extra"), action="append", help="parts to run")
    args = parser.parse_args(argv)
    if args.compare:
        before, after = (json.loads(Path(name).read_text()) for name in args.compare)
        differ = sorted(key for key in before.keys() | after.keys() if before.get(key) != after.get(key))
        for key in differ:
            print(f"differs: {key}: {before.get(key)} -> {after.get(key)}")
        print(f"{len(before.keys() & after.keys()) - len(set(differ) & before.keys() & after.keys())} of "
              f"{len(before.keys() | after.keys())} identical")
        raise SystemExit(1 if differ else 0)
    warnings.simplefilter("ignore")
    parts = args.only or ["paper", "block", "extra"]
    hashes = {}
    for part in parts:
        hashes.update({"paper": paper_runs, "block": block_runs, "extra": extra_runs}[part]())
    print(json.dumps(hashes, indent=1, sort_keys=True))


if __name__ == "__main__":
    main()
