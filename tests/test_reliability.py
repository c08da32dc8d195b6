"""The reliability contract (docs/reliability.md): bad input is one line and exit code 2
before anything is written; the input and earlier outputs are never lost; streams,
signals and damaged checkpoints end in the documented code, never a traceback.

References are independent of the code under test: the bytes and modification times
of files that must be kept, step counts ``ceil(end / dt)`` by hand, overlapping pairs
of rectangles by brute force, exit codes 128 + the signal's number.
"""

import json
import re
import os
import signal
import subprocess
import sys
import time
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

from femgrid_mpm import cli
from femgrid_mpm.checkpoint import read_checkpoint, write_checkpoint
from femgrid_mpm.expressions import ExpressionError, compile_expression
from femgrid_mpm.particles import overlapping_pairs, warn_of_overlaps
from femgrid_mpm.scene import Scene, SceneError, bundled_scene
from femgrid_mpm.solver import Simulation
from helpers import run_cli

ROOT = Path(__file__).parents[1]
VIBRATING_BAR = ROOT / "scenes" / "vibrating_bar.toml"
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
#: a block moving in a 4 x 3 grid: 20 steps of 0.01 s, 16 points, a record every 5 steps
BLOCK = """\
title = "block"

[grid]
lower = [0.0, 0.0]
upper = [4.0, 3.0]
spacing = 0.5

[time]
dt = 0.01
end = 0.2

[[bodies]]
name = "block"
lower = [0.75, 0.5]
upper = [1.75, 1.5]
velocity = [1.0, 0.25]
material = { E = 1.0e4, nu = 0.3, density = 1.0e3 }

[output]
every = 5
"""


def one_line_error(err: str, *needles) -> str:
    assert "Traceback" not in err, err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("femgrid-mpm: error: "), err
    for needle in needles:
        assert needle in lines[0], (needle, err)
    return lines[0]


def snapshot(directory: Path) -> dict:
    """Every file below ``directory``: its bytes and modification time."""
    return {p.relative_to(directory): (p.read_bytes(), p.stat().st_mtime_ns)
            for p in sorted(directory.rglob("*")) if p.is_file()}


def cli_process(*argv, **options) -> subprocess.Popen:
    """``femgrid-mpm ARGV`` in its own process, SIGINT handled as in a terminal."""
    options.setdefault("stdout", subprocess.DEVNULL)
    options.setdefault("stderr", subprocess.PIPE)
    options.setdefault("env", ENV)
    return subprocess.Popen([sys.executable, "-m", "femgrid_mpm.cli", *map(str, argv)], cwd=ROOT,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL), **options)


@pytest.fixture
def block_file(tmp_path) -> Path:
    path = tmp_path / "block.toml"
    path.write_text(BLOCK)
    return path


# -- the input and earlier outputs are never lost ----------------------------------------------


@pytest.mark.parametrize("name", ["scene.toml", "source_scene.toml", "energy.csv", "final.npz", "summary.json",
                                  "checkpoint.npz", "particles.pvd"])
def test_a_run_never_writes_over_its_scene_file(tmp_path, capsys, name):
    """``run d/NAME --out d`` for every name the run writes: exit 2, one line naming the
    file, and the directory exactly as it was (the scene's bytes included)."""
    directory = tmp_path / "d"
    directory.mkdir()
    scene = directory / name
    scene.write_text(BLOCK)
    (directory / "notes.txt").write_text("an earlier file")
    before = snapshot(directory)
    code, out, err = run_cli(["run", scene, "--out", directory, "--no-progress"], capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, str(scene), "is the scene file given")
    assert snapshot(directory) == before


@pytest.mark.parametrize("link", ["symbolic", "hard"])
def test_a_link_to_the_scene_file_among_the_outputs_is_refused(tmp_path, capsys, link):
    scene = tmp_path / "mine.toml"
    scene.write_text(BLOCK)
    out = tmp_path / "out"
    out.mkdir()
    (os.symlink if link == "symbolic" else os.link)(scene, out / "scene.toml")
    before = snapshot(tmp_path)
    code, _, err = run_cli(["run", scene, "--out", out, "--no-progress"], capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, "is the scene file given")
    assert snapshot(tmp_path) == before


def test_a_scene_elsewhere_runs_into_a_directory_with_an_earlier_run(tmp_path, capsys, block_file):
    """The refusal is about the scene file only: the same scene from elsewhere runs and
    replaces the earlier outputs (16 points moving at (1, 0.25) m/s for 0.2 s)."""
    out = tmp_path / "out"
    assert run_cli(["run", block_file, "--out", out, "--no-progress"], capsys)[0] == cli.EXIT_DONE
    copy = tmp_path / "again.toml"
    copy.write_bytes((out / "scene.toml").read_bytes())
    assert run_cli(["run", copy, "--out", out, "--no-progress"], capsys)[0] == cli.EXIT_DONE
    final = np.load(out / "final.npz")
    np.testing.assert_allclose(final["x"] - final["x0"], np.tile([0.2, 0.05], (16, 1)), atol=1e-12)


