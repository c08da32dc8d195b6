"""Checkpoints and ``femgrid-mpm resume``: a run continued from a checkpoint is
bit for bit the run that was never interrupted; the same scene run twice
gives the same bytes.

The reference is the uninterrupted run itself: every output file is compared
byte for byte, except the wall-time fields of ``summary.json`` (and the
checkpoint file, which records the wall time so far).
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from femgrid_mpm import cli
from femgrid_mpm.checkpoint import CHECKPOINT_FILE, CheckpointError, read_checkpoint, write_checkpoint
from femgrid_mpm.observers import COLUMNS
from femgrid_mpm.scene import bundled_scene
from femgrid_mpm.solver import Simulation
from helpers import benchmark_block, run_cli

ROOT = Path(__file__).parents[1]
VIBRATING_BAR = ROOT / "scenes" / "vibrating_bar.toml"
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}


class Interrupted(Exception):
    """Stands for the kill: raised by the checkpoint callback after writing."""


def interrupted_then_resumed(scene, tmp_path, checkpoint_every, stop_after=1, configure=lambda simulation: None):
    """Run until the ``stop_after``-th checkpoint is written to a file, drop
    the simulation, build a new one from the scene, restore the file and run
    to the end."""
    path = tmp_path / CHECKPOINT_FILE
    written = []

    def checkpoint(simulation):
        arrays, values = simulation.state()
        write_checkpoint(path, arrays, {"simulation": values})
        written.append(simulation.step_index)
        if len(written) == stop_after:
            raise Interrupted

    first = Simulation(scene)
    configure(first)
    with pytest.raises(Interrupted):
        first.run(checkpoint=checkpoint, checkpoint_every=checkpoint_every)
    arrays, values = read_checkpoint(path)
    second = Simulation(scene)
    configure(second)
    second.restore(arrays, values["simulation"])
    assert second.step_index == written[-1] > 0
    return second, second.run()


def assert_same_run(result, reference):
    p, q = result.particles, reference.particles
    for name in p.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(p, name), getattr(q, name), err_msg=name)
    if reference.energy is not None:
        for name in COLUMNS:
            np.testing.assert_array_equal(result.energy[name], reference.energy[name], err_msg=name)
    summary = {k: v for k, v in result.summary.items() if k != "wall_time"}
    assert summary == {k: v for k, v in reference.summary.items() if k != "wall_time"}


def with_cg(simulation):
    """Consistent mass solved by CG (as beyond 5000 nodes), warm-started from
    the last two solutions: that history must come through the checkpoint."""
    simulation.mass.linear_solver = "cg"


CASES = {
    # the paper's bar, records every 7 steps (not a divisor of the checkpoint interval)
    "q1 lumped": (bundled_scene("vibrating_bar").with_overrides(**{"time.end": 0.9, "output.every": 7}), 100, None),
    # dt = "auto": the critical step is estimated from the scene's start, before the state is restored
    "q1 dt auto": (bundled_scene("vibrating_bar").with_overrides(**{"time.dt": "auto", "time.end": 2.0}), 5, None),
    # consistent mass by CG: its warm start carries over
    "bspline3 consistent cg": (bundled_scene("vibrating_bar").with_overrides(
        **{"grid.basis": "bspline3", "solver.mass": "consistent", "time.end": 0.6}), 50, with_cg),
    # the iterated mass (a fixed map of each step's right-hand side: nothing of it carries over), its
    # products from the points (k = 2 on cubic splines)
    "bspline3 iterated": (bundled_scene("vibrating_bar").with_overrides(
        **{"grid.basis": "bspline3", "solver.mass": "iterated", "time.end": 0.6}), 50, None),
    # the same with its products from the assembled matrix (k = 3), on supports
    "q1 iterated, assembled": (bundled_scene("cantilever").with_overrides(
        **{"grid.basis": "q1", "solver.mass": "iterated", "solver.mass_corrections": 3, "time.end": 0.6}), 50, None),
    # consistent mass, "auto" below the direct limit: the kept factors carry over
    "q1 consistent auto": (bundled_scene("vibrating_bar").with_overrides(
        **{"solver.mass": "consistent", "time.end": 0.6}), 50, None),
    # consistent mass, kept factors made again at most steps (gimp's block): the small systems go over
    # to a factorization every step between the checkpoints, and the count towards it carries over
    "gimp consistent, refactor rate": (benchmark_block("gimp", "consistent", 1000, weak_fraction=0.1).with_overrides(
        **{"time.end": 1.4, "output.every": 5}), 15, None),
    # the same with 1763 free nodes (SuperLU's kept factors): the run goes over to CG at step 20,
    # between the checkpoints; the count towards it and CG's history carry over
    "gimp consistent, refactor rate to CG": (benchmark_block("gimp", "consistent", 6400, weak_fraction=0.1).with_overrides(
        **{"time.end": 2.0, "output.every": 10}), 20, None),
    # the same at 1e3 points with dt = "auto": factored every step, then CG instead of the layouts'
    # analyses (FactoredRate; its trial from step 81), interrupted at step 90, mid-trial
    "gimp consistent, layouts to CG": (benchmark_block("gimp", "consistent", 1000).with_overrides(
        **{"time.dt": "auto", "time.end": 7.8, "output.every": 45}), 45, None),
    # HRZ, a neo-Hookean body, gravity, a ramped point load and damping: the work ledger in order
    "q2 hrz, loads": (bundled_scene("cantilever_large").with_overrides(
        **{"grid.basis": "q2", "solver.mass": "hrz", "bodies.0.material.model": "neo_hookean", "time.end": 0.6,
           "time.rest_speed": None, "time.dt": 0.005, "loads.0.ramp": 0.5}), 40, None),
    # frictional contact books its work; the box is 0.5 m above the beam, contact from step ~50
    "box frictional": (bundled_scene("box_impact").with_overrides(
        **{"contact.kind": "frictional", "contact.friction": 0.3, "time.end": 0.6}), 40, None),
    # the mass threshold under q2, negative masses from step 0 (counters)
    "q2 threshold": (bundled_scene("vibrating_bar").with_overrides(
        **{"grid.basis": "q2", "solver.negative_mass": "threshold", "bodies.0.upper": (4.75, 1.0), "time.end": 0.6}), 50, None),
}


@pytest.mark.parametrize("case", list(CASES))
def test_resumed_run_is_bit_identical(case, tmp_path):
    scene, every, configure = CASES[case]
    configure = configure or (lambda simulation: None)
    reference_simulation = Simulation(scene)
    configure(reference_simulation)
    reference = reference_simulation.run()
    resumed_simulation, resumed = interrupted_then_resumed(scene, tmp_path, every, stop_after=2, configure=configure)
    assert_same_run(resumed, reference)
    if configure is with_cg:
        assert resumed.summary["consistent_mass"]["cg_iterations"] > 0


def test_checkpoint_must_carry_the_cg_history(tmp_path):
    """The test above is sensitive: dropping CG's warm start changes the bits."""
    scene, every, configure = CASES["bspline3 consistent cg"]
    reference_simulation = Simulation(scene)
    configure(reference_simulation)
    reference = reference_simulation.run()
    resumed_simulation, resumed = interrupted_then_resumed(
        scene, tmp_path, every, configure=lambda s: (configure(s), setattr(s.mass, "restore", lambda arrays, values: None)))
    assert not np.array_equal(resumed.particles.v, reference.particles.v)


