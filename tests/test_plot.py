"""``femgrid-mpm plot`` and the grid series (``[output] grid = true``).

The pictures are checked for their size and for not being blank (many colours,
pixels that vary); the animation for one frame per record; the grid series
against the points it was made from: its nodal masses sum to the points' mass
(the partition of unity), its momenta to their momentum, and its negative-mass
flag marks exactly the nodes of negative mass on a serendipity lumped run (where
the corner functions make them).  Bad directories and options are one line,
exit code 2, nothing written.
"""

import json
import shutil
from pathlib import Path

import meshio
import numpy as np
import pytest
from PIL import Image

from femgrid_mpm import cli
from femgrid_mpm.output import declared_observers, scene_to_toml
from helpers import block_scene

ROOT = Path(__file__).resolve().parent.parent
VIBRATING_BAR = ROOT / "scenes" / "vibrating_bar.toml"

#: records of the runs below: t = 0, every 5 steps of 20, and the end
RECORDS = 5


def run_block(tmp_path_factory, name, basis="serendipity", **output):
    """A block moving across a 4 x 3 grid for 20 steps (records every 5), deformed by a
    velocity that varies across it so that stresses and velocities differ between points
    (a step of 0.002 s: serendipity's negative masses make 0.01 s run away)."""
    directory = tmp_path_factory.mktemp(name)
    body = {"name": "block", "lower": [0.75, 0.5], "upper": [1.75, 1.5], "points_per_cell": 3,
            "velocity": ["1.0 + 0.5*y", "0.25 - 0.3*x"], "material": {"E": 1e4, "nu": 0.3, "density": 1e3}}
    scene = block_scene(basis=basis, dt=0.002, end=0.04, bodies=[body], output={"every": 5, **output})
    path = directory / "scene.toml"
    path.write_text(scene_to_toml(scene))
    out = directory / "run"
    assert cli.main(["run", str(path), "--out", str(out), "--no-progress"]) == cli.EXIT_DONE
    return out


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return run_block(tmp_path_factory, "plot", particles=True, grid=True)


def listing(directory):
    """Every file under ``directory`` (hidden ones too) with its bytes."""
    return {str(path.relative_to(directory)): path.read_bytes() for path in sorted(directory.rglob("*")) if path.is_file()}


def assert_not_blank(image):
    pixels = np.asarray(image.convert("RGB"), dtype=float)
    colours = len(np.unique(pixels.reshape(-1, 3), axis=0))
    assert colours > 50, colours  # text, lines, a colour bar and points: hundreds
    assert pixels.std() > 20, pixels.std()  # a white page is 0


def test_pictures_have_their_size_and_are_not_blank(run, tmp_path, run_cli):
    out = tmp_path / "pictures"
    code, stdout, err = run_cli(["plot", run, "--field", "stress_xx", "--record", "2", "--out", out])
    assert code == 0 and err == "", err
    assert stdout.splitlines() == [f"wrote {out / 'points.png'}", f"wrote {out / 'energy.png'}"]
    for name in ("points.png", "energy.png"):
        with Image.open(out / name) as image:
            assert image.size == (800, 600)
            assert_not_blank(image)


def test_default_writes_into_the_run_directory_and_each_field_draws(run, tmp_path, run_cli):
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    for field in ("velocity", "displacement_y", "stress_xy", "body"):
        code, _, err = run_cli(["plot", copy, "--field", field, "--only", "points"])
        assert code == 0 and err == "", (field, err)
        with Image.open(copy / "points.png") as image:
            assert image.size == (800, 600)
            assert_not_blank(image)


def test_body_colours_are_one_band_a_body():
    """Two bodies: two colours (tab10's first two), each band centred on its body's number."""
    from matplotlib import colormaps

    from femgrid_mpm.plotting.figures import _scale

    colours, low, high = _scale("body", np.array([0.0, 1.0, 1.0, 0.0]))
    assert colours.N == 2 and (low, high) == (-0.5, 1.5)
    for body in (0, 1):
        assert colours((body - low) / (high - low)) == colormaps["tab10"](body)
    eleven = _scale("body", np.arange(11.0))[0]
    assert eleven.N == 11 and eleven(1.0) == colormaps["tab10"](0)  # the eleventh takes the first's colour again


