"""First use and ``reproduce``: the note that kernels are compiling, the progress over the
runs, and wall times taken with the kernels loaded."""

from pathlib import Path

import pytest

from femgrid_mpm.cli.progress import runs_bar
from femgrid_mpm.kernels import compiled
from femgrid_mpm.reproduce import PLANNED_RUNS, box_impact, cantilever
from femgrid_mpm.reproduce import timing
from femgrid_mpm.scene import bundled_scene

import helpers


@pytest.fixture
def cache_at(monkeypatch):
    """Point the library's kernel cache at a directory, and forget that the note was given."""
    def point(directory):
        monkeypatch.setattr(compiled, "cache_directory", lambda root: directory)
        compiled.note_compilation.cache_clear()
    yield point
    compiled.note_compilation.cache_clear()


def compile_a_library_function(name: str):
    """numba compiles a function of the library's package (not cached: it compiles every time)."""
    import numba

    def function(x):
        return x + 1

    function.__module__, function.__qualname__ = f"femgrid_mpm.{name}", name
    return numba.njit(cache=False)(function)(1)


def test_a_cold_cache_is_announced_once_when_a_kernel_compiles(tmp_path, cache_at, caplog):
    cache_at(tmp_path)  # empty: nothing compiled yet
    with caplog.at_level("INFO", logger="femgrid_mpm"):
        compile_a_library_function("first")
        compile_a_library_function("second")  # the same process: said once
    notes = [record.getMessage() for record in caplog.records if "compiling the numba kernels" in record.getMessage()]
    assert len(notes) == 1 and "only once" in notes[0] and str(tmp_path) in notes[0]


def test_a_command_that_compiles_nothing_says_nothing(tmp_path, cache_at, capsys):
    """``info`` builds the simulation and estimates a lumped scene's step with no kernel: no note
    that kernels compile, even on a cold cache."""
    cache_at(tmp_path)
    path = tmp_path / "bar.toml"
    path.write_text(helpers_scene_text())
    code, _, err = helpers.run_cli(["info", path], capsys)
    assert code == 0 and "compiling" not in err


def test_a_warm_cache_says_nothing(tmp_path, cache_at, caplog):
    (tmp_path / "kernels").mkdir()
    (tmp_path / "kernels" / "g2p.local_g2p-59.py311.nbi").write_bytes(b"")
    cache_at(tmp_path)
    with caplog.at_level("INFO", logger="femgrid_mpm"):
        compile_a_library_function("warm")
    assert not any("compiling" in record.getMessage() for record in caplog.records)


def test_no_writable_cache_is_announced_as_compiling_every_time(cache_at):
    cache_at(None)
    assert compiled.note_compilation() is True


def helpers_scene_text() -> str:
    from importlib.resources import files

    return (files("femgrid_mpm") / "scenes" / "vibrating_bar.toml").read_text()


def test_the_runs_bar_counts_runs_on_a_terminal_and_in_lines_elsewhere(capsys, monkeypatch):
    import femgrid_mpm.cli.progress as progress

    monkeypatch.setattr(progress, "LINE_EVERY", 0.0)  # (60 s in a run: a line a minute at most)
    bar, line = runs_bar(3, enabled=False)
    assert bar is None
    line("first")
    assert capsys.readouterr().err == "  1 of 3 runs, 0 min (first)\n"
    monkeypatch.setattr(progress, "LINE_EVERY", 3600.0)
    bar, line = runs_bar(3, enabled=False)
    line("first")
    assert capsys.readouterr().err == ""
    bar, count = runs_bar(3, enabled=True)
    count("first")
    count("second")
    assert bar.n == 2 and bar.total == 3
    bar.close()
    err = capsys.readouterr().err
    assert "2/3 runs" in err and "second" in err


