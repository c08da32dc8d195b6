"""The command line and its outputs: the contract of docs/cli.md and docs/outputs.md.

References: rigid motion is exact (a block moving at 10 m/s is at
``x0 + 10 t`` to 1e-12 m), the vibrating bar's initial kinetic energy is
``1/2 rho H int (0.01 cos(pi x / 5))^2 dx = 0.125`` J/m, energies in the
table equal the ones recomputed from ``final.npz`` to 1e-12, and a killed
run leaves only complete files.
"""

import csv
import fcntl
import json
import os
import pty
import re
import select
import signal
import struct
import subprocess
import sys
import termios
import time
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import meshio
import numpy as np
import pytest

from femgrid_mpm import cli
from femgrid_mpm.observers import COLUMNS
from femgrid_mpm.output import EnergyCsv, atomic_path, atomic_write, scene_to_toml
from femgrid_mpm.scene import Scene, load_scene
from femgrid_mpm.solver import Simulation
from helpers import run_cli

ROOT = Path(__file__).parents[1]
VIBRATING_BAR = ROOT / "scenes" / "vibrating_bar.toml"
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}


def block(**changes) -> Scene:
    """A 1 x 1 block (2 x 2 points per cell: 16 points) in a 4 x 3 q1 grid (63 nodes)."""
    data = {
        "title": "Block",
        "grid": {"basis": "q1", "lower": [0, 0], "upper": [4, 3], "spacing": 0.5},
        "time": {"dt": 0.01, "end": 0.2},
        "bodies": [
            {
                "name": "block",
                "lower": [0.75, 0.5],
                "upper": [1.75, 1.5],
                "points_per_cell": 2,
                "velocity": [1.0, 0.25],
                "material": {"E": 1e4, "nu": 0.3, "density": 1e3},
            }
        ],
        "output": {"every": 5},
    }
    for key, value in changes.items():
        if value is None:
            data.pop(key, None)
        else:
            data[key] = value
    return Scene.model_validate(data)


def write_scene(directory: Path, scene: Scene, name="scene.toml") -> Path:
    path = directory / name
    path.write_text(scene_to_toml(scene))
    return path


def read_energy(path: Path) -> tuple[list[str], np.ndarray]:
    with path.open() as handle:
        rows = list(csv.reader(handle))
    return rows[0], np.array(rows[1:], dtype=float).reshape(-1, len(rows[0]))


def read_series(directory: Path) -> list[tuple[float, meshio.Mesh]]:
    root = ElementTree.parse(directory / "particles.pvd").getroot()
    datasets = root.find("Collection").findall("DataSet")
    return [(float(d.get("timestep")), meshio.read(directory / d.get("file"))) for d in datasets]


def info_lines(stdout: str) -> dict:
    return {key.strip(): value.strip() for key, _, value in (line.partition(":") for line in stdout.splitlines())}


# -- run ------------------------------------------------------------------------------------


def test_run_vibrating_bar_with_overrides(tmp_path, capsys):
    """``femgrid-mpm run scenes/vibrating_bar.toml --out DIR --basis bspline3 --mass consistent``
    (shortened to 0.3 s: 100 steps) writes the whole contract."""
    out = tmp_path / "bar"
    argv = ["run", VIBRATING_BAR, "--out", out, "--basis", "bspline3", "--mass", "consistent", "--set", "time.end=0.3"]
    code, stdout, err = run_cli(argv, capsys)
    assert code == 0, err
    assert err == ""  # stderr is not a terminal here: no progress bar
    assert stdout.startswith("reached t = 0.3 s: 100 steps") and str(out) in stdout
    assert sorted(p.name for p in out.iterdir()) == ["energy.csv", "final.npz", "scene.toml", "source_scene.toml", "summary.json"]

    header, energy = read_energy(out / "energy.csv")
    assert header == [c for c in COLUMNS if c != "external_work"]  # no loads: no work column
    assert len(energy) == 101
    np.testing.assert_allclose(energy[:, 0], 0.003 * np.arange(101), rtol=1e-12, atol=1e-15)
    total = energy[:, header.index("total")]
    assert total[0] == pytest.approx(0.125, rel=1e-12)
    np.testing.assert_allclose(total, 0.125, rtol=0.01)  # energy conserved within 1%

    final = np.load(out / "final.npz")
    assert {"x0", "x", "v", "stress", "strain", "mass", "volume", "body"} <= set(final.files)
    assert final["x"].shape == final["v"].shape == (180, 2) and final["stress"].shape == final["strain"].shape == (180, 3)
    assert (int(final["step"]), float(final["time"])) == (100, pytest.approx(0.3, rel=1e-12))
    np.testing.assert_array_equal(final["body"], 0)
    assert final["mass"].sum() == pytest.approx(1e3 * 5.0, rel=1e-12)  # density x bar area
    assert final["volume"].sum() == pytest.approx(5.0, rel=1e-3)  # nearly incompressible motion
    # the last row is the final state's energy
    kinetic = 0.5 * np.sum(final["mass"][:, None] * final["v"] ** 2)  # Eq. 26
    assert energy[-1, header.index("kinetic")] == pytest.approx(kinetic, rel=1e-12)
    stress, strain = final["stress"], final["strain"]  # Eq. 27, tensor shear counted twice
    strain = 0.5 * np.sum(final["volume"] * (stress[:, 0] * strain[:, 0] + stress[:, 1] * strain[:, 1] + 2 * stress[:, 2] * strain[:, 2]))
    assert energy[-1, header.index("strain")] == pytest.approx(strain, rel=1e-12)

    summary = json.loads((out / "summary.json").read_text())
    expected_scene = load_scene(VIBRATING_BAR, {"grid.basis": "bspline3", "solver.mass": "consistent", "time.end": 0.3})
    simulation = Simulation(expected_scene)
    assert (summary["title"], summary["basis"], summary["mass"]) == ("Free vibration of an elastic bar", "bspline3", "consistent")
    assert (summary["status"], summary["stop"], summary["steps"], summary["records"]) == ("completed", None, 100, 101)
    assert (summary["points"], summary["nodes"]) == (180, simulation.grid.n_nodes)
    assert summary["negative_mass"]["steps_with_negative_mass"] == 0 and summary["wall_time"] > 0
    assert summary["overrides"] == {"time.end": 0.3, "grid.basis": "bspline3", "solver.mass": "consistent"}
    # the scene as run loads back equal; the source is copied byte for byte
    assert load_scene(out / "scene.toml") == expected_scene
    assert (out / "source_scene.toml").read_bytes() == VIBRATING_BAR.read_bytes()


