"""``femgrid-mpm sweep`` and ``report`` against the reliability contract (docs/reliability.md):
inputs never written, absurd sweeps refused at once, one sweep at a time into a directory,
a damaged ``runs.csv`` named by file and line, stdout failures as ``run``'s, Dask quiet.

Each test states what the old behaviour was that it rules out (a file replaced, a
traceback, a false message); the reference is the file's bytes before and after, the
exit code and the one line of the contract.
"""

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from femgrid_mpm.sweep.directories import SweepLock, remove_stale

ROOT = Path(__file__).parents[1]
VIBRATING_BAR = ROOT / "scenes" / "vibrating_bar.toml"
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
CLI = [sys.executable, "-m", "femgrid_mpm.cli"]


def one_line_error(code, out, err, *parts):
    assert code == 2 and out == "", (code, out, err)
    assert len(err.strip().splitlines()) == 1, err
    for part in parts:
        assert part in err, err


# -- inputs are never outputs ---------------------------------------------------------


@pytest.mark.parametrize("name", ["runs.csv", "report.md", "work_precision.png"])
def test_a_directory_where_an_output_goes_is_refused_before_any_run(tmp_path, run_cli, name):
    """Old: the runs were computed, then writing the report failed with exit 1."""
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\n[vary]\n"grid.spacing" = [0.5]\n[set]\n"time.end" = 0.01\n')
    (tmp_path / "out" / name).mkdir(parents=True)
    one_line_error(*run_cli(["sweep", sweep, "--out", tmp_path / "out", "--workers", "1"]), f"{name}: is a directory")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [name]


@pytest.mark.parametrize("make", [lambda path: path.write_text("x"), lambda path: path.symlink_to(path.parent / "gone")])
def test_a_file_where_the_runs_directory_goes_is_refused_before_any_run(tmp_path, run_cli, make):
    """A file (or a dangling link) at ``DIR/runs``: the cluster was started and ``sweep.toml``
    written before ``mkdir`` failed, exit 1 ("File exists")."""
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\n[vary]\n"grid.spacing" = [0.5]\n[set]\n"time.end" = 0.01\n')
    (tmp_path / "out").mkdir()
    make(tmp_path / "out" / "runs")
    one_line_error(*run_cli(["sweep", sweep, "--out", tmp_path / "out", "--workers", "1"]),
                   f"{tmp_path / 'out' / 'runs'}: is not a directory")
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["runs"]


@pytest.mark.parametrize("name", ["runs.csv", "report.md", "report.html", "sweep.toml", "cost.png"])
def test_a_sweep_file_named_like_an_output_is_refused(tmp_path, run_cli, name):
    (tmp_path / "bar.toml").write_bytes(VIBRATING_BAR.read_bytes())
    sweep = tmp_path / name
    sweep.write_text('scene = "bar.toml"\n[vary]\n"grid.spacing" = [0.5]\n[set]\n"time.end" = 0.01\n')
    before = sweep.read_bytes()
    one_line_error(*run_cli(["sweep", sweep, "--out", tmp_path, "--workers", "1"]), "is the sweep file given")
    assert sweep.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == sorted(["bar.toml", name])


def test_a_scene_named_like_an_output_or_linked_to_one_is_refused(tmp_path, run_cli):
    out = tmp_path / "out"
    out.mkdir()
    scene = out / "report.md"
    scene.write_bytes(VIBRATING_BAR.read_bytes())
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{scene}"\n[vary]\n"grid.spacing" = [0.5]\n')
    one_line_error(*run_cli(["sweep", sweep, "--out", out]), "report.md is the sweep's scene file")
    # a hard link under another name: the same file
    linked = tmp_path / "scene.toml"
    scene.rename(linked)
    os.link(linked, out / "runs.csv")
    sweep.write_text(f'scene = "{linked}"\n[vary]\n"grid.spacing" = [0.5]\n')
    one_line_error(*run_cli(["sweep", sweep, "--out", out]), "runs.csv is the sweep's scene file")
    assert linked.read_bytes() == VIBRATING_BAR.read_bytes()