def test_quasi_static_run_resumed_comes_to_rest_at_the_same_step(tmp_path):
    """No checkpoint is taken at the step where the run comes to rest (a resumed
    run would step past it)."""
    scene = bundled_scene("cantilever_quasistatic").with_overrides(**{"output.every": 50})
    reference = Simulation(scene).run()
    assert reference.message.startswith("at rest")
    _, resumed = interrupted_then_resumed(scene, tmp_path, 200, stop_after=3)
    assert_same_run(resumed, reference)


def test_a_state_kept_in_memory_is_that_of_its_step():
    """``state()`` taken in a checkpoint callback and kept while the run goes on: it held the
    points' arrays themselves, so a restore started step 6 from step 7's points (the unstable
    bar then stopped at step 6 instead of 7).  The reference: the run never interrupted,
    bit for bit, and a run to its end, bit for bit too."""
    scene = bundled_scene("vibrating_bar").with_overrides(**{"time.end": 0.3, "output.every": 10})
    kept = {}
    reference = Simulation(scene).run(checkpoint=lambda s: kept.setdefault(s.step_index, s.state()),
                                      checkpoint_every=40)
    assert sorted(kept) == [40, 80]
    resumed = Simulation(scene)
    resumed.restore(*kept[40])
    assert_same_run(resumed.run(), reference)
    assert np.array_equal(kept[80][0]["particles.x"], Simulation(scene.with_overrides(**{"time.end": 0.24})).run().particles.x)