@pytest.mark.parametrize("name", ["energy.csv", "final.npz", "summary.json"])
def test_a_directory_in_the_place_of_an_output_is_refused_before_writing(tmp_path, capsys, block_file, name):
    out = tmp_path / "out"
    (out / name).mkdir(parents=True)
    code, _, err = run_cli(["run", block_file, "--out", out, "--no-progress"], capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, f"{name}: is a directory")
    assert sorted(p.name for p in out.iterdir()) == [name]


# -- a limit on the steps and on the records, for every way of giving dt --------------------------


@pytest.mark.parametrize("settings, steps", [
    (["time.dt=auto", "time.safety=1e-300"], "e+301 steps"),
    (["time.dt=auto", "time.safety=5e-324"], "infinitely many steps"),  # dt = 0 (was ZeroDivisionError)
    (["time.end=1e300"], "3.33e+302 steps"),  # 1e300 / 0.003
    (["time.dt=auto", "bodies.0.material.E=1e30", "bodies.0.material.density=1e-30"], "e+31 steps"),
])
def test_absurd_step_counts_are_refused_before_anything_is_removed(tmp_path, capsys, settings, steps):
    """An earlier run's outputs stay byte for byte; the line names the steps and the key."""
    out = tmp_path / "out"
    argv = ["run", VIBRATING_BAR, "--out", out, "--no-progress", "--set", "time.end=0.03"]
    assert run_cli(argv, capsys)[0] == cli.EXIT_DONE
    before = snapshot(out)
    code, _, err = run_cli(["run", VIBRATING_BAR, "--out", out, "--no-progress",
                            *[a for s in settings for a in ("--set", s)]], capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, "time.dt", steps, "time.max_steps")
    assert snapshot(out) == before


def test_the_step_limit_is_exact_and_raised_by_time_max_steps(tmp_path, capsys, block_file):
    """20 steps (0.2 s / 0.01 s): refused under a limit of 19, run under 20."""
    code, _, err = run_cli(["info", block_file, "--set", "time.max_steps=19"], capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, "time.dt", "20 steps, more than the limit of 19")
    code, out, _ = run_cli(["info", block_file, "--set", "time.max_steps=20"], capsys)
    assert code == cli.EXIT_DONE and re.search(r"^steps: +20 to t = 0.2 s$", out, flags=re.M)
    # dt = "auto" the same way: info's own step count, then one fewer as the limit
    code, out, _ = run_cli(["info", block_file, "--set", "time.dt=auto"], capsys)
    auto_steps = int(next(line for line in out.splitlines() if line.startswith("steps:")).split()[1])
    code, _, err = run_cli(["info", block_file, "--set", "time.dt=auto", "--set", f"time.max_steps={auto_steps - 1}"], capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, "time.dt", f"{auto_steps} steps", "time.max_steps")


def test_records_beyond_output_max_bytes_are_refused(tmp_path, capsys):
    """The bar for 8e4 s at 0.003 s: 2.67e7 steps (under the step limit), a record each:
    about 26.7 GB of energy rows at 1 kB, over the 10 GB default; every 10 steps fits."""
    code, _, err = run_cli(["info", VIBRATING_BAR, "--set", "time.end=8e4"], capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, "output.every", "26.7 GB", "output.max_bytes")
    assert run_cli(["info", VIBRATING_BAR, "--set", "time.end=8e4", "--set", "output.every=10"], capsys)[0] == cli.EXIT_DONE
    # particle files count their points: 2669 records of 1 kB + 2 kB + 180 points x 120 B: 65.7 MB
    code, _, err = run_cli(["info", VIBRATING_BAR, "--set", "output.particles=true", "--set", "output.max_bytes=60000000"],
                           capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, "(energy and particles)", "0.0657 GB")


def test_the_library_refuses_the_same_step_counts_and_builds_long_records(tmp_path):
    """A simulation may be built to be stepped a few times: its records' size is the
    command line's check, its steps are the library's."""
    scene = bundled_scene("vibrating_bar").with_overrides(**{"time.dt": "auto", "time.safety": 1e-300})
    with pytest.raises(ValueError, match=r"time\.dt: .* steps, more than the limit"):
        Simulation(scene)
    long = bundled_scene("vibrating_bar").with_overrides(**{"time.end": 8e4})
    assert Simulation(long).n_steps == 26666667  # ceil(8e4 / 0.003)


# -- tracebacks and hangs ------------------------------------------------------------------------