def test_a_scene_inside_a_run_directory_is_refused(tmp_path, run_cli):
    """Old: exit 0 and the scene deleted with the run directory it was in."""
    run = tmp_path / "out" / "runs" / "0.5"
    run.mkdir(parents=True)
    scene = run / "my.toml"
    scene.write_bytes(VIBRATING_BAR.read_bytes())
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{scene}"\n[vary]\n"grid.spacing" = [0.5]\n')
    one_line_error(*run_cli(["sweep", sweep, "--out", tmp_path / "out"]), "my.toml is the sweep's scene file")
    assert scene.read_bytes() == VIBRATING_BAR.read_bytes()


# -- absurd sweeps and files that are not read ----------------------------------------


def test_more_runs_than_max_runs_is_refused_before_planning(tmp_path, run_cli):
    """Old: 1e6 combinations planned (a scene loaded per combination) for minutes."""
    values = ", ".join(str(0.01 * (i + 1)) for i in range(1000))
    sweep = tmp_path / "big.toml"
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\n[vary]\n"grid.spacing" = [{values}]\n"time.end" = [{values}]\n')
    one_line_error(*run_cli(["sweep", sweep, "--out", tmp_path / "out"]),
                   "1000000 runs (1000 x 1000), more than max_runs = 10000")
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\nmax_runs = 2\n[vary]\n"grid.spacing" = [0.5, 0.25, 0.125]\n')
    one_line_error(*run_cli(["sweep", sweep, "--out", tmp_path / "out"]), "3 runs (3), more than max_runs = 2")
    assert not (tmp_path / "out").exists()


def test_run_keys_of_many_runs_are_those_of_few():
    """Thousands of runs whose slugs collide in pairs (``q2`` and ``Q2``): each named by its hash,
    as two are (run_keys counts the slugs once, not a scan per run)."""
    from femgrid_mpm.sweep.spec import run_keys

    combinations = [{"b": b, "n": n} for n in range(3000) for b in ("q2", "Q2")] + [{"b": "q1", "n": 0}]
    keys = run_keys(combinations)
    assert len(set(keys)) == len(keys) and keys[-1] == "q1-0"
    assert keys[2:4] == run_keys(combinations[2:4])
    assert all(re.fullmatch(rf"q2-{n}-[0-9a-f]{{8}}", k) for k, n in zip(keys[:-1], [n for n in range(3000) for _ in "ab"]))


@pytest.mark.parametrize("argument, problem", [("--workers=0", "must be from 1 to 256"),
                                               ("--workers=257", "must be from 1 to 256"),
                                               ("--scheduler=foo", "--scheduler: expected tcp://HOST:PORT"),
                                               ("--scheduler=http://x", "--scheduler: expected tcp://HOST:PORT"),
                                               ("--scheduler=tcp://host", "--scheduler: expected tcp://HOST:PORT"),
                                               ("--scheduler=tcp://host:99999", "--scheduler: expected tcp://HOST:PORT"),
                                               # the count of a local cluster went unused with --scheduler
                                               ("--workers=2 --scheduler=tcp://127.0.0.1:8786",
                                                "argument --scheduler: not allowed with argument --workers")])
def test_workers_and_scheduler_are_checked_at_once(tmp_path, run_cli, argument, problem):
    """Old: --workers 10000 started 10000 processes; --scheduler foo a traceback after 21 s."""
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\n[vary]\n"grid.spacing" = [0.5]\n')
    one_line_error(*run_cli(["sweep", sweep, "--out", tmp_path / "out", *argument.split()]), problem)
    assert not (tmp_path / "out").exists()