def test_restore_refuses_another_scene(tmp_path):
    scene = bundled_scene("vibrating_bar")
    arrays, values = Simulation(scene).state()
    other = Simulation(scene.with_overrides(**{"bodies.0.points_per_cell": 2}))
    with pytest.raises(ValueError, match="particles.x"):
        other.restore(arrays, values)


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
@pytest.mark.parametrize("change, problem", [
    ({"wall_time": "x"}, "wall_time 'x'"), ({"work": [["a", "b"]]}, "could not convert"),
    ({"energy_guard": None}, "not subscriptable"), ({"energy_initial": None}, "'NoneType'"),
    ({"negative_mass": {"first_step": "x"}}, "negative_mass.first_step: 'x' is not a count"),
    ({"time": -1.0}, "time -1.0 s: step 4 of"), ({"mass": {"iterations": "x"}}, "invalid literal"),
    ({"dt": None}, "dt None"),
    ({"energy_guard": "peak nan"}, r"energy_guard.peak nan: not a finite energy"),
    ({"energy_guard": "peak -1"}, r"energy_guard.peak -1.0: not a finite energy"),
])
def test_a_state_that_fails_part_way_is_undone(mass, change, problem):
    """restore() checked a few values and took the rest back as it went: a bad one further on
    raised KeyError, TypeError or AttributeError (a traceback of `resume`, exit 1) with the
    points and step already replaced; a negative time was taken."""
    scene = bundled_scene("vibrating_bar").with_overrides(**{"solver.mass": mass, "output.every": 1,
                                                             "output.energy": True})
    source = Simulation(scene)
    for _ in range(4):
        source.advance(record=True)
    arrays, values = source.state()
    if isinstance(change.get("energy_guard"), str):  # the guard's peak damaged, the rest kept
        change = {"energy_guard": {**values["energy_guard"], "peak": float(change["energy_guard"].split()[1])}}
    if "negative_mass" in change:
        change = {"negative_mass": {**values["negative_mass"], **change["negative_mass"]}}
    if "mass" in change:
        if mass == "lumped":
            change = {"step": 4.5}
            problem = "step 4.5"
        else:
            change = {"mass": {**values["mass"], **change["mass"]}}
    target = Simulation(scene)
    target.advance(record=True)
    before = target.state()
    with pytest.raises(ValueError, match=problem.replace("(", r"\(").replace(".", r"\.")):
        target.restore(arrays, {**values, **change})
    after = target.state()
    assert after[1] == before[1] and after[0].keys() == before[0].keys()
    assert all(np.array_equal(after[0][name], before[0][name]) for name in before[0])
    target.restore(arrays, values)  # and the good state is taken
    assert np.array_equal(target.run().particles.x, source.run().particles.x)


# -- the command line ----------------------------------------------------------------------------


def bar_argv(out, *extra):
    return ["run", str(VIBRATING_BAR), "--out", str(out), "--set", "time.end=20", "--set", "output.every=10",
            "--set", "output.particles=true", "--set", "damping={kind = \"mass\", coefficient = 0.01}", *extra]


def output_bytes(directory: Path) -> dict:
    """Every file of a run's directory (hidden temporaries and the checkpoint
    excluded), ``summary.json`` without its wall time."""
    files = {}
    for path in sorted(directory.rglob("*")):
        name = str(path.relative_to(directory))
        if path.is_dir() or path.name.startswith(".") or name == CHECKPOINT_FILE:
            continue
        if name == "summary.json":
            summary = json.loads(path.read_text())
            summary.pop("wall_time")
            files[name] = summary
        else:
            files[name] = path.read_bytes()
    return files