def test_each_case_run_is_counted_and_warmed_first(tmp_path, monkeypatch):
    """The box impact (shortened) makes the runs it plans, each after one warm-up step of
    its own scene (same basis and contact, a 1e-12 s step)."""
    monkeypatch.setattr(box_impact, "END", 0.02)
    warmed, labels = [], []
    original = timing.warm_kernels

    def spy(scene):
        warmed.append((scene.grid.basis, scene.contact.kind))
        original(scene)

    monkeypatch.setattr(timing, "warm_kernels", spy)
    with timing.following(labels.append):
        box_impact.run(tmp_path, contacts=("shared",))
    assert len(labels) == box_impact.planned_runs(("shared",)) == len(box_impact.BASES)
    assert warmed == [(basis, "shared") for basis in box_impact.BASES]
    assert labels[0] == f"box impact, {box_impact.BASES[0]} shared"


def test_the_planned_runs_of_every_case():
    assert set(PLANNED_RUNS) == {"vibrating_bar", "cantilever", "box_impact", "cost_accuracy"}
    # its runs are on the sweeps' workers, each counted as it ends (below): those the sweeps plan
    from femgrid_mpm.reproduce import cost_accuracy
    from femgrid_mpm.sweep import plan, read_sweep
    from femgrid_mpm.sweep.spec import BUNDLED_SWEEPS

    paths = [BUNDLED_SWEEPS / f"{name}.toml" for name in cost_accuracy.SWEEPS]
    assert PLANNED_RUNS["cost_accuracy"]() == sum(len(plan(read_sweep(path), path)) for path in paths) > 500
    assert PLANNED_RUNS["vibrating_bar"]() == 15
    # both protocols for every basis, the large rotation's three, one resolution per mass for the
    # resolution study's bases
    bases, studied = len(cantilever.BASES), len(cantilever.RESOLUTION_BASES)
    assert PLANNED_RUNS["cantilever"]() == 2 * bases + 3 + 2 * studied
    assert PLANNED_RUNS["cantilever"](resolutions=(0.5, 0.25)) == 2 * bases + 3 + 4 * studied


def test_the_warm_up_takes_one_tiny_step(monkeypatch):
    steps = []
    original = timing.Simulation.run

    def counting(self, *args, **kwargs):
        result = original(self, *args, **kwargs)
        steps.append((self.step_index, self.time))
        return result

    monkeypatch.setattr(timing.Simulation, "run", counting)
    timing.warm_kernels(bundled_scene("vibrating_bar"))
    assert steps == [(1, timing.WARM_STEP)]


def test_a_note_during_a_progress_bar_has_a_line_of_its_own(monkeypatch):
    """The kernels compile in the first step, after the run's bar is drawn: the note clears the
    bar's line first (it was written after the bar's text) and the bar is drawn again below."""
    import io

    from femgrid_mpm.cli.parser import say

    err = io.StringIO()
    monkeypatch.setattr("sys.stderr", err)
    bar, count = runs_bar(10, enabled=True)
    count("bar q1")
    say("note", "compiling the numba kernels")
    before, after = err.getvalue().split("femgrid-mpm: note: compiling the numba kernels\n")
    bar.close()
    assert "runs" in before and before.endswith("\r") and "1/10" in after


def test_the_cost_accuracy_sweeps_count_each_run_for_the_progress(tmp_path):
    """The study's sweeps run on Dask's workers: each run that ends is told to the followers
    (the command line's count stood still for its ~12 minutes), and on a second call the
    reused runs at once."""
    from femgrid_mpm.reproduce.cost_accuracy import SweepFollower
    from femgrid_mpm.sweep import plan, read_sweep, run_sweep

    sweep = tmp_path / "tiny.toml"
    bar = Path(__file__).resolve().parents[1] / "scenes" / "vibrating_bar.toml"
    sweep.write_text(f'scene = "{bar}"\n[vary]\n"grid.spacing" = [0.5, 1.0]\n[set]\n"time.end" = 0.03\n')
    labels = []
    with timing.following(labels.append):
        for _ in range(2):
            run_sweep(plan(read_sweep(sweep), sweep), tmp_path / "out", workers=1, progress=SweepFollower("tiny"))
    assert sorted(labels[:2]) == ["tiny, 0.5", "tiny, 1.0"], labels  # the runs' keys
    assert labels[2:] == ["tiny, reused"] * 2