def test_rerunning_into_a_directory_replaces_the_earlier_outputs(tmp_path, capsys):
    """Fewer records the second time: no particle file of the first run is left over."""
    scene = write_scene(tmp_path, block(output={"every": 2, "particles": True}))
    out = tmp_path / "out"
    assert run_cli(["run", scene, "--out", out], capsys)[0] == 0
    assert len(list((out / "particles").iterdir())) == 11
    assert run_cli(["run", scene, "--out", out, "--set", "output.every=10", "--set", "output.energy=false"], capsys)[0] == 0
    assert sorted(p.name for p in (out / "particles").iterdir()) == ["particles_00.vtu", "particles_10.vtu", "particles_20.vtu"]
    assert len(read_series(out)) == 3
    assert not (out / "energy.csv").exists()  # energy not declared any more


STOPS = {
    # a block at 10 m/s: its right column of points (x = 1.625) passes x = 4 at step 24
    "particle_left_grid": (dict(), {"velocity": [10.0, 0.0]}, 24),
    # serendipity's lumped corner masses are negative from the start
    "negative_mass": (dict(grid={"basis": "serendipity", "lower": [0, 0], "upper": [4, 3], "spacing": 0.5}), {}, 0),
    # a weight of 62.5 kg x 1e308 m/s^2 overflows: the state is not finite after the first step
    "not_finite": (dict(loads=[{"kind": "gravity", "acceleration": [0.0, -1e308]}]), {"velocity": [0.0, 0.0]}, 1),
}