def test_toml_nested_3000_deep_is_one_line(tmp_path, capsys, block_file):
    deep = tmp_path / "deep.toml"
    deep.write_text(BLOCK + "deep = " + "[" * 3000 + "]" * 3000 + "\n")
    code, _, err = run_cli(["info", deep], capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, "nested too deeply")
    code, _, err = run_cli(["info", block_file, "--set", "title=" + "[" * 3000 + "]" * 3000], capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, "--set title", "nested too deeply")


def test_nesting_the_toml_reader_takes_is_refused_by_key(tmp_path, capsys, block_file):
    """100 levels parse, but are deeper than any scene key: refused naming the key."""
    code, _, err = run_cli(["info", block_file, "--set", "output.every=" + "[" * 100 + "]" * 100], capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, "output.every", "nested more than 32 levels deep")


def test_names_longer_than_the_file_system_allows_are_one_line(tmp_path, capsys, block_file):
    long = tmp_path / ("a" * 300)
    for argv in (["run", block_file, "--out", long], ["resume", long], ["info", str(long) + ".toml"]):
        code, _, err = run_cli(argv, capsys)
        assert code == cli.EXIT_BAD_INPUT, argv
        one_line_error(err, "File name too long")


def test_stdout_on_a_full_device_is_exit_1_in_one_line(block_file):
    with open("/dev/full", "w") as full:
        process = cli_process("info", block_file, stdout=full)
        err = process.communicate(timeout=120)[1].decode()
    assert process.returncode == cli.EXIT_WRITE_FAILED
    assert err.splitlines() == ["femgrid-mpm: error: cannot write to standard output: No space left on device"]


def test_a_completed_run_whose_line_cannot_be_written_is_exit_1(tmp_path, block_file):
    """The outputs are complete, but its line is lost: exit 1 (was 0 with a warning; the docs
    and `sweep` said 1)."""
    with open("/dev/full", "w") as full:
        process = cli_process("run", block_file, "--out", tmp_path / "out", "--no-progress", stdout=full)
        err = process.communicate(timeout=300)[1].decode()
    assert process.returncode == cli.EXIT_WRITE_FAILED
    assert err.splitlines() == [f"femgrid-mpm: error: the run completed (outputs in {tmp_path / 'out'}) but standard "
                                "output cannot be written: No space left on device"]
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["status"] == "completed"


def test_a_title_that_stdout_cannot_encode_is_escaped(tmp_path, block_file):
    """PYTHONIOENCODING=ascii (a non-UTF-8 locale) and a title "café": a UnicodeEncodeError
    traceback from `info`, exit 1."""
    scene = tmp_path / "cafe.toml"
    scene.write_text(Path(block_file).read_text().replace('title = "block"', 'title = "café"', 1))
    process = cli_process("info", scene, stdout=subprocess.PIPE, env={**ENV, "PYTHONIOENCODING": "ascii"})
    out, err = (stream.decode() for stream in process.communicate(timeout=120))
    assert process.returncode == 0 and err == ""
    assert "caf\\xe9" in out


def test_the_memory_check_counts_an_address_space_limit():
    """`ulimit -v` was not counted (MemAvailable only): a scene passed the check and ran out of
    memory mid-run, a MemoryError traceback after the earlier outputs were removed."""
    import resource

    limit = 3 * 2**30
    code = "from femgrid_mpm.cli.scene_input import available_memory; print(available_memory())"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT, env=ENV,
                          preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (limit, limit)))
    assert done.returncode == 0, done.stderr
    assert 0 < float(done.stdout) < limit


def test_control_characters_of_a_scene_do_not_reach_the_terminal(tmp_path, block_file, capsys):
    """An ESC in a title or a body's name reached the terminal raw (a command to it) in `info`'s
    lines and in error messages; a no-break space, a joiner or a tab is text and stays."""
    scene = tmp_path / "esc.toml"
    text = Path(block_file).read_text().replace('title = "block"', 'title = "a\\u001b[2Jb"', 1)
    scene.write_text(text)
    code, out, err = run_cli(["info", scene], capsys)
    assert code == 0 and "\x1b" not in out and "a\\x1b[2Jb" in out
    from femgrid_mpm.cli.parser import visible

    typeset = "Poutre\u00a0: 10\u202f000 points, \u00e9moji \U0001f469\u200d\U0001f52c\t(\u202eevil)"
    assert visible(typeset) == typeset.replace("\u202e", "\\u202e")  # text stays text; an override is escaped
    code, out, err = run_cli(["info", scene, "--set", "bodies.0.name=b\u001b[2Jc", "--set", "bodies.0.upper=[99, 99]"],
                             capsys)
    assert code == cli.EXIT_BAD_INPUT and "\x1b" not in err and "b\\x1b[2Jc" in err and "outside the grid" in err