@pytest.mark.parametrize("number", [2**31 - 1, 1e300, np.inf, np.nan])
def test_an_edited_body_number_draws_the_bodies_it_has(run, tmp_path, run_cli, number):
    """An edited final state with a body number of 2**31 - 1 (or 1e300) built a colour map of as
    many colours (a hang), one of inf or NaN a traceback (exit 1); the colours are one a body
    of the scene (one block here), else of the points' numbers at most one a point."""
    from femgrid_mpm.plotting.figures import _body_count, _scale

    assert _scale("body", np.array([0.0, 1.0, number]))[0].N == (3 if np.isfinite(number) else 2)
    assert _body_count(np.array([0.0, 2.0, number]), 100) == (100 if np.isfinite(number) else 3)
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    shutil.rmtree(copy / "particles")
    (copy / "particles.pvd").unlink()
    final = dict(np.load(copy / "final.npz"))
    final["body"] = final["body"].astype(float)
    final["body"][0] = number
    np.savez(copy / "final.npz", **final)
    for scene in (True, False):
        if not scene:
            (copy / "scene.toml").unlink()
        code, _, err = run_cli(["plot", copy, "--field", "body", "--only", "points", "--out", tmp_path / f"{scene}.png"])
        assert code == 0, err
        assert_not_blank(Image.open(tmp_path / f"{scene}.png"))


def test_animation_has_one_frame_per_record(run, tmp_path, run_cli):
    target = tmp_path / "movie.gif"
    code, stdout, err = run_cli(["plot", run, "--animate", "--field", "velocity_x", "--out", target])
    assert code == 0 and err == "" and stdout.strip() == f"wrote {target} ({RECORDS} frames)"
    with Image.open(target) as image:
        assert image.size == (800, 600) and image.n_frames == RECORDS
        image.seek(RECORDS - 1)
        assert_not_blank(image)
    assert [path.name for path in tmp_path.iterdir()] == ["movie.gif"]  # no temporary left


def test_grid_series_sums_to_the_points_and_flags_negative_masses(run):
    final = np.load(run / "final.npz")
    total_mass = final["mass"].sum()
    collection = (run / "grid.pvd").read_text()
    files = sorted((run / "grid").iterdir())
    assert len(files) == RECORDS and all(f'file="grid/{path.name}"' in collection for path in files)
    assert [path.name for path in files] == [path.name.replace("particles", "grid") for path in sorted((run / "particles").iterdir())]
    negative_nodes = 0
    for path in files:
        mesh = meshio.read(path)
        data = mesh.point_data
        assert sorted(data) == ["mass", "momentum", "negative_mass", "velocity"]
        mass = data["mass"]
        assert len(mesh.points) == len(mass) == 51  # serendipity on 4 x 2 elements of 2 x 2 lattice cells (spacing 0.5 in 4 x 3)
        assert abs(mass.sum() - total_mass) <= 1e-12 * total_mass
        assert np.array_equal(data["negative_mass"].astype(bool), mass < 0)
        negative_nodes += int(np.count_nonzero(mass < 0))
        # lumped mass: the velocity is momentum / mass wherever a node carries mass
        carries = np.abs(mass) > 1e-6 * np.abs(mass).max()
        assert np.allclose(data["velocity"][carries] * mass[carries, None], data["momentum"][carries], rtol=1e-12, atol=0)
    assert negative_nodes > 0  # serendipity's corner functions: negative row sums at the block's corners
    last = meshio.read(files[-1]).point_data["momentum"][:, :2].sum(axis=0)
    points = (final["mass"][:, None] * final["v"]).sum(axis=0)
    assert np.allclose(last, points, rtol=1e-12, atol=1e-12 * np.abs(points).max())


def test_grid_series_costs_nothing_unasked_and_changes_no_result(run, tmp_path_factory):
    plain = run_block(tmp_path_factory, "plain", particles=True)
    assert not (plain / "grid.pvd").exists() and not (plain / "grid").exists()
    summary, with_grid = (json.loads((d / "summary.json").read_text()) for d in (plain, run))
    assert "grid" not in summary["effects"] and "grid" in with_grid["effects"]
    assert "grid.pvd" in with_grid["files"] and "grid.pvd" not in summary["files"]
    scene = block_scene(every=5)
    assert declared_observers(scene, plain) == []
    # observing the grid leaves every other output as it was, byte for byte
    for name in ["final.npz", "energy.csv", *(f"particles/{p.name}" for p in (run / "particles").iterdir())]:
        assert (plain / name).read_bytes() == (run / name).read_bytes(), name


