"""First use and ``reproduce``: the note that kernels are compiling, the progress over the
runs, and wall times taken with the kernels loaded."""

import os
import subprocess
import sys
import textwrap

import pytest

from femgrid_mpm.cli.progress import runs_bar
from femgrid_mpm.kernels import compiled
from femgrid_mpm.reproduce import PLANNED_RUNS, WARM_SCENES, box_impact, cantilever
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


def test_a_cold_cache_is_announced_once(tmp_path, cache_at, capsys):
    cache_at(tmp_path)  # empty: nothing compiled yet
    path = tmp_path / "bar.toml"
    path.write_text(helpers_scene_text())
    code, _, err = helpers.run_cli(["info", path], capsys)
    assert code == 0
    notes = [line for line in err.splitlines() if line.startswith("femgrid-mpm: note: compiling the numba kernels")]
    assert len(notes) == 1 and "only once" in notes[0] and str(tmp_path) in notes[0]
    code, _, err = helpers.run_cli(["info", path], capsys)  # the same process: said once
    assert "compiling" not in err


def test_a_warm_cache_says_nothing(tmp_path, cache_at, capsys):
    (tmp_path / "kernels").mkdir()
    (tmp_path / "kernels" / "g2p.local_g2p-59.py311.nbi").write_bytes(b"")
    cache_at(tmp_path)
    path = tmp_path / "bar.toml"
    path.write_text(helpers_scene_text())
    code, _, err = helpers.run_cli(["info", path], capsys)
    assert code == 0 and "compiling" not in err


def test_no_writable_cache_is_announced_as_compiling_every_time(cache_at):
    cache_at(None)
    assert compiled.note_compilation() is True


def helpers_scene_text() -> str:
    from importlib.resources import files

    return (files("femgrid_mpm") / "scenes" / "vibrating_bar.toml").read_text()


def test_the_runs_bar_counts_runs_on_a_terminal_only(capsys):
    assert runs_bar(3, enabled=False) == (None, None)
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
        scenes.append(scene)
        original(scene)

    scenes = []

    monkeypatch.setattr(timing, "warm_kernels", spy)
    with timing.following(labels.append):
        box_impact.run(tmp_path, contacts=("shared",))
    assert len(labels) == box_impact.planned_runs(("shared",)) == len(box_impact.BASES)
    assert warmed == [(basis, "shared") for basis in box_impact.BASES]
    assert labels[0] == f"box impact, {box_impact.BASES[0]} shared"
    # the scenes a cold cache compiles in parallel beforehand are these
    assert [s.model_dump() for s in box_impact.warm_scenes(("shared",))] == [s.model_dump() for s in scenes]


def test_the_planned_runs_of_every_case():
    assert set(PLANNED_RUNS) == {"vibrating_bar", "cantilever", "box_impact", "cost_accuracy"}
    assert PLANNED_RUNS["cost_accuracy"]() == 0  # its runs are on the sweep's workers
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


def test_every_case_lists_the_scenes_it_runs():
    """As many warm-up scenes as simulations (the sweeps' planned runs for cost_accuracy)."""
    from femgrid_mpm.reproduce.cost_accuracy import SWEEPS
    from femgrid_mpm.sweep import plan, read_sweep
    from femgrid_mpm.sweep.spec import BUNDLED_SWEEPS

    assert set(WARM_SCENES) == set(PLANNED_RUNS)
    for name in ("vibrating_bar", "cantilever", "box_impact"):
        assert len(WARM_SCENES[name]()) == PLANNED_RUNS[name]()
    planned = sum(len(plan(read_sweep(BUNDLED_SWEEPS / f"{n}.toml"), BUNDLED_SWEEPS / f"{n}.toml")) for n in SWEEPS)
    assert len(WARM_SCENES["cost_accuracy"]()) == planned
    assert {(s.grid.basis, s.solver.mass) for s in WARM_SCENES["vibrating_bar"]()} >= {("q1", "lumped"),
                                                                                     ("bspline3", "consistent")}


def test_one_warm_up_per_kernel_key_and_each_basis_in_one_process():
    bar = bundled_scene("vibrating_bar")
    scenes = [bar.with_overrides(**{"grid.basis": basis, "solver.mass": mass, "grid.spacing": spacing,
                                    "time.end": end})
              for basis in ("q1", "q2", "bspline3") for mass in ("lumped", "consistent")
              for spacing in (0.5, 0.25) for end in (1.0, 2.0)]
    assert timing.kernel_key(scenes[0]) == timing.kernel_key(scenes[3])  # spacing and end time apart
    assert timing.kernel_key(scenes[0]) != timing.kernel_key(scenes[4])  # the mass
    dealt = timing.shares(scenes)
    assert [[(s.grid.basis, s.solver.mass, s.grid.spacing, s.time.end) for s in share] for share in dealt] == \
        [[(b, m, 0.5, 1.0) for m in ("lumped", "consistent")] for b in ("q1", "q2", "bspline3")]
    assert timing.warm_in_parallel(scenes[:1], 2) == 1  # one basis: nothing to share


def test_kernels_compiled_in_parallel_load_in_a_fresh_process(tmp_path):
    """Two processes compile two bases' kernels into one empty cache at once (their shared
    helpers both); a fresh process then runs both scenes without compiling anything."""
    scenes = ("from femgrid_mpm.scene import bundled_scene\n"
              "scenes = [bundled_scene('vibrating_bar').with_overrides(**{'grid.basis': b}) for b in ('q1', 'q2')]\n")
    warm = scenes + textwrap.dedent("""
        from femgrid_mpm.reproduce.timing import warm_in_parallel
        if __name__ == "__main__":
            print(warm_in_parallel(scenes, 2))
        """)
    load = scenes + textwrap.dedent("""
        from numba.core import event
        from femgrid_mpm.reproduce.timing import warm_kernels
        compiled = []
        class Listener(event.Listener):
            def on_start(self, ev):
                compiled.append(ev.data["dispatcher"].py_func.__qualname__)
            def on_end(self, ev):
                pass
        event.register("numba:compile", Listener())
        for scene in scenes:
            warm_kernels(scene)
        print(len(compiled), compiled)
        """)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    for name, program in (("warm.py", warm), ("load.py", load)):
        (tmp_path / name).write_text(program)
    first = subprocess.run([sys.executable, str(tmp_path / "warm.py")], env=env, capture_output=True, text=True)
    assert first.returncode == 0 and first.stdout.split() == ["2"], first.stderr[-2000:]
    second = subprocess.run([sys.executable, str(tmp_path / "load.py")], env=env, capture_output=True, text=True)
    assert second.returncode == 0 and second.stdout.startswith("0 []"), second.stdout + second.stderr[-2000:]