@pytest.mark.parametrize("command", ["info", "run", "help"])
def test_a_closed_pipe_on_stdout_ends_quietly_with_the_commands_code(tmp_path, block_file, command):
    """The reader has gone before anything is printed (it is closed at once, the libraries
    take a second to load); a run's outputs are complete all the same."""
    out = tmp_path / "out"
    argv = {"info": ["info", block_file], "run": ["run", block_file, "--out", out, "--no-progress"],
            "help": ["--help"]}[command]
    process = cli_process(*argv, stdout=subprocess.PIPE)
    process.stdout.close()
    err = process.stderr.read().decode()
    assert process.wait(timeout=120) == cli.EXIT_DONE
    assert err == ""
    if command == "run":
        summary = json.loads((out / "summary.json").read_text())
        assert summary["status"] == "completed" and summary["steps"] == 20
        assert int(np.load(out / "final.npz")["step"]) == 20


@pytest.mark.parametrize("kind", ["fifo", "device", "large"])
def test_only_regular_files_of_at_most_16_mib_are_read(tmp_path, kind):
    """A FIFO would block the open for ever, /dev/zero would be read until memory runs
    out: both are refused at once (the process is bounded by a timeout)."""
    if kind == "fifo":
        scene = tmp_path / "scene.toml"
        os.mkfifo(scene)
    elif kind == "device":
        scene = Path("/dev/zero")
    else:
        scene = tmp_path / "scene.toml"
        with scene.open("wb") as handle:
            handle.truncate(16 * 2**20 + 1)  # sparse: no disk taken
    for argv in (["info", scene], ["run", scene, "--out", tmp_path / "out"]):
        process = cli_process(*argv)
        err = process.communicate(timeout=120)[1].decode()
        assert process.returncode == cli.EXIT_BAD_INPUT
        one_line_error(err, str(scene), {"fifo": "a FIFO", "device": "a character device", "large": "more than the 16777216"}[kind])
    assert not (tmp_path / "out").exists()


def test_a_resume_whose_summary_is_a_fifo_does_not_block(tmp_path, block_file):
    out = tmp_path / "out"
    assert cli_process("run", block_file, "--out", out, "--checkpoint-every", "5").wait(timeout=120) == 0
    (out / "summary.json").unlink()
    os.mkfifo(out / "summary.json")
    process = cli_process("resume", out, "--no-progress")
    err = process.communicate(timeout=120)[1].decode()
    # no status to read: it resumes from step 15 and ends; the FIFO is replaced by the summary
    assert process.returncode == cli.EXIT_DONE, err
    assert json.loads((out / "summary.json").read_text())["steps"] == 20


def killed_checkpoint(tmp_path, block_file, capsys) -> Path:
    """A run with checkpoints at steps 5, 10 and 15 whose summary says "running" (killed)."""
    out = tmp_path / "out"
    assert run_cli(["run", block_file, "--out", out, "--no-progress", "--checkpoint-every", "5"], capsys)[0] == 0
    summary = json.loads((out / "summary.json").read_text())
    (out / "summary.json").write_text(json.dumps({**summary, "status": "running"}))
    return out


@pytest.mark.parametrize("step", [float("inf"), float("nan"), 1e300, 2.5, True])
def test_a_checkpoint_step_that_is_no_whole_number_is_refused(tmp_path, capsys, block_file, step):
    out = killed_checkpoint(tmp_path, block_file, capsys)
    arrays, values = read_checkpoint(out / "checkpoint.npz")
    values["simulation"]["step"] = step
    write_checkpoint(out / "checkpoint.npz", arrays, {k: v for k, v in values.items() if k != "format"})
    before = snapshot(out)
    code, _, err = run_cli(["resume", out, "--no-progress"], capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, "does not fit", "step")
    assert snapshot(out) == before


def test_an_array_header_claiming_more_than_its_member_holds_is_refused(tmp_path, capsys, block_file):
    """A header of 10^12 doubles (8 TB) over the 16 of the file: refused without the
    allocation (the traced peak stays below a megabyte)."""
    import tracemalloc

    out = killed_checkpoint(tmp_path, block_file, capsys)
    path = out / "checkpoint.npz"
    with zipfile.ZipFile(path) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    header = {"descr": "<f8", "fortran_order": False, "shape": (10**12,)}
    import io
    forged = io.BytesIO()
    np.lib.format.write_array_header_1_0(forged, header)
    members["particles.mass.npy"] = forged.getvalue() + np.zeros(16).tobytes()
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    before = snapshot(out)
    tracemalloc.start()
    try:
        code, _, err = run_cli(["resume", out, "--no-progress"], capsys)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, "particles.mass.npy", "(1000000000000,)")
    assert peak < 1e6
    assert snapshot(out) == before