def test_a_sweep_file_or_scene_that_is_not_a_regular_file_is_refused_unread(tmp_path, run_cli):
    """Old: a FIFO blocked for ever, /dev/zero a MemoryError; a FIFO or a directory as the scene
    'no such scene file'."""
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)
    one_line_error(*run_cli(["sweep", fifo, "--out", tmp_path / "out"]), "is a FIFO")
    one_line_error(*run_cli(["sweep", "/dev/zero", "--out", tmp_path / "out"]), "is a character device")
    sweep = tmp_path / "sweep.toml"
    sweep.write_text('scene = "fifo.toml"\n')
    one_line_error(*run_cli(["sweep", sweep, "--out", tmp_path / "out"]), "scene:", "is a FIFO")
    (tmp_path / "folder.toml").mkdir()
    sweep.write_text('scene = "folder.toml"\n')
    one_line_error(*run_cli(["sweep", sweep, "--out", tmp_path / "out"]), "scene:", "is a directory")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("content, problem", [
    ('[vary]\n"bodies.0.points_per_cell" = [2]\n"bodies.00.points_per_cell" = [3]\n',
     'vary."bodies.00.points_per_cell": is the key vary."bodies.0.points_per_cell" spelled differently'),
    ('[vary]\n"bodies.0.points_per_cell" = [2, 4]\n[set]\n"bodies.00.points_per_cell" = 3\n',
     'set."bodies.00.points_per_cell": is the key vary."bodies.0.points_per_cell" spelled differently'),
    ('[vary]\n"grid.spacing" = [1, 0.5, 1.0]\n', 'vary."grid.spacing"[2]: 1.0 is already in the list (as 1)'),
])
def test_two_spellings_of_one_key_or_value_are_refused(tmp_path, run_cli, content, problem):
    """Old: exit 0, runs.csv showing 2 for a run of 3, a [set] value ignored, a run made twice."""
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\n{content}')
    one_line_error(*run_cli(["sweep", sweep, "--out", tmp_path / "out"]), problem)


# -- one sweep at a time ----------------------------------------------------------------


def test_a_second_sweep_into_a_locked_directory_is_refused(tmp_path, run_cli):
    """Old: two sweeps deleted each other's runs in progress and both failed with tracebacks."""
    out = tmp_path / "out"
    out.mkdir()
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\n[vary]\n"grid.spacing" = [0.5]\n')
    lock = SweepLock(out)
    lock.acquire()
    try:
        one_line_error(*run_cli(["sweep", sweep, "--out", out, "--workers", "1"]), f"another sweep is running in {out}")
    finally:
        lock.release()
    assert list(out.iterdir()) == []