@pytest.mark.parametrize("reason", list(STOPS))
def test_stopped_run_exits_3_and_keeps_valid_outputs(tmp_path, capsys, reason):
    changes, body_changes, stop_step = STOPS[reason]
    base = block()
    body = {**base.bodies[0].model_dump(mode="json"), **body_changes}
    scene = block(bodies=[body], time={"dt": 0.01, "end": 0.5}, output={"every": 5, "particles": True}, **changes)
    out = tmp_path / "out"
    code, stdout, err = run_cli(["run", write_scene(tmp_path, scene), "--out", out], capsys)
    assert code == cli.EXIT_STOPPED
    assert "Traceback" not in err and stdout == ""
    assert err.splitlines()[-1].startswith(f"femgrid-mpm: stopped: step {stop_step} ")
    assert err.splitlines()[-1].endswith(f"the outputs so far are in {out}")

    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "stopped"
    assert (summary["stop"]["reason"], summary["stop"]["step"]) == (reason, stop_step)
    assert summary["stop"]["time"] == pytest.approx(0.01 * stop_step, rel=1e-12)
    records = [k * 0.05 for k in range((stop_step + 4) // 5)]  # record steps 0, 5, ... before the stop
    header, energy = read_energy(out / "energy.csv")
    assert header[0] == "time" and summary["records"] == len(records)
    np.testing.assert_allclose(energy[:, 0], records, rtol=1e-12)
    final = np.load(out / "final.npz")
    assert int(final["step"]) == stop_step
    if records:
        series = read_series(out)
        assert [t for t, _ in series] == pytest.approx(records, rel=1e-12)
    else:
        assert not (out / "particles.pvd").exists()  # nothing was recorded
    if reason == "particle_left_grid":
        # rigid motion is exact: positions x0 + v t, in the table, the series and final.npz
        for t, mesh in series:
            np.testing.assert_allclose(mesh.points[:, :2], final["x0"] + [10.0 * t, 0.0], rtol=0, atol=1e-12)
            np.testing.assert_allclose(mesh.point_data["velocity"], np.tile([10.0, 0.0, 0.0], (16, 1)), rtol=0, atol=1e-12)
            np.testing.assert_array_equal(mesh.point_data["body"], 0)
        np.testing.assert_allclose(final["x"], final["x0"] + [10.0 * 0.24, 0.0], rtol=0, atol=1e-12)
        assert final["x"][:, 0].max() > 4.0  # the state the run stopped at
    if reason == "negative_mass":
        negative = summary["negative_mass"]
        assert (negative["steps_with_negative_mass"], negative["first_step"]) == (1, 0)
        assert negative["min_mass_ratio"] < 0
        np.testing.assert_array_equal(final["x"], final["x0"])
    if reason == "not_finite":  # the place: the first point of the stopped state that is not finite
        first = int(np.flatnonzero(~(np.isfinite(final["x"]).all(axis=1) & np.isfinite(final["v"]).all(axis=1)))[0])
        assert f"; first at point {first} of body 'block' at (" in err.splitlines()[-1]


# -- effects: only the declared ones run ------------------------------------------------------


def all_effects_scene(**output) -> Scene:
    return block(
        loads=[
            {"kind": "gravity", "acceleration": [0.0, -9.81]},
            {"kind": "point", "body": "block", "at": [1.75, 1.5], "force": [1.0, 0.0], "ramp": 0.1},
        ],
        damping={"kind": "mass", "coefficient": 0.5},
        supports=[{"where": "y <= 0", "fix": ["y"]}],
        contact={"kind": "shared"},
        output={"every": 5, **output},
    )


def test_info_lists_counts_effects_and_time_steps(tmp_path, capsys):
    scene = all_effects_scene(particles=True)
    code, stdout, err = run_cli(["info", write_scene(tmp_path, scene)], capsys)
    assert code == 0 and err == ""
    lines = info_lines(stdout)
    assert (lines["title"], lines["basis"], lines["mass"]) == ("Block", "q1", "lumped")
    assert lines["points"] == "16 (block 16)"  # 2 x 2 cells of 2 x 2 points
    assert lines["nodes"] == str(9 * 7)  # q1 on [0, 4] x [0, 3] at spacing 0.5
    effects = lines["effects"].split(", ")
    assert effects[0] == "internal_force (always)"
    assert sorted(effects[1:]) == ["damping", "energy", "gravity", "particles", "point_load", "supports"]
    assert lines["dt"] == "0.01 s"
    assert lines["critical_dt"] == f"{Simulation(scene).critical_dt:.6g} s (estimated)"
    assert lines["steps"] == "20 to t = 0.2 s"


def test_info_with_overrides_and_an_unstable_time_step(tmp_path, capsys):
    """dt beyond the critical step: a one-line warning on stderr, exit 0."""
    path = write_scene(tmp_path, block())
    critical = Simulation(block()).critical_dt
    # to t = 1 s: a step longer than the run would be warned of too
    code, stdout, err = run_cli(["info", path, "--set", f"time.dt={3 * critical!r}", "--set", "time.end=1",
                                 "--mass", "consistent"], capsys)
    assert code == 0
    assert info_lines(stdout)["mass"] == "consistent"
    (warning,) = err.splitlines()
    assert warning.startswith("femgrid-mpm: warning: dt = ") and "exceeds the estimated critical time step" in warning
    # consistent mass has the smaller critical step (about half of lumped for q1)
    assert float(info_lines(stdout)["critical_dt"].split()[0]) < 0.7 * critical


def test_undeclared_effects_run_no_code(tmp_path, capsys, monkeypatch):
    """No [output], loads, damping or supports: ``info`` lists only the internal
    force, and a run succeeds although every effect's set-up is booby-trapped."""
    from femgrid_mpm import effects, observers, output

    def trap(self, simulation):
        raise AssertionError(f"{type(self).__name__} was bound although not declared")

    for cls in (*(entry.effect for entry in effects.REGISTRY), observers.EnergyBookkeeping, output.ParticleSeries,
                output.GridSeries):
        monkeypatch.setattr(cls, "bind", trap)
    path = write_scene(tmp_path, block(output=None))
    code, stdout, _ = run_cli(["info", path], capsys)
    assert code == 0 and info_lines(stdout)["effects"] == "internal_force (always)"
    out = tmp_path / "out"
    code, _, err = run_cli(["run", path, "--out", out], capsys)
    assert code == 0, err
    assert sorted(p.name for p in out.iterdir()) == ["final.npz", "scene.toml", "source_scene.toml", "summary.json"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["effects"] == [] and summary["records"] == 0
    final = np.load(out / "final.npz")
    np.testing.assert_allclose(final["x"] - final["x0"], np.tile([0.2, 0.05], (16, 1)), rtol=0, atol=1e-12)  # v t, rigid


@pytest.mark.parametrize("particles", [False, True])
def test_particle_output_only_when_declared(tmp_path, capsys, particles):
    path = write_scene(tmp_path, block(output={"every": 5, "particles": particles}))
    effects = info_lines(run_cli(["info", path], capsys)[1])["effects"]
    assert ("particles" in effects.split(", ")) is particles
    out = tmp_path / "out"
    assert run_cli(["run", path, "--out", out], capsys)[0] == 0
    assert (out / "particles.pvd").exists() is particles
    assert (out / "particles").exists() is particles
    if particles:
        series = read_series(out)
        assert [t for t, _ in series] == pytest.approx([0.0, 0.05, 0.1, 0.15, 0.2], rel=1e-12)
        final = np.load(out / "final.npz")
        np.testing.assert_array_equal(series[-1][1].points[:, :2], final["x"])  # the last record is the final state


def test_declared_effects_of_zero_strength_change_no_result(tmp_path, capsys):
    """Gravity 0, a point force 0 and damping 0, declared: bit-identical final
    state and energies; the work column they add is zero throughout."""
    plain, zero = tmp_path / "plain", tmp_path / "zero"
    assert run_cli(["run", write_scene(tmp_path, block(), "plain.toml"), "--out", plain], capsys)[0] == 0
    zero_scene = block(
        loads=[
            {"kind": "gravity", "acceleration": [0.0, 0.0]},
            {"kind": "point", "body": "block", "at": [1.0, 1.0], "force": [0.0, 0.0]},
        ],
        damping={"kind": "mass", "coefficient": 0.0},
    )
    code, stdout, _ = run_cli(["info", write_scene(tmp_path, zero_scene, "zero.toml")], capsys)
    assert {"gravity", "point_load", "damping"} <= set(info_lines(stdout)["effects"].split(", "))
    assert run_cli(["run", tmp_path / "zero.toml", "--out", zero], capsys)[0] == 0
    for name in ("x", "v", "stress", "strain", "volume"):
        np.testing.assert_array_equal(np.load(zero / "final.npz")[name], np.load(plain / "final.npz")[name])
    plain_header, plain_energy = read_energy(plain / "energy.csv")
    zero_header, zero_energy = read_energy(zero / "energy.csv")
    assert zero_header == [*plain_header, "external_work"]
    np.testing.assert_array_equal(zero_energy[:, :-1], plain_energy)
    np.testing.assert_array_equal(zero_energy[:, -1], 0.0)


# -- progress bar -----------------------------------------------------------------------------


def test_progress_bar_is_quiet_when_stderr_is_not_a_terminal(tmp_path):
    path = write_scene(tmp_path, block())
    process = subprocess.run(
        [sys.executable, "-m", "femgrid_mpm.cli", "run", str(path), "--out", str(tmp_path / "out")],
        capture_output=True, text=True, env=ENV, timeout=120,
    )
    assert process.returncode == 0
    assert process.stderr == ""
    assert process.stdout.startswith("reached t = 0.2 s: 20 steps")


def test_progress_bar_on_a_terminal_shows_steps_and_simulated_time(tmp_path):
    path = write_scene(tmp_path, block())
    leader, follower = pty.openpty()
    fcntl.ioctl(follower, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # a terminal 100 columns wide
    process = subprocess.Popen(
        [sys.executable, "-m", "femgrid_mpm.cli", "run", str(path), "--out", str(tmp_path / "out")],
        stdout=subprocess.DEVNULL, stderr=follower, env=ENV,
    )
    os.close(follower)
    shown = b""
    while True:  # read as it comes, so the terminal's buffer never fills
        ready, _, _ = select.select([leader], [], [], 120)
        try:
            chunk = os.read(leader, 4096) if ready else b""
        except OSError:  # the terminal closed with the process
            chunk = b""
        if not chunk:
            break
        shown += chunk
    os.close(leader)
    assert process.wait(timeout=120) == 0
    text = shown.decode(errors="replace")
    assert "20/20 steps" in text and "t = 0.2/0.2 s" in text and "100%" in text


# -- killed and interrupted runs ----------------------------------------------------------------


def start_long_run(tmp_path) -> tuple[subprocess.Popen, Path]:
    """The vibrating bar run for 100 s (tens of seconds of work), with particle output."""
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "femgrid_mpm.cli", "run", str(VIBRATING_BAR), "--out", str(out),
            "--set", "time.end=100", "--set", "output.every=10", "--set", "output.particles=true"]
    # SIGINT as the default: a test session started in the background (``&``) ignores it,
    # and a child inherits that, so Python would not install its KeyboardInterrupt handler
    return subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=ENV,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL)), out


def wait_for_records(process, out: Path, rows: int, timeout=120.0) -> None:
    """Until energy.csv holds ``rows`` records (it is rewritten about once a second)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert process.poll() is None, "the run ended before it could be interrupted"
        energy = out / "energy.csv"
        if energy.exists() and len(energy.read_text().splitlines()) > rows:
            return
        time.sleep(0.05)
    raise AssertionError("no records in time")


def assert_outputs_complete(out: Path) -> dict:
    """Every output file under its final name parses completely."""
    header, energy = read_energy(out / "energy.csv")  # a torn row would not have all columns
    assert header == [c for c in COLUMNS if c != "external_work"]
    steps = energy[:, 0] / 0.03
    np.testing.assert_allclose(steps, np.arange(len(energy)), atol=1e-6)  # every record, in order
    for t, mesh in read_series(out):
        assert len(mesh.points) == 180 and mesh.point_data["velocity"].shape == (180, 3)
    summary = json.loads((out / "summary.json").read_text())
    names = {p.name for p in out.iterdir() if not p.name.startswith(".")}
    assert names <= {"energy.csv", "final.npz", "summary.json", "scene.toml", "source_scene.toml", "particles.pvd", "particles"}
    return summary


def test_killed_run_leaves_only_complete_files(tmp_path):
    process, out = start_long_run(tmp_path)
    try:
        wait_for_records(process, out, rows=2)
    finally:
        process.kill()
        process.wait(timeout=60)
    summary = assert_outputs_complete(out)
    assert summary["status"] == "running"  # it never got to say otherwise
    assert not (out / "final.npz").exists()


def test_interrupted_run_exits_130_and_writes_what_it_has(tmp_path):
    process, out = start_long_run(tmp_path)
    try:
        wait_for_records(process, out, rows=2)
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=60) == cli.EXIT_INTERRUPTED
    finally:
        process.kill()
    assert process.stderr.read().decode().splitlines()[-1].startswith("femgrid-mpm: interrupted: at step ")
    summary = assert_outputs_complete(out)
    assert summary["status"] == "interrupted"
    final = np.load(out / "final.npz")
    assert int(final["step"]) == summary["steps"] > 0
    _, energy = read_energy(out / "energy.csv")
    assert energy[-1, 0] <= float(final["time"]) < energy[-1, 0] + 0.03 + 1e-9  # every record so far is in the table


# -- atomic files ------------------------------------------------------------------------------


def test_atomic_write_keeps_the_old_file_when_writing_fails(tmp_path):
    path = tmp_path / "table.csv"
    atomic_write(path, "old, complete\n")
    with pytest.raises(RuntimeError):
        with atomic_path(path) as temporary:
            temporary.write_text("new, half")
            raise RuntimeError("killed while writing")
    assert path.read_text() == "old, complete\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.csv"]  # no temporary left


@pytest.mark.parametrize("flush_seconds", [0.0, 1e9])
def test_energy_csv_rows_reach_the_file(tmp_path, flush_seconds):
    """Every row at once without throttling; with it, the first row at once and
    the rest by ``flush``; never a partial table."""
    path = tmp_path / "energy.csv"
    table = EnergyCsv(path, ("time", "kinetic"), flush_seconds)
    table.flush()
    assert path.read_text() == "time,kinetic\n"
    for k in range(5):
        table.add_row({"time": 0.1 * k, "kinetic": 1.0 / 3.0, "strain": 7.0})
        rows_on_disk = len(path.read_text().splitlines()) - 1
        assert rows_on_disk == (k + 1 if flush_seconds == 0 else 1)
    table.flush()
    header, values = read_energy(path)
    assert header == ["time", "kinetic"]
    np.testing.assert_array_equal(values[:, 0], [0.1 * k for k in range(5)])
    np.testing.assert_array_equal(values[:, 1], 1.0 / 3.0)  # repr: the same double back


# -- usage errors, help, reproduce -----------------------------------------------------------------


@pytest.mark.parametrize(
    "argv, words",
    [
        ([], "required"),
        (["frobnicate"], "invalid choice"),
        (["run"], "required"),
        (["run", "{scene}"], "--out"),
        (["run", "{scene}", "--out", "{tmp}/o", "--basis", "q7"], "argument --basis: invalid choice: 'q7'"),
        (["run", "{scene}", "--out", "{tmp}/o", "--mass", "diagonal"], "argument --mass: invalid choice"),
        (["run", "{scene}", "--out", "{tmp}/o", "--set", "time.end"], "--set time.end: expected KEY=VALUE"),
        (["run", "{scene}", "--out", "{tmp}/o", "--set", "bodies.3.name=x"], "bodies.3.name: no such key to set"),
        (["run", "{scene}", "--out", "{tmp}/o", "--set", "time.end=-1"], "time.end: must be greater than 0"),
        (["run", "{scene}", "--out", "{scene}"], "exists and is not a directory"),
        (["run", "{scene}", "--out", "{scene}/sub"], "cannot write there"),
        (["info", "{tmp}/missing.toml"], "no such scene file"),
        (["reproduce", "--case", "nope"], "--case nope: no such case"),
        # an unset $OUT: it would have meant the working directory
        (["run", "{scene}", "--out", ""], "--out: is empty"),
        (["reproduce", "--out", ""], "--out: is empty"),
        (["reproduce", "--out", "{scene}/sub"], "cannot write there"),
        # a --gallery that cannot be written: the --out it had made (o/a) was left behind
        (["reproduce", "--case", "vibrating_bar", "--out", "{tmp}/o/a", "--gallery", "{scene}/sub"],
         "--gallery {scene}/sub: cannot write there"),
        # an empty file or directory to read: it was taken as the working directory
        (["run", "", "--out", "{tmp}/o"], "argument SCENE.toml: is empty"),
        (["info", ""], "argument SCENE.toml: is empty"),
        (["resume", ""], "argument DIR: is empty"),
        (["plot", ""], "argument DIR: is empty"),
        (["sweep", "", "--out", "{tmp}/o"], "argument SWEEP.toml: is empty"),
        (["report", ""], "argument DIR: is empty"),
    ],
)
def test_bad_arguments_are_one_line_exit_2(tmp_path, capsys, argv, words):
    scene = write_scene(tmp_path, block())
    argv = [a.format(scene=scene, tmp=tmp_path) for a in argv]
    code, stdout, err = run_cli(argv, capsys)
    assert code == cli.EXIT_BAD_INPUT
    assert "Traceback" not in err
    (line,) = err.splitlines()
    assert line.startswith("femgrid-mpm: error: ") and words.format(scene=scene) in line
    assert not (tmp_path / "o").exists()


def test_help_lists_commands_and_exit_codes(capsys):
    code, stdout, _ = run_cli(["--help"], capsys)
    assert code == 0
    stdout = " ".join(stdout.split())  # argparse wraps the text
    assert all(word in stdout for word in ("run", "info", "reproduce", "Exit codes", "3 the simulation stopped"))


def test_reproduce_runs_every_case_and_prints_its_table(tmp_path, capsys, monkeypatch):
    """The loop over ``femgrid_mpm.reproduce.CASES`` (replaced here by two quick cases)."""
    from femgrid_mpm import reproduce

    calls = []

    def case(name):
        def run(out_dir):
            calls.append(Path(out_dir))
            Path(out_dir).mkdir(parents=True)
            (Path(out_dir) / "table.md").write_text(f"| {name} |\n")

        return run

    monkeypatch.setattr(reproduce, "CASES", {"first": case("first"), "second": case("second")})
    monkeypatch.setattr(reproduce, "PLANNED_RUNS", {"first": lambda: 0, "second": lambda: 0})
    code, stdout, err = run_cli(["reproduce", "--out", tmp_path / "results"], capsys)
    assert code == 0
    assert calls == [tmp_path / "results" / "first", tmp_path / "results" / "second"]
    assert stdout == f"| first |\n\n| second |\n\nreproduced first, second: figures and tables in {tmp_path / 'results'}\n"
    assert err == "first ...\nsecond ...\n"
    calls.clear()
    assert run_cli(["reproduce", "--out", tmp_path / "again", "--case", "second"], capsys)[0] == 0
    assert calls == [tmp_path / "again" / "second"]
    # a file where a case writes its directory: refused before any case runs (was a FileExistsError traceback)
    calls.clear()
    (tmp_path / "third").mkdir()
    (tmp_path / "third" / "second").write_text("a file")
    code, _, err = run_cli(["reproduce", "--out", tmp_path / "third"], capsys)
    assert code == cli.EXIT_BAD_INPUT and calls == []
    assert err == f"femgrid-mpm: error: --out {tmp_path / 'third'}: {tmp_path / 'third' / 'second'} is a file, where case second writes its directory\n"

    def full_disk(out_dir):
        raise OSError(28, "No space left on device")

    monkeypatch.setitem(reproduce.CASES, "second", full_disk)
    code, _, err = run_cli(["reproduce", "--out", tmp_path / "fourth"], capsys)
    assert code == cli.EXIT_WRITE_FAILED
    assert err.splitlines()[-1] == (f"femgrid-mpm: error: cannot write the outputs of case second in "
                                    f"{tmp_path / 'fourth' / 'second'}: No space left on device; the finished cases "
                                    f"(first) are in {tmp_path / 'fourth'}")


def test_version_prints_the_installed_distributions_version(capsys):
    import importlib.metadata

    code, stdout, err = run_cli(["--version"], capsys)
    assert (code, err) == (0, "")
    assert stdout == f"femgrid-mpm {importlib.metadata.version('femgrid-mpm')}\n"


def test_reproduce_lists_its_cases_and_names_them_for_an_unknown_case(tmp_path, capsys):
    from femgrid_mpm.reproduce import CASES

    code, stdout, err = run_cli(["reproduce", "--list", "--out", tmp_path / "results"], capsys)
    assert (code, err) == (0, "")
    assert stdout.splitlines() == list(CASES)
    assert not (tmp_path / "results").exists()  # nothing run, nothing written
    for argv in (["--case", "bar"], ["--list", "--case", "bar"]):  # with --list it was passed over
        code, stdout, err = run_cli(["reproduce", *argv, "--out", tmp_path / "results"], capsys)
        assert code == cli.EXIT_BAD_INPUT and stdout == ""
        (line,) = err.splitlines()
        assert line == f"femgrid-mpm: error: --case bar: no such case (cases: {', '.join(CASES)})"


def test_reproduce_gallery_copies_the_figures_of_the_cases_run(tmp_path, capsys, monkeypatch):
    """``--gallery DIR``: each picture of ``GALLERY`` whose case ran is its case's figure, byte for byte."""
    from femgrid_mpm import reproduce
    from femgrid_mpm.reproduce import gallery

    def case(name):
        def run(out_dir):
            (Path(out_dir) / "sub").mkdir(parents=True)
            (Path(out_dir) / "sub" / "figure.png").write_bytes(f"png of {name}".encode())

        return run

    monkeypatch.setattr(reproduce, "CASES", {"first": case("first"), "second": case("second")})
    monkeypatch.setattr(reproduce, "PLANNED_RUNS", {"first": lambda: 0, "second": lambda: 0})
    monkeypatch.setattr(gallery, "GALLERY", {"a.png": ("first", "sub/figure.png"), "b.png": ("second", "sub/figure.png")})
    code, _, err = run_cli(["reproduce", "--out", tmp_path / "results", "--case", "second", "--gallery", tmp_path / "g"], capsys)
    assert code == 0, err
    assert sorted(p.name for p in (tmp_path / "g").iterdir()) == ["b.png"]
    assert (tmp_path / "g" / "b.png").read_bytes() == b"png of second"
    (tmp_path / "file").write_text("")
    code, _, err = run_cli(["reproduce", "--out", tmp_path / "results", "--gallery", tmp_path / "file"], capsys)
    assert code == 2 and err.count("\n") == 1 and "--gallery" in err


# -- the docs document the contract ---------------------------------------------------------------

DOCS = ROOT / "docs"


def doc_text(page: str) -> str:
    return (DOCS / page).read_text()


def models_of(annotation) -> list:
    """The pydantic models an annotation holds (tuple[...], Union[...], Annotated[...], None left out)."""
    import typing

    origin = typing.get_origin(annotation)
    if origin is not None:
        arguments = typing.get_args(annotation)[:1] if origin is typing.Annotated else typing.get_args(annotation)
        return [model for argument in arguments for model in models_of(argument)]
    return [annotation] if isinstance(fields_of(annotation), dict) else []


def fields_of(model):
    return getattr(model, "model_fields", None) or getattr(model, "__pydantic_fields__", None)


def model_keys(model) -> set[str]:
    """A table's keys as the scene reference spells them: ``key``, and ``key.sub`` for an inline table."""
    keys = set()
    for name, info in fields_of(model).items():
        keys.add(name)
        for inner in models_of(info.annotation):
            keys |= {f"{name}.{sub}" for sub in model_keys(inner)}
    return keys


def kind_of(model) -> str:
    import typing

    (kind,) = typing.get_args(fields_of(model)["kind"].annotation)
    return kind


def scene_sections() -> dict:
    """Every section of the scene reference the models ask for: (table, kind) -> its keys.

    The top level is ("", None); a table of several kinds (``[[loads]]``) has one section per
    kind, whose ``kind`` the section's heading gives."""
    sections = {("", None): set()}
    for name, info in Scene.model_fields.items():
        models = models_of(info.annotation)
        if not models:
            sections[("", None)].add(name)
        elif len(models) == 1:
            sections[(name, None)] = model_keys(models[0])
        else:
            sections.update({(name, kind_of(model)): model_keys(model) for model in models})
    return sections


def documented_sections() -> dict:
    """The sections of docs/scenes.md's table of keys: a row ``**`[table]`**`` (with ``, `kind = "k"```)
    opens one; every backticked name in the first cell of the rows after it is a key."""
    text = doc_text("scenes.md")
    start = text.index("| key | default | meaning |")
    rows = text[start:text.index("\n\n", start)].splitlines()[2:]
    sections, current = {("", None): set()}, ("", None)
    for row in rows:
        cell = row.split("|")[1]
        heading = re.fullmatch(r" \*\*`\[{1,2}(\w+)\]{1,2}`\*\*(?:, `kind = \"(\w+)\"`)? ", cell)
        if heading:
            current = heading.groups()
            assert current not in sections, f"docs/scenes.md documents {current} twice"
            sections[current] = {"kind"} if current[1] else set()
            continue
        for key in re.findall(r"`([\w.]+)`", cell):
            sections[current].add(key)
    return sections


def test_scene_reference_documents_exactly_the_models_keys():
    """docs/scenes.md lists every key of the scene's models and of the effects registry's tables,
    in its table's section, and nothing they do not have: the page cannot drift."""
    expected, documented = scene_sections(), documented_sections()
    assert sorted(documented, key=str) == sorted(expected, key=str), "tables of docs/scenes.md"
    for section, keys in expected.items():
        assert sorted(keys - documented[section]) == [], f"keys of {section} missing from docs/scenes.md"
        assert sorted(documented[section] - keys) == [], f"docs/scenes.md documents keys {section} does not have"


def test_docs_document_every_option_output_and_exit_code():
    command_section = doc_text("cli.md")
    parser = cli.parser.build_parser()
    (commands,) = [action for action in parser._actions if isinstance(action, type(parser._subparsers._group_actions[0]))]
    for name, subparser in commands.choices.items():
        assert f"femgrid-mpm {name}" in command_section
        for action in subparser._actions:
            for option in action.option_strings:
                if option not in ("-h", "--help"):
                    assert f"`{option}" in command_section, (name, option)
    for code in cli.EXIT_CODES:
        assert f"\n| {code} |" in command_section, code
    outputs_section = doc_text("outputs.md")
    for name in [*COLUMNS, "energy.csv", "final.npz", "summary.json", "particles.pvd", "scene.toml", "source_scene.toml",
                 "x0", "x", "v", "stress", "strain", "mass", "volume", "body", "velocity", "displacement", "stress_xx",
                 # summary.json's entries that the page once left out, and the grid series
                 "energy_drift", "rms_end", "rms_max", "when", "note", "grid.pvd"]:
        assert f"`{name}`" in outputs_section, name


def test_scene_reference_example_is_a_valid_scene_with_every_effect(tmp_path, capsys):
    (example,) = re.findall(r"```toml\n(.*?)```", doc_text("scenes.md"), flags=re.S)
    path = tmp_path / "example.toml"
    path.write_text(example)
    code, stdout, err = run_cli(["info", path], capsys)
    assert code == 0 and err == ""
    effects = info_lines(stdout)["effects"].split(", ")
    assert sorted(effects) == sorted(["internal_force (always)", "energy", "particles", "gravity", "point_load", "damping", "supports"])


# -- what must not escape as a traceback or cost an earlier run's outputs ---------------------


def test_write_failure_after_a_stop_is_one_line_exit_1(tmp_path, capsys, monkeypatch):
    """A full disk while a stopped run writes its last files: exit code 1 and one line
    naming the directory and the stop (it was a 54-line traceback)."""
    import femgrid_mpm.output as output

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(output, "write_final_state", full_disk)
    body = {**block().bodies[0].model_dump(mode="json"), "velocity": [10.0, 0.0]}  # leaves the grid at step 24
    scene = block(bodies=[body], time={"dt": 0.01, "end": 0.5})
    out = tmp_path / "out"
    code, _, err = run_cli(["run", write_scene(tmp_path, scene), "--out", out], capsys)
    assert code == cli.EXIT_WRITE_FAILED
    (line,) = err.splitlines()
    assert line.startswith(f"femgrid-mpm: error: cannot write the outputs in {out} after step 24 ")
    assert "No space left on device" in line


def test_a_full_disk_as_the_outputs_start_is_a_failed_write_not_bad_input(tmp_path, capsys, monkeypatch):
    """The start ran into a full disk (``resume`` rewrites its .pvd and summary first): exit 2
    said nothing had been written; it is exit 1, naming the directory."""
    import femgrid_mpm.output as output

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(output, "write_summary", full_disk)
    out = tmp_path / "out"
    code, _, err = run_cli(["run", write_scene(tmp_path, block()), "--out", out], capsys)
    assert code == cli.EXIT_WRITE_FAILED
    (line,) = err.splitlines()
    assert line == f"femgrid-mpm: error: cannot write the outputs in {out} before the first step: [Errno 28] No space left on device"


def test_failed_start_removes_nothing_of_an_earlier_run(tmp_path, capsys, monkeypatch):
    """A second run into a directory whose particle series cannot be written: exit 2 and
    every file of the first run keeps its bytes (its energy.csv, final.npz and series
    were removed before the failure showed)."""
    import femgrid_mpm.output as output

    out = tmp_path / "out"
    scene_path = write_scene(tmp_path, block(output={"every": 5, "particles": True}))
    assert run_cli(["run", scene_path, "--out", out], capsys)[0] == cli.EXIT_DONE
    before = {path: path.read_bytes() for path in sorted(out.rglob("*")) if path.is_file()}
    assert out / "energy.csv" in before and out / "final.npz" in before and len(before) > 6
    probe = output.probe_writable

    def read_only_series(directory):
        if Path(directory).name == "particles":
            raise PermissionError(13, "Permission denied")
        probe(directory)

    monkeypatch.setattr(output, "probe_writable", read_only_series)
    code, _, err = run_cli(["run", scene_path, "--out", out, "--set", "time.end=0.1"], capsys)
    assert code == cli.EXIT_BAD_INPUT
    (line,) = err.splitlines()
    assert line == f"femgrid-mpm: error: --out {out}: cannot write there: Permission denied"
    assert {path: path.read_bytes() for path in sorted(out.rglob("*")) if path.is_file()} == before


def test_scene_larger_than_the_memory_is_refused_before_allocating(tmp_path, capsys, monkeypatch):
    """A scene whose points and nodes alone need more than the machine has available
    is refused in one line (the system would kill the run mid-allocation, with no
    message); the bound is 300 B per point and 100 B per node (measured: 317-887 B)."""
    # 16 points; nodes as the size check counts them, cells + 3 per direction: 11 x 9 = 99
    need = 300 * 16 + 100 * 99
    monkeypatch.setattr(cli.scene_input, "available_memory", lambda: need + 1.0)
    path = write_scene(tmp_path, block())
    assert run_cli(["info", path], capsys)[0] == cli.EXIT_DONE
    monkeypatch.setattr(cli.scene_input, "available_memory", lambda: 10_000.0)
    code, _, err = run_cli(["info", path], capsys)
    assert code == cli.EXIT_BAD_INPUT
    (line,) = err.splitlines()
    assert line == (f"femgrid-mpm: error: {path}: the scene needs at least {need / 1e9:.3g} GB of memory, "
                    "more than the 1e-05 GB this machine has available")


def test_critical_step_without_memory_is_a_warning(tmp_path, capsys, monkeypatch):
    """The critical time step's eigenvalue problem running out of memory: ``info`` says
    it was not estimated and warns in one line (it was a MemoryError traceback)."""
    from femgrid_mpm.solver import Simulation as Simulated

    def no_memory(self):
        raise MemoryError

    monkeypatch.setattr(Simulated, "critical_dt", property(no_memory))
    code, stdout, err = run_cli(["info", write_scene(tmp_path, block())], capsys)
    assert code == cli.EXIT_DONE
    assert "critical_dt: not estimated (not enough memory)" in " ".join(stdout.split())
    (line,) = err.splitlines()
    assert line.startswith("femgrid-mpm: warning: the critical time step could not be estimated")


def test_summary_lists_a_checkpoint_only_when_one_was_written(tmp_path, capsys):
    """``--checkpoint-every`` longer than the run (20 steps) writes none, and the summary
    does not list one (it did)."""
    path = write_scene(tmp_path, block())
    for every, written in ((1000, False), (10, True)):
        out = tmp_path / f"every_{every}"
        assert run_cli(["run", path, "--out", out, "--checkpoint-every", every], capsys)[0] == cli.EXIT_DONE
        listed = "checkpoint.npz" in json.loads((out / "summary.json").read_text())["files"]
        assert listed == written == (out / "checkpoint.npz").exists()


def test_ctrl_c_while_the_libraries_load_is_one_line(capsys, monkeypatch):
    """Importing the command line loads no numpy, scipy or scikit-fem (a Ctrl-C there
    printed a traceback from the package's import); they load inside ``main``, where a
    Ctrl-C is one line and exit code 130."""
    loaded = subprocess.run([sys.executable, "-c", "import sys, femgrid_mpm.cli; "
                             "print(sorted(m for m in ('numpy', 'scipy', 'skfem', 'numba') if m in sys.modules))"],
                            capture_output=True, text=True, env=ENV, timeout=60)
    assert loaded.stdout.strip() == "[]", loaded.stderr

    def interrupted():
        raise KeyboardInterrupt

    monkeypatch.setattr(cli.parser, "build_parser", interrupted)
    assert cli.main(["info", "scene.toml"]) == cli.EXIT_INTERRUPTED
    assert capsys.readouterr().err == "femgrid-mpm: interrupted: stopped by the user\n"


def test_a_run_stopped_at_step_0_lists_only_the_files_it_wrote(tmp_path, capsys):
    """summary.json's "files" named particles.pvd for a run stopped before its first record
    (serendipity's negative masses on the bar, at step 0): plot then said the scene did not ask
    for particles."""
    out = tmp_path / "out"
    scene = Path(__file__).parents[1] / "femgrid_mpm" / "scenes" / "vibrating_bar.toml"
    code, _, err = run_cli(["run", scene, "--basis", "serendipity", "--out", out, "--no-progress",
                            "--set", "output.particles=true", "--set", "output.every=20"], capsys)
    assert code == cli.EXIT_STOPPED, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stop"]["step"] == 0 and "particles.pvd" not in summary["files"]
    assert all((out / name).is_file() for name in summary["files"])