def test_overlaps_of_many_bodies_are_found_by_the_sweep_and_summarised(capsys):
    """4000 random squares: the sweep's pairs equal brute force's; the warning is one line
    naming the first 3 pairs and counting the rest."""
    rng = np.random.default_rng(7)
    lower = rng.uniform(0, 95, size=(4000, 2))
    lower[:10, 0] = 3.0  # equal left edges, and squares that only touch
    lower[10, 0] = lower[11, 0] + 4.0
    upper = lower + 4.0
    brute = (np.minimum(upper[:, None], upper[None]) > np.maximum(lower[:, None], lower[None])).all(axis=2)
    expected = np.argwhere(np.triu(brute, k=1))
    found = overlapping_pairs(lower, upper)
    np.testing.assert_array_equal(found, expected)

    class Body:
        def __init__(self, index):
            self.name, self.lower, self.upper = f"b{index}", tuple(lower[index]), tuple(upper[index])

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warn_of_overlaps([Body(i) for i in range(4000)])
    assert len(caught) == 1
    text = str(caught[0].message)
    i, j = expected[0]
    assert text.startswith(f"bodies 'b{i}' and 'b{j}' overlap in ")
    assert f"and {len(expected) - 3} more pairs" in text and text.count(" overlap in ") == 3


# -- messages ------------------------------------------------------------------------------------


def test_min_max_state_their_real_argument_limits():
    arguments = ", ".join(["x"] * 65)
    with pytest.raises(ExpressionError, match=r"max\(\) takes 2 to 64 arguments, got 65"):
        compile_expression(f"max({arguments})", ("x",))
    with pytest.raises(ExpressionError, match=r"sin\(\) takes 1 argument, got 2"):
        compile_expression("sin(x, x)", ("x",))
    assert compile_expression("max(" + ", ".join([f"x + {k}" for k in range(64)]) + ")", ("x",))(x=np.array([2.0]))[0] == 65.0


@pytest.mark.parametrize("text, expected", [
    ("(x < 1) - (x > 2)", [1.0, 1.0, 0.0, -1.0]), ("-(x < 1)", [-1.0, -1.0, 0.0, 0.0]),
    ("+(x <= 0)", [1.0, 0.0, 0.0, 0.0]), ("(x < 1 and x > 0) - 1", [-1.0, 0.0, -1.0, -1.0]),
    ("-(not (x < 1))", [0.0, 0.0, -1.0, -1.0]), ("(x < 1) * 2", [2.0, 2.0, 0.0, 0.0]),
    # booleans stay numpy's elsewhere: a node condition's logical or and and, as before
    ("(x <= 0) + (x >= 2)", [True, False, False, True]), ("(x <= 1) * (x >= 0.5)", [False, True, False, False]),
])
def test_comparisons_in_arithmetic_count_as_one_and_zero(text, expected):
    """numpy refuses ``-`` on booleans: these passed the scene's checks and stopped the run with
    a traceback when evaluated (a body force at its first step, the earlier outputs gone)."""
    value = compile_expression(text, ("x",))(x=np.array([0.0, 0.5, 1.5, 2.5]))
    assert value.dtype == (bool if isinstance(expected[0], bool) else float) and value.tolist() == expected


def test_constant_names_are_read_as_python_reads_the_expression():
    """Python reads identifiers in NFKC form: a constant "ℯ" was taken, then ignored for e, and
    "ｔ" for the variable t."""
    from femgrid_mpm.expressions import check_constants

    for constants, message in (({"ℯ": 5.0}, "constant 'ℯ' would hide the built-in 'e'"),
                               ({"ｔ": 5.0}, "constant 'ｔ' would hide the variable 't'"),
                               ({"w": 1.0, "ｗ": 2.0}, "constant 'ｗ' is the constant 'w' again")):
        with pytest.raises(ExpressionError, match=message):
            check_constants(constants, ("x", "t"))
    constants = check_constants({"ｗ": 5.0}, ("x",))
    assert compile_expression("ｗ + w", ("x",), constants=constants)(x=np.array([0.0]))[0] == 10.0


def test_a_body_force_of_comparisons_runs(block_scene):
    scene = block_scene(end=0.02).with_overrides(**{"loads": [
        {"kind": "body_force", "acceleration": ["(t < 1) - (t > 2)", "0"]}]})
    simulation = Simulation(scene)
    simulation.run()
    assert np.allclose(simulation.particles.v[:, 0] - scene.bodies[0].velocity[0], 0.02)


@pytest.mark.parametrize("value", ["[true, false]", "[\"0\", 0]"])
def test_grid_lower_of_booleans_or_strings_names_grid_lower(capsys, block_file, value):
    code, _, err = run_cli(["info", block_file, "--set", f"grid.lower={value}"], capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, "grid.lower[0]: must be a number")