def test_sigkilled_run_resumes_to_the_same_bytes(tmp_path, capsys):
    """The bar for 20 s (6667 steps, damped: the work column), a checkpoint
    every 500 steps; killed with SIGKILL a little after the first checkpoint,
    then ``femgrid-mpm resume``: every file equals the uninterrupted run's."""
    full, killed = tmp_path / "full", tmp_path / "killed"
    assert cli.main(bar_argv(full, "--checkpoint-every", "500")) == cli.EXIT_DONE
    process = subprocess.Popen([sys.executable, "-m", "femgrid_mpm.cli", *bar_argv(killed, "--checkpoint-every", "500")],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=ENV)
    try:
        deadline = time.monotonic() + 120
        while not (killed / CHECKPOINT_FILE).exists():
            assert process.poll() is None, "the run ended before it could be killed"
            assert time.monotonic() < deadline, "no checkpoint in time"
            time.sleep(0.005)
        time.sleep(0.2)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait(timeout=60)
    assert process.returncode == -signal.SIGKILL
    assert json.loads((killed / "summary.json").read_text())["status"] == "running"
    assert not (killed / "final.npz").exists()
    step = read_checkpoint(killed / CHECKPOINT_FILE)[1]["simulation"]["step"]
    assert step % 500 == 0 and 0 < step < 6667
    capsys.readouterr()
    assert cli.main(["resume", str(killed)]) == cli.EXIT_DONE
    assert capsys.readouterr().out.startswith("reached t = 20.001 s: 6667 steps")
    resumed, reference = output_bytes(killed), output_bytes(full)
    assert resumed.keys() == reference.keys()
    assert len([name for name in reference if name.startswith("particles/")]) == 668
    for name in reference:
        assert resumed[name] == reference[name], name


def test_same_scene_twice_gives_the_same_bytes(tmp_path):
    """Two runs in two processes: every output file byte for byte (wall time aside)."""
    runs = []
    for name in ("first", "second"):
        out = tmp_path / name
        argv = [sys.executable, "-m", "femgrid_mpm.cli", "run", str(VIBRATING_BAR), "--out", str(out), "--basis", "q2",
                "--mass", "hrz", "--set", "time.end=2", "--set", "output.every=25", "--set", "output.particles=true"]
        assert subprocess.run(argv, capture_output=True, env=ENV, timeout=300).returncode == 0
        runs.append(output_bytes(out))
    assert runs[0].keys() == runs[1].keys() and "final.npz" in runs[0] and "particles/particles_650.vtu" in runs[0]
    for name in runs[0]:
        assert runs[0][name] == runs[1][name], name


@pytest.mark.parametrize("ending", ["completed", "stopped"])
def test_resume_of_a_finished_run_is_refused_and_keeps_its_outputs(tmp_path, capsys, ending):
    """The last checkpoint stays after the end, but resuming a completed (or stopped)
    run would only end the same way, after cutting its outputs back to the checkpoint:
    an interrupt on the way then lost the finished results.  It is refused in one line
    (exit 2) and every file keeps its bytes."""
    out = tmp_path / "out"
    # at 10 m/s the bar leaves its grid after a few dozen steps, past the first checkpoints
    extra = ["--set", "bodies.0.velocity=['10', '0']"] if ending == "stopped" else []
    code = cli.main(bar_argv(out, "--set", "time.end=1", "--checkpoint-every", "10", *extra))
    assert code == (cli.EXIT_DONE if ending == "completed" else cli.EXIT_STOPPED)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == ending and "checkpoint.npz" in summary["files"]
    before = output_bytes(out)
    capsys.readouterr()
    assert cli.main(["resume", str(out)]) == cli.EXIT_BAD_INPUT
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"femgrid-mpm: error: {out}: the run {ending} at step ") and "nothing to resume" in line
    assert output_bytes(out) == before