def test_remove_stale_leaves_a_live_process_temporaries(tmp_path):
    finished = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead = int(finished.stdout)
    live = tmp_path / f".q1-0.5.{os.getpid()}.tmp"
    stale = tmp_path / f".q1-0.25.{dead}.tmp"
    old = tmp_path / f".q2-0.5.{dead}.old"
    for place in (live, stale, old):
        place.mkdir()
    remove_stale(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == [live.name]


def test_a_file_where_a_run_directory_goes_is_replaced_and_gone(tmp_path):
    """A stray file (or a link) at ``runs/<key>``: the finished run takes its place and no
    ``.KEY.PID.old`` is left (its removal took directories only); one a killed sweep left is removed."""
    from femgrid_mpm.sweep.directories import replace_directory

    runs = tmp_path / "runs"
    runs.mkdir()
    for name, make in (("q1-0.5", lambda path: path.write_text("stray")),
                       ("q1-0.25", lambda path: path.symlink_to(tmp_path / "nowhere"))):
        make(runs / name)
        source = runs / f".{name}.{os.getpid()}.tmp"
        source.mkdir()
        (source / "summary.json").write_text("{}")
        replace_directory(source, runs / name)
        assert (runs / name / "summary.json").read_text() == "{}"
    assert sorted(p.name for p in runs.iterdir()) == ["q1-0.25", "q1-0.5"]
    finished = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    (runs / f".q2-0.5.{int(finished.stdout)}.old").write_text("left by a killed sweep")
    remove_stale(runs)
    assert sorted(p.name for p in runs.iterdir()) == ["q1-0.25", "q1-0.5"]


# -- a finished sweep: Dask quiet, stdout failures, a damaged runs.csv ------------------


@pytest.fixture(scope="module")
def finished_sweep(tmp_path_factory):
    """One run, --workers 8 (capped at the one run missing), with port 8787 taken (Dask's
    default dashboard port: its warning was printed by every sweep)."""
    directory = tmp_path_factory.mktemp("finished")
    sweep = directory / "sweep.toml"
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\n[vary]\n"grid.spacing" = [0.5]\n[set]\n"time.end" = 0.03\n')
    taken = socket.socket()
    try:
        taken.bind(("", 8787))
        taken.listen()
    except OSError:
        pass  # taken already: the same condition
    try:
        result = subprocess.run([*CLI, "sweep", str(sweep), "--out", str(directory / "out"), "--workers", "8"],
                                cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=600)
    finally:
        taken.close()
    return sweep, directory / "out", result


def test_a_sweep_caps_its_workers_and_prints_nothing_of_dask(finished_sweep):
    _, _, result = finished_sweep
    assert result.returncode == 0, result.stderr
    assert "1 runs: 1 computed (1 at once), 0 reused, 0 failed" in result.stdout
    assert result.stderr == ""


@pytest.mark.parametrize("command", ["sweep", "report", "help"])
def test_a_full_or_closed_stdout(finished_sweep, command):
    """Old: an OSError or BrokenPipeError traceback; --help > /dev/full exit 0 silently."""
    sweep, out, _ = finished_sweep
    argv = {"sweep": ["sweep", str(sweep), "--out", str(out)], "report": ["report", str(out)],
            "help": ["sweep", "--help"]}[command]
    with open("/dev/full", "w") as full:
        result = subprocess.run([*CLI, *argv], cwd=ROOT, env=ENV, stdout=full, stderr=subprocess.PIPE, text=True,
                                timeout=300)
    assert result.returncode == 1
    assert result.stderr.splitlines() == ["femgrid-mpm: error: cannot write to standard output: No space left on device"]
    read, write = os.pipe()
    os.close(read)
    try:
        result = subprocess.run([*CLI, *argv], cwd=ROOT, env=ENV, stdout=write, stderr=subprocess.PIPE, text=True,
                                timeout=300)
    finally:
        os.close(write)
    assert result.returncode == 0 and result.stderr == ""
    assert (out / "report.md").is_file()


def damaged(out: Path, tmp_path: Path, change) -> Path:
    copy = tmp_path / "damaged"
    copy.mkdir()
    lines = (out / "runs.csv").read_text().splitlines()
    (copy / "runs.csv").write_bytes(change(lines))
    return copy


def replaced(column: str, value: str):
    def change(lines):
        header = lines[0].split(",")
        cells = lines[1].split(",")
        cells[header.index(column)] = value
        return "\n".join([lines[0], ",".join(cells)]).encode() + b"\n"
    return change


def test_a_runs_csv_saved_with_a_byte_order_mark_reads_as_without(finished_sweep, tmp_path):
    """A spreadsheet's "UTF-8 with BOM": the mark was read as part of the first varied key's name."""
    from femgrid_mpm.sweep.table import read_runs

    _, out, _ = finished_sweep
    copy = damaged(out, tmp_path, lambda lines: "\ufeff".encode() + "\n".join(lines).encode() + b"\n")
    assert read_runs(copy / "runs.csv") == read_runs(out / "runs.csv")
    assert read_runs(copy / "runs.csv")[0] == ["grid.spacing"]


@pytest.mark.parametrize("change, problem", [
    (lambda lines: "\n".join([lines[0], ",".join(lines[1].split(",")[:5])]).encode(), "line 2: has 5 fields, expected"),
    (lambda lines: "\n".join(lines).encode() + b"\n\xff\xfe,x\n", "line 3: not UTF-8 text"),
    (replaced("wall_time", "-1"), "line 2: wall_time: must be positive"),
    (replaced("wall_time", "0"), "line 2: wall_time: must be positive"),
    (replaced("wall_time", "nan"), "line 2: wall_time: must be finite"),
    (replaced("wall_time", "1e400"), "line 2: wall_time: must be finite"),
    (replaced("error_max", "inf"), "line 2: error_max: must be finite in a completed run"),
    (replaced("steps", "2.5"), "line 2: steps: must be a whole number"),
    (replaced("status", "done"), "line 2: status: 'done' is not one of"),
    (replaced("spacing", ""), "line 2: spacing: is empty"),
    (replaced("dt", ""), "line 2: dt: is empty"),
    (lambda lines: "\n".join([lines[0].replace("grid.spacing", "spacing", 1), *lines[1:]]).encode() + b"\n",
     "the column 'spacing' twice"),
])
def test_a_damaged_runs_csv_is_one_line_naming_file_and_line(finished_sweep, tmp_path, run_cli, change, problem):
    """Old: a row cut short gave exit 0 and a false 'the scene declares no [reference]';
    random bytes an error naming no file; a wall time of 0 matplotlib's warnings."""
    _, out, result = finished_sweep
    assert result.returncode == 0, result.stderr
    copy = damaged(out, tmp_path, change)
    one_line_error(*run_cli(["report", copy]), str(copy / "runs.csv"), problem)
    assert not (copy / "report.md").exists()


def test_a_failed_run_reads_without_a_time_step(finished_sweep, tmp_path):
    """A failed run's row has no time step (it never ran), but its spacing, its scene's."""
    from femgrid_mpm.sweep.table import read_runs

    _, out, _ = finished_sweep
    copy = damaged(out, tmp_path, lambda lines: replaced("dt", "")([lines[0], lines[1].replace(",completed,", ",failed,")]))
    _, rows = read_runs(copy / "runs.csv")
    assert rows[0]["status"] == "failed" and rows[0]["dt"] is None and rows[0]["spacing"] == 0.5


@pytest.mark.parametrize("field, value", [("reference", [1]), ("wall_time", "fast"), ("steps", True),
                                          ("consistent_mass", {"cg_iterations": "many"}), ("reason", 3)])
def test_a_damaged_summary_of_a_finished_run_is_computed_again(finished_sweep, tmp_path, field, value):
    """A finished run whose summary.json holds a field of the wrong type (edited by hand): not
    reused (its row was a traceback, or a runs.csv the report then refused), so computed again."""
    from femgrid_mpm.sweep.runner import MARKER_FILE, finished_summary
    from femgrid_mpm.sweep.spec import plan, read_sweep

    sweep, out, _ = finished_sweep
    planned = plan(read_sweep(sweep), sweep)[0]
    digest = json.loads((out / "runs" / planned.key / MARKER_FILE).read_text())["digest"]
    copy = tmp_path / planned.key
    shutil.copytree(out / "runs" / planned.key, copy)
    assert finished_summary(copy, digest) is not None
    summary = json.loads((copy / "summary.json").read_text())
    summary[field] = value
    (copy / "summary.json").write_text(json.dumps(summary))
    assert finished_summary(copy, digest) is None


# -- a signal to the terminal's process group -------------------------------------------


def spawned_children(pid: int) -> list[int]:
    """The processes ``pid`` started through multiprocessing (a local cluster's workers)."""
    found = []
    for entry in Path("/proc").iterdir():
        try:
            status = (entry / "status").read_text()
            command = (entry / "cmdline").read_bytes()
        except OSError:
            continue
        if f"\nPPid:\t{pid}\n" in status and b"spawn_main" in command:
            found.append(int(entry.name))
    return found


@pytest.mark.skipif(not Path("/proc/self/status").is_file(), reason="finds the workers through /proc")
@pytest.mark.parametrize("signum, code, moment", [(signal.SIGINT, 130, "workers starting"),
                                                  (signal.SIGINT, 130, "run under way"),
                                                  (signal.SIGHUP, 129, "run under way"),
                                                  (signal.SIGTERM, 143, "run under way")])
def test_a_signal_to_the_process_group_is_the_sweeps_one_line(tmp_path, signum, code, moment):
    """Ctrl-C (or a closed terminal) signals every process of the group, a local cluster's workers
    too: they leave it to the sweep, whose one line is all of stderr, whether the workers were
    starting or running; no temporary of a run cut short is left.  A SIGTERM ends the workers,
    and the cluster's logs of their lost connections stay off stderr."""
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\n[vary]\n"bodies.0.points_per_cell" = [2, 3, 4, 5]\n'
                     '[set]\n"time.end" = 2.0\n"grid.spacing" = 0.0625\n')
    out = tmp_path / "out"
    process = subprocess.Popen([*CLI, "sweep", str(sweep), "--out", str(out), "--workers", "2"], cwd=ROOT, env=ENV,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and process.poll() is None:
            if moment == "workers starting" and spawned_children(process.pid):
                break
            if moment == "run under way" and (out / "runs").is_dir() and any(
                    p.name.endswith(".tmp") for p in (out / "runs").iterdir()):
                break
            time.sleep(0.01)
        assert process.poll() is None, "the sweep ended before the signal (make its runs longer)"
        os.killpg(process.pid, signum)
        _, err = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    assert process.returncode == code, err
    assert len(err.splitlines()) == 1 and err.startswith("femgrid-mpm: interrupted: "), err
    # it says runs are kept only where a runs.csv keeps them (its header alone keeps none)
    kept = (out / "runs.csv").is_file() and len((out / "runs.csv").read_text().splitlines()) > 1
    assert ("the finished runs are kept in" in err) == kept, err
    if (out / "runs").is_dir():
        assert not [p.name for p in (out / "runs").iterdir() if p.name.startswith(".")]


def test_a_run_that_cannot_write_its_files_is_a_failed_write(tmp_path):
    """A run whose files do not fit (here a file-size limit, as a full disk) is a failed row, and
    the sweep's exit code is 1 (cannot write outputs), not 2 (bad input)."""
    import resource

    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\n[vary]\n"grid.spacing" = [0.0625]\n[set]\n"time.end" = 0.01\n')
    out = tmp_path / "out"
    limit = 500_000  # above runs.csv and the report of a failed run, below the run's final.npz (1.7 MB)
    result = subprocess.run([*CLI, "sweep", str(sweep), "--out", str(out), "--workers", "1"], cwd=ROOT, env=ENV,
                            capture_output=True, text=True, timeout=600,
                            preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit)))
    assert result.returncode == 1, result.stderr
    assert result.stderr.startswith(f"femgrid-mpm: error: cannot write the sweep's outputs in {out}: 1 run(s)")
    assert len(result.stderr.splitlines()) == 1, result.stderr
    (row,) = [line.split(",") for line in (out / "runs.csv").read_text().splitlines()[1:]]
    assert row[1] == "failed" and "File too large" in (out / "runs.csv").read_text()
    assert [p.name for p in (out / "runs").iterdir()] == []


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_a_scheduler_lost_midway_is_the_sweeps_lines_alone(tmp_path):
    """The scheduler of ``--scheduler`` killed while a run is under way: the runs not finished are
    failed rows (tried again by the next sweep) and stderr holds the sweep's line alone, none of
    the Dask client's logs of its reconnection (an ERROR with a traceback)."""
    address = f"tcp://127.0.0.1:{free_port()}"
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                  "--port", address.rsplit(":", 1)[1], "--dashboard-address", ":0"],
                                 env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
                               "--no-dashboard"], cwd=ROOT, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\n[vary]\n"bodies.0.points_per_cell" = [2, 3, 4]\n'
                     '[set]\n"time.end" = 2.0\n"grid.spacing" = 0.0625\n')
    out = tmp_path / "out"
    try:
        process = subprocess.Popen([*CLI, "sweep", str(sweep), "--out", str(out), "--scheduler", address], cwd=ROOT,
                                   env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and process.poll() is None:
            if (out / "runs").is_dir() and any(p.name.endswith(".tmp") for p in (out / "runs").iterdir()):
                break
            time.sleep(0.01)
        scheduler.kill()
        _, err = process.communicate(timeout=120)
    finally:
        for started in (scheduler, worker):
            started.kill()
            started.wait()
    assert len(err.splitlines()) == 1 and err.startswith("femgrid-mpm: error: "), err
    rows = (out / "runs.csv").read_text().splitlines()[1:]
    assert rows and all(",failed," in line and "scheduler" in line for line in rows if ",completed," not in line)


def test_dask_logs_during_the_cluster_close_stay_off_stderr(monkeypatch):
    """The local cluster's silence of Dask's logs ends inside its close, before the close has
    ended: a record then (a worker's lost connection after a SIGTERM) reached stderr."""
    import io
    import logging

    from dask.distributed import LocalCluster

    from femgrid_mpm.sweep.runner import _dask_client

    close = LocalCluster.close

    def close_and_log(self, *args, **kwargs):
        result = close(self, *args, **kwargs)
        logging.getLogger("distributed.batched").error("Batched Comm Closed")
        return result

    monkeypatch.setattr(LocalCluster, "close", close_and_log)
    stderr = io.StringIO()
    handler = logging.StreamHandler(stderr)  # as distributed's own handler on stderr
    logging.getLogger("distributed").addHandler(handler)
    try:
        with _dask_client(1, None):
            pass
    finally:
        logging.getLogger("distributed").removeHandler(handler)
    assert stderr.getvalue() == ""


@pytest.mark.parametrize("workers", [0, -1, 2.5, True])
def test_run_sweep_refuses_a_count_of_workers_that_is_not_one_or_more(tmp_path, workers):
    """``run_sweep(..., workers=-1)`` started a cluster of no worker and waited for ever; 0 ran on
    every core, where ``--workers 0`` is refused."""
    from femgrid_mpm.sweep import plan, read_sweep, run_sweep

    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\n[vary]\n"grid.spacing" = [0.5]\n[set]\n"time.end" = 0.03\n')
    with pytest.raises(ValueError, match=r"^workers: must be a whole number of at least 1"):
        run_sweep(plan(read_sweep(sweep), sweep), tmp_path / "out", workers=workers)
    assert not (tmp_path / "out").exists()


def test_a_run_whose_records_exceed_max_bytes_is_a_failed_row(tmp_path, run_cli):
    """``run`` refuses a scene whose records would exceed ``output.max_bytes`` (exit 2); the same run
    in a sweep wrote them all (a run of the sweep is the run ``run`` makes with the same keys)."""
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\nparticles = true\n[vary]\n"grid.spacing" = [0.5]\n[set]\n'
                     '"time.end" = 0.5\n"output.every" = 1\n"output.particles" = true\n"output.max_bytes" = 1000\n')
    code, _, err = run_cli(["run", VIBRATING_BAR, "--out", tmp_path / "single", "--set", "time.end=0.5",
                            "--set", "output.every=1", "--set", "output.particles=true", "--set", "output.max_bytes=1000",
                            "--set", "grid.spacing=0.5"])
    assert code == 2 and "more than output.max_bytes = 1e+03" in err
    code, out, err = run_cli(["sweep", sweep, "--out", tmp_path / "out", "--workers", "1"])
    assert code == 2 and "1 runs: 0 computed (1 at once), 0 reused, 1 failed" in out, err
    table = (tmp_path / "out" / "runs.csv").read_text()
    assert ",failed," in table and "more than output.max_bytes = 1e+03" in table
    assert list((tmp_path / "out" / "runs").iterdir()) == []