def test_grid_series_is_resumed_from_a_checkpoint_to_the_same_bytes(tmp_path, run_cli):
    """The bar for 167 steps (records every 20), a checkpoint every 100; its directory made
    as a run killed after the checkpoint of step 100 leaves it (summary running, no final
    state, no collections, the records after step 100 gone), then resumed: every file of
    both series is the whole run's, byte for byte."""
    argv = ["run", VIBRATING_BAR, "--set", "time.end=0.5", "--set", "output.every=20", "--set", "output.particles=true",
            "--set", "output.grid=true", "--checkpoint-every", "100", "--no-progress"]
    full, killed = tmp_path / "full", tmp_path / "killed"
    assert run_cli([*argv, "--out", full])[0] == 0
    reference = listing(full)
    shutil.copytree(full, killed)
    summary = json.loads((killed / "summary.json").read_text())
    summary["status"] = "running"
    (killed / "summary.json").write_text(json.dumps(summary))
    for name in ["final.npz", "grid.pvd", "particles.pvd"] + [f"{series}/{series}_{step}.vtu" for series in ("grid", "particles")
                                                             for step in (120, 140, 160, 167)]:
        (killed / name).unlink()
    code, _, err = run_cli(["resume", killed, "--no-progress"])
    assert code == 0, err
    resumed = listing(killed)
    series = [name for name in reference if name.startswith(("grid", "particles"))]
    assert len([name for name in series if name.startswith("grid/")]) == 10  # steps 0, 20, ..., 160 and 167
    for name in series:
        assert resumed.get(name) == reference[name], name


def test_a_run_without_series_draws_its_final_state_and_a_stopped_run_draws(tmp_path_factory, tmp_path, run_cli, capsys):
    final_only = run_block(tmp_path_factory, "final")  # [output] with energy, no particle series
    capsys.readouterr()  # the run's warning of negative masses
    code, stdout, err = run_cli(["plot", final_only, "--field", "displacement", "--out", tmp_path / "a"])
    assert code == 0 and err == "" and len(stdout.splitlines()) == 2
    code, _, err = run_cli(["plot", final_only, "--record", "1", "--out", tmp_path / "b"])
    assert code == 2 and "--record 1" in err and "has 1 record" in err and not (tmp_path / "b").exists()
    code, _, err = run_cli(["plot", final_only, "--animate", "--out", tmp_path / "c"])
    assert code == 2 and "no particle series" in err and not (tmp_path / "c").exists()
    # serendipity's negative masses at 0.01 s: the energy runs away at step 9 and the run stops (exit 3)
    directory = tmp_path_factory.mktemp("stopped")
    body = {"name": "block", "lower": [0.75, 0.5], "upper": [1.75, 1.5], "points_per_cell": 3,
            "velocity": ["1.0 + 0.5*y", "0.25 - 0.3*x"], "material": {"E": 1e4, "nu": 0.3, "density": 1e3}}
    (directory / "scene.toml").write_text(scene_to_toml(block_scene(basis="serendipity", end=0.2, bodies=[body],
                                                                     output={"every": 2, "particles": True})))
    assert run_cli(["run", directory / "scene.toml", "--out", directory / "run", "--no-progress"])[0] == cli.EXIT_STOPPED
    code, _, err = run_cli(["plot", directory / "run"])
    assert code == 0 and err == ""
    for name in ("points.png", "energy.png"):
        with Image.open(directory / "run" / name) as image:
            assert image.size == (800, 600)
            assert_not_blank(image)


def damage(name):
    """A way to spoil a copy of a run: ``(path to give plot, words of the error)``."""

    def spoil(run, tmp_path):
        if name == "missing":
            return tmp_path / "nowhere", "no such directory"
        if name == "file":
            (tmp_path / "file").write_text("not a run")
            return tmp_path / "file", "is not a directory"
        if name == "empty":
            (tmp_path / "empty").mkdir()
            return tmp_path / "empty", "is not the directory of a run"
        copy = tmp_path / "run"
        shutil.copytree(run, copy)
        if name == "collection":
            (copy / "particles.pvd").write_text("<VTKFile><Collection><DataSet timestep=")
            return copy, "particles.pvd: is not a ParaView collection"
        if name == "points":
            path = copy / "particles" / "particles_20.vtu"
            path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
            return copy, "particles_20.vtu: is not a VTK particle file"
        if name == "listed":
            (copy / "particles" / "particles_20.vtu").unlink()
            return copy, "particles_20.vtu: is missing"
        if name == "energy":
            with (copy / "energy.csv").open("a") as handle:
                handle.write("0.5,1,2\n")
            return copy, "energy.csv: line 7"
        if name == "summary":
            (copy / "summary.json").write_text('{"status": ')
            return copy, "summary.json: is not valid JSON"
        if name == "scene":
            (copy / "scene.toml").write_text("[grid]\nlower = [0, 0]\n")
            return copy, "scene.toml: is not a scene"
        raise AssertionError(name)

    return spoil


def check_refused(run_cli, path, argv, words):
    """``plot`` refuses in one line with exit code 2 and writes nothing, anywhere."""
    places = [place for place in (path, path.parent) if place.is_dir()]
    before = [listing(place) for place in places]
    code, stdout, err = run_cli(["plot", path, *argv])
    assert code == cli.EXIT_BAD_INPUT, err
    assert stdout == "" and len(err.splitlines()) == 1 and err.startswith("femgrid-mpm: error: ")
    assert words in err, err
    assert [listing(place) for place in places] == before