@pytest.mark.parametrize("damage, words", [
    ("missing directory", "no such directory"),
    ("no checkpoint", "no checkpoint here"),
    ("truncated", "not a readable checkpoint"),
    ("not a zip", "not a readable checkpoint"),
    ("other format", "not a checkpoint of this version"),
    ("scene edited", "is not the scene of"),
    ("scene missing", "no such scene file"),
    ("other scene", "does not fit"),
    # well-formed but edited by hand: refused before any file is rewritten (particles.pvd was cut first)
    ("energy rows edited", "energy.rows: shape (15, 3), the energy record has 9 columns"),  # records 0-140
    ("step edited", "step -50, this scene runs steps 0 to 167"),
    # values of the wrong type where the checks did not look: a traceback, or taken as they were
    ("energy initial edited", "does not fit"),
    ("series name edited", "series 'particles': entry (0.0, '<bad\"&name>') is not one it writes"),
    ("checkpoint_every edited", "checkpoint_every -3 is not a whole number of steps"),
])
def test_resume_refuses_bad_checkpoints_in_one_line(tmp_path, capsys, damage, words):
    out = tmp_path / "out"
    assert cli.main(bar_argv(out, "--set", "time.end=0.5", "--checkpoint-every", "50")) == cli.EXIT_DONE
    capsys.readouterr()
    checkpoint, scene_file = out / CHECKPOINT_FILE, out / "scene.toml"
    summary_file = out / "summary.json"  # as a killed run leaves it: resumable
    summary_file.write_text(json.dumps({**json.loads(summary_file.read_text()), "status": "running"}))
    if damage == "missing directory":
        out = tmp_path / "nowhere"
    elif damage == "no checkpoint":
        checkpoint.unlink()
    elif damage == "truncated":
        checkpoint.write_bytes(checkpoint.read_bytes()[:1000])
    elif damage == "not a zip":
        checkpoint.write_bytes(b"\x00" * 64)
    elif damage == "other format":
        arrays, values = read_checkpoint(checkpoint)
        write_checkpoint(checkpoint, arrays, {**values, "format": "something else 9"})
    elif damage == "scene edited":
        scene_file.write_text(scene_file.read_text().replace("end = 0.5", "end = 0.6"))
    elif damage == "scene missing":
        scene_file.unlink()
    elif damage == "other scene":  # a well-formed checkpoint whose points are another scene's
        other = Simulation(bundled_scene("vibrating_bar").with_overrides(**{"bodies.0.points_per_cell": 2}))
        arrays, values = read_checkpoint(checkpoint)
        arrays.update({name: array for name, array in other.state()[0].items() if name.startswith("particles.")})
        values.pop("format")
        write_checkpoint(checkpoint, arrays, values)
    elif damage == "energy rows edited":
        arrays, values = read_checkpoint(checkpoint)
        values.pop("format")
        write_checkpoint(checkpoint, {**arrays, "energy.rows": arrays["energy.rows"][:, :3]}, values)
    elif damage == "step edited":
        arrays, values = read_checkpoint(checkpoint)
        values.pop("format")
        write_checkpoint(checkpoint, arrays, {**values, "simulation": {**values["simulation"], "step": -50}})
    elif damage.endswith("edited") and damage.split()[0] in ("energy", "series", "checkpoint_every"):
        arrays, values = read_checkpoint(checkpoint)
        values.pop("format")
        simulation, outputs = values["simulation"], values["outputs"]
        if damage == "energy initial edited":
            simulation = {**simulation, "energy_initial": [1, 2]}
        elif damage == "series name edited":
            outputs = {**outputs, "series": {"particles": [[0.0, '<bad"&name>']]}}
        else:
            outputs = {**outputs, "checkpoint_every": -3}
        write_checkpoint(checkpoint, arrays, {**values, "simulation": simulation, "outputs": outputs})
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()} if out.exists() else {}
    code, stdout, err = run_cli(["resume", out], capsys)
    assert code == cli.EXIT_BAD_INPUT and stdout == ""
    assert "Traceback" not in err
    (line,) = err.splitlines()
    assert line.startswith("femgrid-mpm: error: ") and words in line
    after = {p.name: p.stat().st_mtime_ns for p in out.iterdir()} if out.exists() else {}
    assert after == before  # nothing written


@pytest.mark.parametrize("value", ["0", "-3", "ten", "1.5"])
def test_checkpoint_every_must_be_a_positive_count(tmp_path, capsys, value):
    code, _, err = run_cli(bar_argv(tmp_path / "out", "--checkpoint-every", value), capsys)
    assert code == cli.EXIT_BAD_INPUT and len(err.splitlines()) == 1 and "--checkpoint-every" in err
    assert not (tmp_path / "out").exists()


def test_read_checkpoint_errors_are_checkpoint_errors(tmp_path):
    with pytest.raises(CheckpointError, match="no checkpoint here"):
        read_checkpoint(tmp_path / CHECKPOINT_FILE)


def test_cubic_splines_choice_of_tensor_cg_carries_over(tmp_path, monkeypatch):
    """The choice between kept factors and CG on the tensor preconditioner is made at the run's
    first factorization and kept for the run: the fill moves with the points (the drifting bar at
    h = 0.05 from 5.58 at the start to 5.38), so a resumed run that measured it again would choose
    otherwise than the run it continues.  With the limit between the two, the run takes CG, and so
    does the resumed one, bit for bit."""
    from femgrid_mpm.mass import layout

    monkeypatch.setattr(layout, "FILL_LIMIT", 5.5)
    scene = bundled_scene("drifting_bar").with_overrides(
        **{"grid.basis": "bspline3", "grid.spacing": 0.05, "solver.mass": "consistent", "time.dt": 0.001,
           "time.end": 0.04, "output.every": 5})
    reference_simulation = Simulation(scene)
    reference = reference_simulation.run()
    assert reference_simulation.mass._choices.tensor_cg and not reference_simulation.mass._layout.direct
    resumed_simulation, resumed = interrupted_then_resumed(scene, tmp_path, 10, stop_after=2)
    assert resumed_simulation.mass._choices.tensor_cg
    assert_same_run(resumed, reference)