@pytest.mark.parametrize("name", ["summary.json", "sweep_run.json"])
def test_a_fifo_in_a_finished_runs_file_is_no_run_and_does_not_block(finished_sweep, tmp_path, name):
    """A FIFO in the place of a run's summary.json (or its digest) was opened for reading, and the
    sweep waited for a writer for ever; it is no finished run, as a summary that is not a regular
    file reads as no summary for ``resume``."""
    import threading

    from femgrid_mpm.sweep.runner import finished_summary

    _, out, _ = finished_sweep
    copy = tmp_path / "q"
    shutil.copytree(out / "runs" / "0.5", copy)
    (copy / name).unlink()
    os.mkfifo(copy / name)
    found = []
    reader = threading.Thread(target=lambda: found.append(finished_summary(copy, "any digest")), daemon=True)
    reader.start()
    reader.join(timeout=20)
    blocked = reader.is_alive()
    if blocked:  # let the blocked open end
        os.close(os.open(copy / name, os.O_WRONLY | os.O_NONBLOCK))
        reader.join(timeout=20)
    assert not blocked and found == [None]


def test_a_name_too_long_is_refused_before_any_run(tmp_path, run_cli):
    """``report`` of a directory named longer than the file system allows was a traceback; ``sweep``
    into a folder of such a name to make was exit 1 once its cluster had started (``run`` refuses
    both, exit 2)."""
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\n[vary]\n"grid.spacing" = [0.5]\n[set]\n"time.end" = 0.01\n')
    long = "a" * 300
    one_line_error(*run_cli(["report", tmp_path / long]), "cannot be used: File name too long")
    one_line_error(*run_cli(["sweep", sweep, "--out", tmp_path / "x" / long / "y", "--workers", "1"]),
                   "cannot be used: File name too long")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sweep.toml"]