@pytest.mark.parametrize("name", ["missing", "file", "empty", "collection", "points", "listed", "energy", "summary", "scene"])
def test_a_directory_that_is_not_a_run_is_one_line(run, tmp_path, run_cli, name):
    path, words = damage(name)(run, tmp_path)
    check_refused(run_cli, path, [], words)


@pytest.mark.parametrize("argv, words", [
    (["--field", "pressure"], "--field"),
    (["--record", "5"], "--record 5: the run in"),
    (["--record", "-1"], "--record"),
    (["--record", "first"], "--record"),
    (["--format", "gif"], "--format: is the format of an animation"),
    (["--fps", "5"], "--fps: is the frame rate of an animation: give it with --animate"),  # was taken and unused
    (["--out", "OUT/pictures.png"], "plot draws 2 pictures"),
    (["--only", "points", "--out", "OUT/points.gif"], "is a .png file"),
    (["--animate", "--format", "mp4"], "--format mp4: needs ffmpeg"),
    (["--animate", "--out", "OUT/movie.mp4"], "--format mp4: needs ffmpeg"),
    (["--animate", "--format", "gif", "--out", "OUT/movie.mp4"], "is written to a .gif file"),
    (["--animate", "--record", "2"], "--record: draws one record"),
    (["--animate", "--only", "points"], "--only"),
    (["--animate", "--fps", "0"], "--fps"),
])
def test_bad_options_are_one_line(run, tmp_path, run_cli, monkeypatch, argv, words):
    from matplotlib.animation import FFMpegWriter

    monkeypatch.setattr(FFMpegWriter, "isAvailable", classmethod(lambda cls: False))  # as on a machine without ffmpeg
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    check_refused(run_cli, copy, [item.replace("OUT", str(tmp_path / "out")) for item in argv], words)
    assert not (tmp_path / "out").exists()


def test_values_beyond_an_axis_are_left_out_and_no_points_refused(run, tmp_path, run_cli):
    """Edited files (a run writes neither): energies of 1e308 and a stop at t = 10**400 made
    matplotlib's axes overflow (tracebacks, exit 1); they are left out of the drawing.  A final
    state of no points (a reduction over nothing, exit 1) is refused in one line."""
    from femgrid_mpm.plotting.run_directory import frame_of

    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    lines = (copy / "energy.csv").read_text().splitlines()
    columns = len(lines[0].split(","))
    (copy / "energy.csv").write_text("\n".join([*lines, ",".join(["1e308"] * columns), ",".join(["-1e308"] * columns)]) + "\n")
    summary = json.loads((copy / "summary.json").read_text())
    (copy / "summary.json").write_text(json.dumps({**summary, "status": "stopped", "stop": {"time": 10**400, "reason": "x"}}))
    code, _, err = run_cli(["plot", copy, "--only", "energy", "--out", tmp_path / "energy.png"])
    assert code == 0, err
    assert (tmp_path / "energy.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(ValueError, match="0 positions"):
        frame_of(0.0, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    with pytest.raises(ValueError, match="5 velocities"):
        frame_of(0.0, np.zeros((6, 3)), np.zeros((5, 3)), np.zeros((6, 3)), np.zeros((6, 3)), np.zeros(6))


def test_a_position_that_is_not_finite_is_refused_in_one_line(run, tmp_path, run_cli):
    """An edited particle file with a position of inf (a run's guards stop before writing one):
    a cKDTree ValueError traceback, exit 1."""
    import meshio

    from femgrid_mpm.plotting.run_directory import frame_of

    with pytest.raises(ValueError, match=r"positions of shape \(2, 1\): not the points of a run"):
        frame_of(0.0, np.zeros((2, 1)), np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 3)), np.zeros(2))
    with pytest.raises(ValueError, match=r"point 1: a position that is not finite"):
        frame_of(0.0, np.array([[0.0, 0.0], [np.inf, 0.0]]), np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 3)),
                 np.zeros(2))
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    last = sorted((copy / "particles").glob("*.vtu"))[-1]
    mesh = meshio.read(last)
    mesh.points[0, 0] = np.inf
    meshio.write(last, mesh)
    check_refused(run_cli, copy, ["--out", str(tmp_path / "out")], "a position that is not finite")


def test_a_directory_where_a_picture_goes_is_refused_before_any_is_drawn(run, tmp_path, run_cli):
    """points.png was written, then energy.png failed on the directory in its place: exit 1
    (docs: exit 2, nothing written)."""
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    for picture in copy.glob("*.png"):
        picture.unlink()
    (copy / "energy.png").mkdir()
    check_refused(run_cli, copy, [], "energy.png: is a directory, where a picture goes")
    assert not (copy / "points.png").exists()