def test_a_crushed_neo_hookean_body_stops_without_numpys_warning(tmp_path, capsys, block_file):
    """A block thrown at 20 m/s onto a clamped bottom with dt = 0.05 s: one step crushes
    its points (J < 0); the run stops on a state no longer finite, in one line."""
    scene = tmp_path / "crush.toml"
    scene.write_text(BLOCK.replace("velocity = [1.0, 0.25]", "velocity = [0.0, -20.0]")
                     .replace('material = { E', 'material = { model = "neo_hookean", E')
                     .replace("dt = 0.01", "dt = 0.05")
                     + '\n[solver]\nnegative_mass = "warn"\n\n[[supports]]\nwhere = "y <= 0.5"\nfix = ["x", "y"]\n')
    code, _, err = run_cli(["run", scene, "--out", tmp_path / "out", "--no-progress"], capsys)
    assert code == cli.EXIT_STOPPED
    assert "invalid value" not in err and "divide" not in err
    assert err.splitlines()[-1].startswith("femgrid-mpm: stopped: step 1 ")
    assert "no longer finite" in err


def test_numpy_values_as_overrides_are_lists_and_numbers():
    scene = bundled_scene("vibrating_bar")
    changed = scene.with_overrides(**{"grid.lower": np.array([0.0, 0.0]), "grid.spacing": np.array(0.25),
                                      "bodies.0.points_per_cell": np.int64(2)})
    assert changed.grid.lower == (0.0, 0.0) and changed.grid.spacing == 0.25 and changed.bodies[0].points_per_cell == 2
    with pytest.raises(SceneError, match=r"^with grid.lower = \[0.0, 0.0, 1.0\]: grid.lower: must have at most 2 item"):
        scene.with_overrides(**{"grid.lower": np.array([0.0, 0.0, 1.0])})


@pytest.mark.parametrize("value, words", [
    (None, "scene: must be a dict of the tables of a scene file, got NoneType"),
    ({"grid": 1}, "scene: grid: must be a table (got 1) (and 2 more problem(s))"),
    ({"grid": {"lower": [True, 0]}}, "scene: grid.lower[0]: must be a number"),
])
def test_the_python_api_refuses_in_one_scene_error_line(value, words):
    for attempt in (lambda: Scene.model_validate(value), lambda: Simulation(value)):
        with pytest.raises(SceneError) as error:
            attempt()
        assert str(error.value).startswith(words) and "\n" not in str(error.value)


def test_a_scene_built_directly_is_checked_as_a_file():
    """Scene(**tables) took pydantic's lax path: "1e4" for a modulus, true for points per cell,
    and a multi-line ValidationError for a table that is not one."""
    tables = bundled_scene("vibrating_bar").model_dump(mode="json", exclude_none=True)
    assert Scene(**tables) == bundled_scene("vibrating_bar")
    body = tables["bodies"][0]
    for changed, words in (({"bodies": [{**body, "material": {**body["material"], "E": "1e4"}}]},
                            'scene: bodies[0].material.E: must be a number (got "1e4")'),
                           ({"bodies": [{**body, "points_per_cell": True}]}, "scene: bodies[0].points_per_cell: must be"),
                           ({"grid": 1}, "scene: grid: must be a table (got 1)")):
        with pytest.raises(SceneError) as error:
            Scene(**{**tables, **changed})
        assert str(error.value).startswith(words) and "\n" not in str(error.value)


def test_a_scene_changed_by_model_copy_is_checked_by_the_simulation():
    """pydantic's model_copy(update=...) checks nothing: a step of -1 s (a dict where a table's
    model goes) ran into an AttributeError inside the simulation."""
    scene = bundled_scene("vibrating_bar")
    bad = scene.model_copy(update={"time": {"dt": -1, "end": 1.0}})
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # and pydantic's serializer warning is not shown
        with pytest.raises(SceneError, match=r"^scene: time.dt: must be greater than 0 or 'auto' \(got -1\)"):
            Simulation(bad)
    assert Scene.model_validate(scene) is scene
    loose = scene.model_copy(update={"time": scene.time.model_dump()})  # a valid table as a dict
    assert Simulation(loose).scene == scene and Simulation(loose).scene.time.dt == scene.time.dt


# -- signals -------------------------------------------------------------------------------------


def long_bar_run(out: Path) -> subprocess.Popen:
    """The vibrating bar for 100 s (33,334 steps, tens of seconds) with particle output."""
    return cli_process("run", VIBRATING_BAR, "--out", out, "--no-progress", "--set", "time.end=100",
                       "--set", "output.every=10", "--set", "output.particles=true")