def test_a_scheduler_without_workers_is_said_and_waited_for(tmp_path):
    """A scheduler with no worker: the sweep says so in one line and waits (it waited without a word)."""
    import select

    address = f"tcp://127.0.0.1:{free_port()}"
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                  "--port", address.rsplit(":", 1)[1], "--dashboard-address", ":0"],
                                 env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\n[vary]\n"grid.spacing" = [0.5]\n')
    process = subprocess.Popen([*CLI, "sweep", str(sweep), "--out", str(tmp_path / "out"), "--scheduler", address],
                               cwd=ROOT, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        ready, _, _ = select.select([process.stderr], [], [], 60)
        line = process.stderr.readline() if ready else ""
        assert process.poll() is None  # still waiting for a worker
    finally:
        for started in (process, scheduler):
            started.kill()
            started.wait()
    assert line == (f"femgrid-mpm: warning: the Dask scheduler at {address} has no workers yet: the runs wait "
                    "until one joins (dask worker ...)\n"), line


def test_a_run_whose_workers_died_names_the_likely_cause():
    """Dask's KilledWorker (every worker that ran the task ended) names the memory share and the
    remedy; any other failure keeps its type and message."""
    from types import SimpleNamespace

    from dask.distributed import KilledWorker

    from femgrid_mpm.sweep.table import run_failure

    died = run_failure(KilledWorker("femgrid-run-q1", SimpleNamespace(address="tcp://127.0.0.1:1"), 3))
    assert died.startswith("KilledWorker: each worker that ran it ended") and "fewer --workers" in died
    assert run_failure(ValueError("grid.spacing: too small")) == "ValueError: grid.spacing: too small"
    # on a --scheduler's workers --workers is refused: the remedy is theirs (dask worker --memory-limit)
    remote = run_failure(KilledWorker("femgrid-run-q1", SimpleNamespace(address="tcp://127.0.0.1:1"), 3), local=False)
    assert remote.startswith("KilledWorker: each worker that ran it ended") and "--workers" not in remote


@pytest.mark.parametrize("every, writes", [(1e9, 2), (0.0, 4)])
def test_runs_csv_is_written_at_most_once_a_table_interval_and_at_the_end(tmp_path, monkeypatch, every, writes):
    """runs.csv is rewritten whole: after every run it was quadratic in the runs.  Three runs:
    written at the start and the end only when the interval is long, after each run when it is 0;
    either way the table holds the three runs."""
    from femgrid_mpm.sweep import plan, read_sweep, run_sweep, runner

    calls = []
    write = runner.write_runs
    monkeypatch.setattr(runner, "write_runs", lambda *args: (calls.append(len(args[2])), write(*args)))
    monkeypatch.setattr(runner, "TABLE_EVERY", every)
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{VIBRATING_BAR}"\n[vary]\n"grid.spacing" = [0.5, 1.0, 0.25]\n[set]\n"time.end" = 0.03\n')
    run_sweep(plan(read_sweep(sweep), sweep), tmp_path / "out", workers=1)
    assert len(calls) == writes and calls[0] == 0 and calls[-1] == 3
    assert len((tmp_path / "out" / "runs.csv").read_text().splitlines()) == 4