def test_a_checkpoint_without_the_cg_trial_measures_the_fill_from_its_kept_factors():
    """A checkpoint written before the CG trial was kept (no ``cg_trial``), taken at step 19 of the
    gimp block at 6400 points, whose kept factors go stale at step 20: the resumed run measures the
    fill from the factors it restored and reaches the uninterrupted run's verdict (CG stays, about 7
    iterations a solve against a limit of 17); with the fill left at zero, the limit was 3 and CG
    was given up for good."""
    scene = benchmark_block("gimp", "consistent", 6400, weak_fraction=0.1).with_overrides(**{"time.end": 2.0})
    reference, interrupted = Simulation(scene), Simulation(scene)
    for _ in range(19):
        interrupted.advance()
    arrays, values = interrupted.state()
    del values["mass"]["cg_trial"]
    resumed = Simulation(scene)
    resumed.restore(arrays, values)
    for simulation in (reference, resumed):
        while simulation.step_index < 45:
            simulation.advance()
    assert reference.mass._choices.trial.verdict is True
    assert resumed.mass._choices.trial.verdict is True and resumed.mass._choices.trial.fill > 1
    assert not resumed.mass._direct


def test_a_resumed_run_counts_the_analyses_of_the_uninterrupted_one():
    """q1's block at 1e3 points with ``dt = "auto"``, factored every step on one layout: resumed
    at steps 5 and 10 (each resumption makes its layout afresh), it counts no analysis the
    uninterrupted run did not (the layouts are compared by their nodes, not as objects), keeps
    its solver, and is bit for bit the uninterrupted run at step 45.  Counted per object, the two
    resumptions made 23.9 products a step of 7.6, above CG's 19.4: CG was tried at step 21."""
    scene = benchmark_block("q1", "consistent", 1000).with_overrides(**{"time.dt": "auto"})
    reference, resumed = Simulation(scene), Simulation(scene)
    for stop in (5, 10):
        while resumed.step_index < stop:
            resumed.advance()
        arrays, values = resumed.state()
        resumed = Simulation(scene)
        resumed.restore(arrays, values)
    for simulation in (reference, resumed):
        while simulation.step_index < 45:
            simulation.advance()
    assert resumed.mass._choices.factored == reference.mass._choices.factored
    assert reference.mass._choices.factored.analyses == 0 and reference.mass._choices.trial.start is None
    assert np.array_equal(resumed.particles.v, reference.particles.v)
    assert np.array_equal(resumed.particles.x, reference.particles.x)


def test_an_auto_step_another_version_estimated_in_its_last_bits_resumes():
    """With ``dt = "auto"`` a checkpoint whose step differs from this version's estimate by at
    most 1e-12 relative (an earlier version's estimate of the same step) resumes on this
    version's step; a step further off (1e-9) is refused, as is any difference with a given dt."""
    auto = bundled_scene("drifting_bar").with_overrides(output=None)
    given = auto.with_overrides(**{"time.dt": Simulation(auto).dt})
    for scene in (auto, given):
        simulation = Simulation(scene)
        simulation.advance()
        arrays, values = simulation.state()
        for factor, resumes in ((1 + 4e-16, scene is auto), (1 + 1e-9, False)):
            changed = {**values, "dt": values["dt"] * factor}
            resumed = Simulation(scene)
            if resumes:
                resumed.restore(arrays, changed)
                assert resumed.dt == simulation.dt and resumed.step_index == 1
            else:
                with pytest.raises(ValueError, match="dt"):
                    resumed.restore(arrays, changed)


@pytest.mark.parametrize("dt", ["0.01", None, [1]])
def test_a_malformed_step_in_a_checkpoint_is_refused_as_such(dt):
    """A checkpoint's dt that is not a number is refused with the dt message (a ValueError), also
    where the scene's dt is "auto" and a near step would resume."""
    scene = bundled_scene("drifting_bar").with_overrides(output=None)
    arrays, values = Simulation(scene).state()
    with pytest.raises(ValueError, match="dt"):
        Simulation(scene).restore(arrays, {**values, "dt": dt})