def wait_for_records(process, out: Path, timeout=120.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert process.poll() is None, process.stderr.read().decode()
        energy = out / "energy.csv"
        if energy.exists() and len(energy.read_text().splitlines()) > 3:
            return
        time.sleep(0.05)
    raise AssertionError("no records in time")


def assert_interrupted_outputs(out: Path) -> dict:
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    final = np.load(out / "final.npz")
    assert int(final["step"]) == summary["steps"] > 0
    rows = (out / "energy.csv").read_text().splitlines()[1:]
    last_time = float(rows[-1].split(",")[0])
    assert last_time <= float(final["time"]) < last_time + 10 * 0.003 + 1e-9  # every record so far
    # the series has every record, but the one whose file was being written when the signal came
    assert (out / "particles.pvd").read_text().count("<DataSet ") in (len(rows) - 1, len(rows))
    return summary


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_sigterm_and_sighup_end_a_run_as_sigint_does(tmp_path, signum):
    out = tmp_path / "out"
    process = long_bar_run(out)
    try:
        wait_for_records(process, out)
        process.send_signal(signum)
        code = process.wait(timeout=120)
    finally:
        process.kill()
    assert code == 128 + signum == {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGHUP: 129}[signum]
    err = process.stderr.read().decode().splitlines()
    assert err[-1].startswith("femgrid-mpm: interrupted: at step ") and "Traceback" not in "".join(err)
    assert_interrupted_outputs(out)


def test_an_interrupted_run_ends_between_two_steps(tmp_path):
    """A signal in the middle of a step raised there: final.npz held the stresses of step N + 1
    with the positions of step N (4 of 14 SIGTERMs).  Now the step under way ends first: each
    array of final.npz is the state after its step, run again here."""
    from femgrid_mpm.scene import load_scene

    for trial in range(3):
        out = tmp_path / f"out{trial}"
        process = long_bar_run(out)
        try:
            wait_for_records(process, out)
            time.sleep(0.03 * trial)
            process.send_signal(signal.SIGTERM)
            assert process.wait(timeout=120) == 143
        finally:
            process.kill()
        final = np.load(out / "final.npz")
        simulation = Simulation(load_scene(out / "scene.toml"))
        for _ in range(int(final["step"])):
            simulation.advance()
        for name in ("x", "v", "stress", "strain", "volume"):
            assert np.array_equal(final[name], getattr(simulation.particles, name)), (trial, name)


def test_a_signal_waits_for_the_step_and_a_second_one_does_not():
    from femgrid_mpm.cli.signals import HANDLED, Interrupted, RunSignals

    handlers = {signum: signal.getsignal(signum) for signum in HANDLED}
    try:
        with RunSignals() as signals:
            signals.arm(at_step_ends=True)
            os.kill(os.getpid(), signal.SIGTERM)  # recorded: the step goes on
            with pytest.raises(Interrupted) as first:
                signals.step_ended()
            assert first.value.signum == signal.SIGTERM and not first.value.mid_step
        for signum, handler in handlers.items():  # the context leaves them ignored, as a command ends
            signal.signal(signum, handler)
        with RunSignals() as signals:
            signals.arm(at_step_ends=True)
            os.kill(os.getpid(), signal.SIGINT)
            with pytest.raises(Interrupted) as second:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(1)  # the handler runs between two bytecodes of this thread
            assert second.value.signum == signal.SIGINT and second.value.mid_step
        for signum, handler in handlers.items():
            signal.signal(signum, handler)
        with RunSignals() as signals:  # a step that does not end (a first compilation): STEP_WAIT at most
            signals.arm(at_step_ends=True)
            started = time.monotonic()
            with pytest.raises(Interrupted) as waited:
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(30)
            assert waited.value.mid_step and 1.9 < time.monotonic() - started < 10
    finally:
        for signum, handler in handlers.items():
            signal.signal(signum, handler)


def test_signals_during_the_shutdown_do_not_cut_it(tmp_path):
    """A burst of 30 SIGINTs and SIGTERMs 2 ms apart, from the first on: the first
    interrupts, the rest fall on the shutdown and are ignored; exit 130, files whole."""
    out = tmp_path / "out"
    process = long_bar_run(out)
    try:
        wait_for_records(process, out)
        for index in range(30):
            if process.poll() is not None:
                break
            process.send_signal(signal.SIGINT if index % 2 == 0 else signal.SIGTERM)
            time.sleep(0.002)
        code = process.wait(timeout=120)
    finally:
        process.kill()
    assert code == cli.EXIT_INTERRUPTED
    assert "Traceback" not in process.stderr.read().decode()
    assert_interrupted_outputs(out)


def test_a_resume_whose_particles_is_a_file_is_refused_before_writing(tmp_path, capsys, block_file):
    scene = tmp_path / "series.toml"
    scene.write_text(BLOCK.replace("every = 5", "every = 5\nparticles = true"))
    out = killed_checkpoint(tmp_path, scene, capsys)
    for stale in (out / "particles").iterdir():
        stale.unlink()
    (out / "particles").rmdir()
    (out / "particles").write_text("not a directory")
    before = snapshot(out)
    code, _, err = run_cli(["resume", out, "--no-progress"], capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, "particles: is not a directory")
    assert snapshot(out) == before
    # and a run into such a directory likewise
    code, _, err = run_cli(["run", scene, "--out", out, "--no-progress"], capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, "particles: is not a directory")
    assert snapshot(out) == before


def wait_for(path: Path, process, timeout=120.0) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        assert process.poll() is None and time.monotonic() < deadline, process.stderr.read().decode()
        time.sleep(0.05)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_end_a_reproduction_as_sigint_does(tmp_path, signum):
    """The cantilever's case runs for minutes: the signal falls inside it."""
    out = tmp_path / "paper"
    process = cli_process("reproduce", "--case", "cantilever", "--out", out)
    try:
        wait_for(out / "cantilever", process)
        time.sleep(1.0)
        process.send_signal(signum)
        code = process.wait(timeout=120)
    finally:
        process.kill()
    err = process.stderr.read().decode()
    assert code == 128 + signum, err
    assert "Traceback" not in err and "leaked" not in err
    name = signal.Signals(signum).name
    assert err.splitlines()[-1] == f"femgrid-mpm: interrupted: in case cantilever by {name}; no case finished"


def test_sigterm_ends_a_sweep_as_sigint_does(tmp_path):
    """Three runs of 1e6 steps of a block at rest (tens of seconds each), one worker: the
    signal comes while the first runs; exit 143, its line, nothing computed in runs.csv."""
    (tmp_path / "bar.toml").write_text(BLOCK.replace("end = 0.2", "end = 10000.0").replace("every = 5", "every = 100000")
                                       .replace("velocity = [1.0, 0.25]", "velocity = [0.0, 0.0]"))  # at rest
    sweep_file = tmp_path / "sweep.toml"
    sweep_file.write_text('scene = "bar.toml"\n[vary]\n"time.end" = [10000.0, 10001.0, 10002.0]\n')
    out = tmp_path / "out"
    process = cli_process("sweep", sweep_file, "--out", out, "--workers", "1", "--no-progress")
    try:
        wait_for(out / "sweep.toml", process)
        time.sleep(2.0)
        process.send_signal(signal.SIGTERM)
        code = process.wait(timeout=120)
    finally:
        process.kill()
    err = process.stderr.read().decode()
    assert code == cli.EXIT_TERMINATED == 143, err
    assert "Traceback" not in err and "leaked" not in err
    assert err.splitlines()[-1].startswith("femgrid-mpm: interrupted: ")
    runs = out / "runs.csv"
    assert not runs.exists() or "completed" not in runs.read_text()
    # no run ended: none is said to be kept (runs.csv, if written, is its header alone)
    assert "before any run was computed" in err.splitlines()[-1], err


@pytest.mark.parametrize("argv", [["--help"], ["sweep", "--help"], ["--version"]])
def test_help_on_a_full_device_is_exit_1_in_one_line(argv):
    with open("/dev/full", "w") as full:
        process = cli_process(*argv, stdout=full)
        err = process.communicate(timeout=120)[1].decode()
    assert process.returncode == cli.EXIT_WRITE_FAILED
    assert err.splitlines() == ["femgrid-mpm: error: cannot write to standard output: No space left on device"]


@pytest.mark.parametrize("value, name", [(3, "int"), (None, "NoneType"), (b"scene.toml", "bytes"),
                                         (bundled_scene("vibrating_bar"), "Scene")])
def test_load_scene_of_no_path_is_one_scene_error_line(value, name):
    from femgrid_mpm.scene import load_scene

    with pytest.raises(SceneError) as error:
        load_scene(value)
    assert str(error.value).startswith(f"load_scene: expected the path of a scene file (str or Path), got {name}")
    assert "\n" not in str(error.value)


def test_resume_of_a_file_says_it_is_a_file(capsys, block_file):
    code, _, err = run_cli(["resume", block_file], capsys)
    assert code == cli.EXIT_BAD_INPUT
    one_line_error(err, f"{block_file}: is a file, not a run's directory")


@pytest.mark.parametrize("setting, key", [("bodies.0.points_per_cell=1e300", "bodies[0].points_per_cell"),
                                          ("time.max_steps=1e30", "time.max_steps")])
def test_whole_numbers_beyond_64_bits_name_the_key_and_the_range(capsys, block_file, setting, key):
    code, _, err = run_cli(["info", block_file, "--set", setting], capsys)
    assert code == cli.EXIT_BAD_INPUT
    line = one_line_error(err, f"{key}: must be a whole number of at most 9.22e+18 (got ")
    assert "Unable to parse" not in line


def test_a_long_set_value_is_echoed_cut_short(capsys, block_file):
    """A 40,001-character expression and a 1000-item array: the line shows 80 characters
    and 16 items and says how long they were, not 40 kB."""
    expression = "x+" * 20000 + "1"
    code, _, err = run_cli(["info", block_file, "--set", f'bodies.0.velocity=["{expression}", "0"]',
                            "--set", f"grid.lower=[{', '.join(['1'] * 1000)}]"], capsys)
    assert code == cli.EXIT_BAD_INPUT
    line = one_line_error(err, f'bodies.0.velocity = ["{expression[:80]}..." (40001 characters), "0"]',
                          "grid.lower = [" + "1, " * 16 + "... (1000 items)]")
    assert len(line) < 600
