"""Scene files: every kind of bad input is refused with one line naming the file
and the key (exit code 2, no traceback, nothing written), expressions from
scene files are safe, and a scene written back to TOML loads to an equal scene.

Bad input is checked through ``femgrid_mpm.cli.main`` (in process, stderr
captured), as a user meets it.
"""

import tomllib
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from femgrid_mpm import cli
from femgrid_mpm.output import scene_to_toml
from femgrid_mpm.scene import Scene, SceneError, bundled_scene, load_scene
from helpers import run_cli

#: a small valid scene; each case below changes one thing
BASE = """\
title = "Block"

[grid]
basis = "q1"
lower = [0.0, 0.0]
upper = [4.0, 3.0]
spacing = 0.5

[time]
dt = 0.01
end = 0.05

[solver]
mass = "lumped"

[[bodies]]
name = "block"
lower = [0.75, 0.5]
upper = [1.75, 1.5]
points_per_cell = 2
velocity = ["0.1*cos(pi*x/5)", "0"]
material = { model = "linear_elastic", E = 1.0e4, nu = 0.3, density = 1.0e3, plane = "strain" }
"""


def replaced(old, new):
    assert old in BASE, old
    return BASE.replace(old, new, 1)


def appended(text):
    return BASE + "\n" + text


#: (id, scene text, key the message must name, words it must contain)
BAD_SCENES = [
    # unknown keys, at every level
    ("unknown top-level key", "titel = 'x'\n" + BASE, "titel", "did you mean 'title'"),
    ("unknown grid key", replaced("spacing = 0.5", "spaceing = 0.5"), "grid.spaceing", "did you mean 'spacing'"),
    ("unknown material key", replaced("plane = \"strain\"", "plane = \"strain\", G = 1"), "bodies[0].material.G", "unknown key"),
    ("unknown load key", appended("[[loads]]\nkind = 'gravity'\nacceleration = [0, -1]\nstrength = 2"), "loads[0].strength", "unknown key"),
    ("unknown table", appended("[boundary]\nwhere = 'x <= 0'"), "boundary", "unknown key"),
    # wrong types
    ("string for a number", replaced("spacing = 0.5", "spacing = \"half\""), "grid.spacing", "must be a number"),
    ("modulus beyond any material", replaced("E = 1.0e4", "E = 1.0e308"), "bodies[0].material.E",
     "less than or equal to 1e+30"),
    ("density beyond any material", replaced("density = 1.0e3", "density = 1.0e-300"), "bodies[0].material.density",
     "greater than or equal to 1e-30"),
    ("steps beyond the limit", replaced("dt = 0.01", "dt = 1e-300"), "time.dt", "5e+298 steps, more than the limit"),
    ("point load outside the grid", appended("[[loads]]\nkind = \"point\"\nbody = \"block\"\nat = [1e300, 1e300]\n"
                                             "force = [1.0, 0.0]"), "loads[0].at", "lies outside the grid"),
    ("friction of a shared field", appended("[contact]\nkind = \"shared\"\nfriction = 0.3"), "contact.friction",
     "applies to kind = 'frictional' only"),
    # these raised OverflowError while counting the nodes
    ("vanishing spacing", replaced("spacing = 0.5", "spacing = 1e-300"), "grid.spacing", "outside the supported range"),
    ("huge spacing", replaced("spacing = 0.5", "spacing = 1e300"), "grid.spacing", "outside the supported range"),
    ("huge extent", replaced("upper = [4.0, 3.0]", "upper = [1e308, 3.0]"), "grid.upper", "outside the supported range"),
    ("numeric string for a number", replaced("spacing = 0.5", "spacing = \"0.5\""), "grid.spacing", "must be a number"),
    ("boolean for a number", replaced("end = 0.05", "end = true"), "time.end", "must be a number"),
    ("fraction for a count", replaced("points_per_cell = 2", "points_per_cell = 2.5"), "bodies[0].points_per_cell", "whole number"),
    ("number for a boolean", appended("[output]\nparticles = 1"), "output.particles", "true or false"),
    ("table for an array of tables", replaced("[[bodies]]", "[bodies]"), "bodies", "must be an array"),
    ("number for a table", replaced('material = { model = "linear_elastic", E = 1.0e4, nu = 0.3, density = 1.0e3, plane = "strain" }', "material = 3"),
     "bodies[0].material", "must be a table"),
    ("short pair", replaced("lower = [0.0, 0.0]", "lower = [0.0]"), "grid.lower[1]", "too short"),
    ("long pair", replaced('velocity = ["0.1*cos(pi*x/5)", "0"]', 'velocity = ["0", "0", "0"]'), "bodies[0].velocity", "at most 2"),
    ("missing key", replaced("spacing = 0.5\n", ""), "grid.spacing", "required key is missing"),
    # material
    ("E = 0", replaced("E = 1.0e4", "E = 0"), "bodies[0].material.E", "greater than 0"),
    ("E < 0", replaced("E = 1.0e4", "E = -5.0"), "bodies[0].material.E", "greater than 0"),
    ("nu = 0.5", replaced("nu = 0.3", "nu = 0.5"), "bodies[0].material.nu", "less than 0.5"),
    ("nu = -1", replaced("nu = 0.3", "nu = -1.0"), "bodies[0].material.nu", "greater than -1"),
    ("density = 0", replaced("density = 1.0e3", "density = 0.0"), "bodies[0].material.density",
     "greater than or equal to 1e-30"),
    ("unknown material model", replaced('model = "linear_elastic"', 'model = "rubber"'), "bodies[0].material.model", "rubber"),
    # grid and bodies
    ("spacing = 0", replaced("spacing = 0.5", "spacing = 0.0"), "grid.spacing", "greater than 0"),
    ("spacing < 0", replaced("spacing = 0.5", "spacing = -0.5"), "grid.spacing", "greater than 0"),
    ("body outside the grid", replaced("upper = [1.75, 1.5]", "upper = [4.5, 1.5]"), "bodies[0]", "outside the grid"),
    ("body with no points", replaced("upper = [1.75, 1.5]", "upper = [0.75, 1.5]"), "bodies[0]", "has no points"),
    ("zero points per cell", replaced("points_per_cell = 2", "points_per_cell = 0"), "bodies[0].points_per_cell", "greater than 0"),
    ("duplicate body names", appended("[[bodies]]\nname = 'block'\nlower = [2, 2]\nupper = [3, 3]\nmaterial = { E = 1.0, nu = 0.0, density = 1.0 }"),
     "bodies[1].name", "already the name"),
    ("grid upper below lower", replaced("upper = [4.0, 3.0]", "upper = [-4.0, 3.0]"), "grid", "must exceed lower"),
    # time
    ("dt = 0", replaced("dt = 0.01", "dt = 0.0"), "time.dt", "greater than 0 or 'auto'"),
    ("dt < 0", replaced("dt = 0.01", "dt = -0.01"), "time.dt", "greater than 0"),
    ("dt a word", replaced("dt = 0.01", "dt = \"fast\""), "time.dt", "'auto'"),
    ("end = 0", replaced("end = 0.05", "end = 0.0"), "time.end", "greater than 0"),
    ("end < 0", replaced("end = 0.05", "end = -1.0"), "time.end", "greater than 0"),
    # kinds
    ("unknown basis", replaced('basis = "q1"', 'basis = "q3"'), "grid.basis", "\"q3\""),
    ("unknown mass kind", replaced('mass = "lumped"', 'mass = "diagonal"'), "solver.mass", "\"diagonal\""),
    ("unknown negative-mass policy", replaced('mass = "lumped"', 'mass = "lumped"\nnegative_mass = "ignore"'), "solver.negative_mass", "ignore"),
    ("unknown linear solver", replaced('mass = "lumped"', 'mass = "consistent"\nlinear_solver = "lu"'), "solver.linear_solver", "'auto', 'direct' or 'cg'"),
    ("zero CG tolerance", replaced('mass = "lumped"', 'mass = "consistent"\ncg_tolerance = 0'), "solver.cg_tolerance", "greater than 0"),
    ("unknown load kind", appended("[[loads]]\nkind = 'magnetic'"), "loads[0].kind", "unknown kind \"magnetic\""),
    ("load without kind", appended("[[loads]]\nacceleration = [0, -1]"), "loads[0].kind", "required key is missing"),
    ("unknown damping kind", appended("[damping]\nkind = 'rayleigh'\ncoefficient = 1.0"), "damping.kind", "rayleigh"),
    ("negative damping", appended("[damping]\nkind = 'mass'\ncoefficient = -1.0"), "damping.coefficient", "greater than or equal to 0"),
    ("unknown contact kind", appended("[contact]\nkind = 'sticky'"), "contact.kind", "'shared' or 'frictional'"),
    ("negative friction", appended("[contact]\nkind = 'frictional'\nfriction = -0.1"), "contact.friction", "greater than or equal to 0"),
    ("frictional contact with consistent mass", appended("[contact]\nkind = 'frictional'").replace('mass = "lumped"', 'mass = "consistent"'),
     "contact.kind", "needs solver.mass"),
    ("unknown support component", appended("[[supports]]\nwhere = 'x <= 0'\nfix = ['z']"), "supports[0].fix[0]", "'x' or 'y'"),
    ("zero output interval", appended("[output]\nevery = 0"), "output.every", "greater than 0"),
    # loads on bodies that do not exist
    ("load on a missing body", appended("[[loads]]\nkind = 'point'\nbody = 'beam'\nat = [1, 1]\nforce = [0, -1]"),
     "loads[0].body", "no body named 'beam'"),
    ("negative ramp", appended("[[loads]]\nkind = 'point'\nbody = 'block'\nat = [1, 1]\nforce = [0, -1]\nramp = -1.0"),
     "loads[0].ramp", "greater than or equal to 0"),
    # NaN and infinities
    ("NaN modulus", replaced("E = 1.0e4", "E = nan"), "bodies[0].material.E", "finite"),
    ("infinite end", replaced("end = 0.05", "end = inf"), "time.end", "finite"),
    ("infinite corner", replaced("lower = [0.0, 0.0]", "lower = [-inf, 0.0]"), "grid.lower[0]", "finite"),
    ("NaN gravity", appended("[[loads]]\nkind = 'gravity'\nacceleration = [0, nan]"), "loads[0].acceleration[1]", "finite"),
    ("NaN velocity", replaced('velocity = ["0.1*cos(pi*x/5)", "0"]', 'velocity = [nan, 0.0]'), "bodies[0].velocity[0]", "finite"),
    # sizes that cannot fit in memory, refused before anything is allocated
    ("too many nodes", replaced("spacing = 0.5", "spacing = 1e-5"), "grid.spacing", "more than the limit of 1e+08"),
    ("too many points", replaced("points_per_cell = 2", "points_per_cell = 20000"), "bodies[0].points_per_cell", "more than the limit of 1e+08"),
    # counted in int64 these wrapped to counts under the limit: 0 points, a traceback, the earlier outputs gone
    ("points near 2**63", replaced("points_per_cell = 2", "points_per_cell = 9223372036854775807"),
     "bodies[0].points_per_cell", "would have 3.4e+38 points"),
    ("points per cell past 64 bits", replaced("points_per_cell = 2", "points_per_cell = 99999999999999999999"),
     "bodies[0].points_per_cell", "must be less than or equal to 9223372036854775807"),
    ("points of 1e9 per cell", replaced("points_per_cell = 2", "points_per_cell = 3000000000"),
     "bodies[0].points_per_cell", "more than the limit of 1e+08"),
    # unsafe or malformed expressions
    ("attribute access", replaced('"0.1*cos(pi*x/5)"', '"x.__class__"'), "bodies[0].velocity", "attribute access is not allowed"),
    ("import", replaced('"0.1*cos(pi*x/5)"', "\"__import__('os')\""), "bodies[0].velocity", "'__import__' is not allowed"),
    ("method call", replaced('"0.1*cos(pi*x/5)"', "\"__import__('os').getcwd()\""), "bodies[0].velocity", "attribute access is not allowed"),
    ("other call", replaced('"0.1*cos(pi*x/5)"', '"open(0)"'), "bodies[0].velocity", "'open' is not allowed"),
    ("lambda", replaced('"0.1*cos(pi*x/5)"', '"(lambda: 1)()"'), "bodies[0].velocity", "not allowed"),
    ("subscript", replaced('"0.1*cos(pi*x/5)"', '"x[0]"'), "bodies[0].velocity", "indexing is not allowed"),
    ("dunder name", replaced('"0.1*cos(pi*x/5)"', '"__builtins__"'), "bodies[0].velocity", "'__builtins__' is not allowed"),
    ("time in a velocity", replaced('"0.1*cos(pi*x/5)"', '"t"'), "bodies[0].velocity", "'t' is not allowed"),
    ("syntax error", replaced('"0.1*cos(pi*x/5)"', '"0.1*"'), "bodies[0].velocity", "cannot parse"),
    # Python's recursion would end near 500 levels: a 500-term sum is refused, not a RecursionError
    ("deeply nested", replaced('"0.1*cos(pi*x/5)"', '"' + "x" + "+x" * 499 + '"'), "bodies[0].velocity",
     "nests more than 100 deep"),
    ("constant too large for a float", replaced('"0.1*cos(pi*x/5)"', '"1' + "0" * 400 + '"'), "bodies[0].velocity",
     "too large for a float"),
    ("unsafe support", appended("[[supports]]\nwhere = \"x.real <= 0\""), "supports[0].where", "attribute access is not allowed"),
    ("string constant", appended("[[supports]]\nwhere = \"'a' < 'b'\""), "supports[0].where", "not allowed"),
    # the file itself
    ("malformed TOML", replaced("end = 0.05", "end = 0.05.1"), "", "not valid TOML"),
    ("unterminated table", replaced("[time]", "[time"), "", "not valid TOML"),
]

#: problems found only once the simulation is built (supports, auto time step, initial velocities)
BAD_BUILDS = [
    ("support selecting no node", appended("[[supports]]\nwhere = 'x < -100'"), "supports[0].where", "selects no grid node"),
    # q2 consistent mass on a block that ends inside elements is singular: no stable step
    ("auto dt without a stable step",
     replaced("dt = 0.01", 'dt = "auto"').replace('basis = "q1"', 'basis = "q2"').replace('mass = "lumped"', 'mass = "consistent"'),
     "time.dt", "no stable time step"),
    ("NaN initial velocity", replaced('"0.1*cos(pi*x/5)"', '"sqrt(-1 - x)"'), "bodies[0].velocity", "NaN or infinity at 16 point(s)"),
    ("infinite initial velocity", replaced('"0.1*cos(pi*x/5)"', '"1/(x - x)"'), "bodies[0].velocity", "NaN or infinity"),
    # arithmetic on literals follows IEEE too (it raised ZeroDivisionError and OverflowError)
    ("division of literals by zero", replaced('"0.1*cos(pi*x/5)"', '"1/0"'), "bodies[0].velocity", "NaN or infinity"),
    ("remainder of literals by zero", replaced('"0.1*cos(pi*x/5)"', '"max(x, 1 % 0)"'), "bodies[0].velocity",
     "NaN or infinity"),
    ("power of literals overflowing", replaced('"0.1*cos(pi*x/5)"', '"10**400"'), "bodies[0].velocity",
     "NaN or infinity"),
    ("real power of a negative literal", replaced('"0.1*cos(pi*x/5)"', '"(-1)**0.5"'), "bodies[0].velocity",
     "NaN or infinity"),
]


def assert_one_line_error(err, *needles):
    assert "Traceback" not in err
    # the note of a first compilation (a cold cache: the kernels the checks of dt = "auto" call)
    lines = [line for line in err.splitlines() if not line.startswith("femgrid-mpm: note: compiling")]
    assert len(lines) == 1, err
    assert lines[0].startswith("femgrid-mpm: error: "), err
    for needle in needles:
        assert needle in lines[0], (needle, err)


@pytest.mark.parametrize("command", ["info", "run"])
@pytest.mark.parametrize("name, text, key, words", BAD_SCENES + BAD_BUILDS, ids=[c[0] for c in BAD_SCENES + BAD_BUILDS])
def test_bad_scene_is_one_line_naming_file_and_key(tmp_path, capsys, command, name, text, key, words):
    """Exit code 2, one line ``femgrid-mpm: error: FILE: KEY: problem``, and for
    ``run`` an output directory that stays untouched."""
    path = tmp_path / "scene.toml"
    path.write_text(text)
    out = tmp_path / "out"
    out.mkdir()
    (out / "energy.csv").write_text("from an earlier run\n")
    argv = ["info", path] if command == "info" else ["run", path, "--out", out, "--no-progress"]
    code, stdout, err = run_cli(argv, capsys)
    assert code == cli.EXIT_BAD_INPUT
    assert stdout == ""
    assert_one_line_error(err, f"{path}: {key}", words)
    # nothing already written is lost, nothing new is written
    assert sorted(p.name for p in out.iterdir()) == ["energy.csv"]
    assert (out / "energy.csv").read_text() == "from an earlier run\n"


def test_the_base_scene_is_valid(tmp_path, capsys):
    """The cases above each break a scene that is otherwise fine."""
    path = tmp_path / "scene.toml"
    path.write_text(BASE)
    code, stdout, err = run_cli(["info", path], capsys)
    assert code == 0 and err == ""
    assert "points:" in stdout


@pytest.mark.parametrize(
    "path_kind, words",
    [("missing", "no such scene file"), ("directory", "is a directory"), ("binary", "cannot be read: 'utf-8' codec")],
)
def test_unreadable_scene_files(tmp_path, capsys, path_kind, words):
    path = tmp_path / "scene.toml"
    if path_kind == "directory":
        path.mkdir()
    elif path_kind == "binary":
        path.write_bytes(b"\xff\xfe\x00 = 1")
    code, _, err = run_cli(["info", path], capsys)
    assert code == cli.EXIT_BAD_INPUT
    assert_one_line_error(err, str(path), words)


def test_unsafe_expression_runs_no_code(tmp_path, capsys):
    """An expression that would create a file if it were evaluated is refused
    before anything is evaluated: the file does not appear."""
    marker = tmp_path / "pwned"
    payload = f"__import__('pathlib').Path('{marker}').touch()"
    path = tmp_path / "scene.toml"
    path.write_text(replaced('"0.1*cos(pi*x/5)"', f'"{payload}"'))
    code, _, err = run_cli(["run", path, "--out", tmp_path / "out", "--no-progress"], capsys)
    assert code == cli.EXIT_BAD_INPUT
    assert_one_line_error(err, "bodies[0].velocity", "not allowed")
    assert not marker.exists()
    assert not (tmp_path / "out").exists()


def test_size_limits_are_checked_before_allocating(tmp_path, capsys):
    """1.6e11 points would need ~10 TB; the refusal allocates less than 5 MB
    (numpy reports its array memory to tracemalloc)."""
    path = tmp_path / "scene.toml"
    path.write_text(replaced("points_per_cell = 2", "points_per_cell = 200000"))
    cli.main(["info", str(path)])  # first call: imports, so they do not count below
    capsys.readouterr()
    tracemalloc.start()
    try:
        code = cli.main(["info", str(path)])
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert code == cli.EXIT_BAD_INPUT
    assert_one_line_error(capsys.readouterr().err, "bodies[0].points_per_cell", "1.6e+11 points")
    assert peak < 5e6


def test_scene_expressions_give_the_initial_velocity(tmp_path):
    """``velocity = ["0.1*cos(pi*x/5)", "0.02*y"]`` evaluated at the seeded
    points, against numpy at the same points (to 1e-15 m/s)."""
    from femgrid_mpm.solver import Simulation

    path = tmp_path / "scene.toml"
    path.write_text(replaced('"0"]', '"0.02*y - min(x, 1) + max(abs(x - 1), sqrt(exp(log(2))))"]'))
    simulation = Simulation(load_scene(path))
    x, y = simulation.particles.x.T
    np.testing.assert_allclose(simulation.particles.v[:, 0], 0.1 * np.cos(np.pi * x / 5), rtol=0, atol=1e-15)
    expected = 0.02 * y - np.minimum(x, 1) + np.maximum(np.abs(x - 1), np.sqrt(2.0))
    np.testing.assert_allclose(simulation.particles.v[:, 1], expected, rtol=0, atol=1e-15)


def test_overrides_are_validated_like_the_file(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(BASE)
    scene = load_scene(path, {"grid.basis": "bspline3", "bodies.0.points_per_cell": 3, "output.every": 2})
    assert (scene.grid.basis, scene.bodies[0].points_per_cell, scene.output.every) == ("bspline3", 3, 2)
    with pytest.raises(SceneError, match=r"\(with time\.end = -1\): time\.end: must be greater than 0"):
        load_scene(path, {"time.end": -1})
    with pytest.raises(SceneError, match=r"grid\.spacing: must be a number \(got \"0\.5\"\)"):
        load_scene(path, {"grid.spacing": "0.5"})
    with pytest.raises(SceneError, match=r"bodies\.4\.name: no such key to set"):
        load_scene(path, {"bodies.4.name": "x"})


def full_scene() -> Scene:
    """A scene that declares every table and kind of entry."""
    return Scene.model_validate(
        {
            # an astral character (JSON escapes it as a surrogate pair, which TOML refuses) and a control one
            "title": 'Everything "quoted" \\ once, 😀 \x01 and \x7f',
            "grid": {"basis": "q2", "lower": [-1, 0], "upper": [4, 3], "spacing": 0.25},
            "time": {"dt": "auto", "end": 0.5, "safety": 0.4},
            "solver": {"mass": "consistent", "negative_mass": "warn", "consistent_fallback": "blend", "blend": 0.2},
            "bodies": [
                {"name": "a", "lower": [0, 0], "upper": [1, 1], "velocity": ["sin(x)", 0.5],
                 "material": {"E": 2e5, "nu": 0.25, "density": 7.8e3, "plane": "stress"}},
                {"name": "b c", "lower": [2, 0], "upper": [3, 1], "points_per_cell": 3,
                 "material": {"E": 1e4, "nu": -0.2, "density": 1e3}},
            ],
            "supports": [{"where": "x <= 0 and y < 1e-9", "fix": ["y"]}],
            "loads": [
                {"kind": "point", "body": "b c", "at": [3, 1], "force": [0, -1e-3], "ramp": 0.1, "model": "paper_eq35"},
                {"kind": "gravity", "acceleration": [0, -9.81]},
            ],
            "damping": {"kind": "mass", "coefficient": 0.5},
            "contact": {"kind": "shared"},
            "output": {"every": 3, "particles": True},
        }
    )


@pytest.mark.parametrize("scene", [full_scene(), bundled_scene("vibrating_bar")], ids=["full", "vibrating_bar"])
def test_scene_written_as_toml_loads_back_equal(tmp_path, scene):
    # the header names the scene file, whose name may hold anything a path can
    text = scene_to_toml(scene, header="a header\nof two lines\nfrom /tmp/a\x1b\rb😀.toml")
    assert text.startswith("# a header\n# of two lines\n# from /tmp/a\\u001b\\u000db😀.toml\n")
    assert Scene.model_validate(tomllib.loads(text)) == scene
    path = tmp_path / "scene.toml"
    path.write_text(text)
    assert load_scene(path) == scene  # the strict loader accepts it too: every type as TOML spells it


def test_bundled_scene_is_the_paper_setup():
    """scenes/vibrating_bar.toml: the paper's section 4 bar (a 5 x 1 bar in a 7 x 1
    grid, spacing 0.5, 3 x 3 points per cell, dt 0.003, t = 8)."""
    scene = bundled_scene("vibrating_bar")
    assert scene.grid.upper == (7.0, 1.0) and scene.grid.spacing == 0.5
    assert scene.bodies[0].upper == (5.0, 1.0) and scene.bodies[0].points_per_cell == 3
    assert (scene.time.dt, scene.time.end) == (0.003, 8.0)


BUNDLED = sorted((Path(__file__).parents[1] / "femgrid_mpm" / "scenes").glob("*.toml"))


@pytest.mark.parametrize("path", BUNDLED, ids=[p.stem for p in BUNDLED])
def test_bundled_scenes_pass_info_with_a_stable_time_step(path, capsys):
    """Every shipped scene loads under the strict loader, builds, and has dt
    within the estimated critical step (no warning on stderr)."""
    code, stdout, err = run_cli(["info", path], capsys)
    assert code == 0 and err == ""
    assert load_scene(path).title in stdout


@pytest.mark.parametrize("changes, words", [
    ({"grid.spaceing": 1.0}, "grid.spaceing: unknown key (did you mean 'spacing'?)"),
    ({"grid.spacing": "0.5"}, 'grid.spacing: must be a number (got "0.5")'),  # a file refuses it; so does the API
    ({"bodies.0.points_per_cell": True}, "bodies[0].points_per_cell: must be a number (got true)"),
    ({"bodies.-1.name": "a"}, "bodies.-1.name: no such key to set"),  # no Python negative indexing
])
def test_overrides_from_python_are_checked_like_a_file(changes, words):
    """``Scene.with_overrides`` raises one-line SceneErrors naming the key (it raised
    pydantic's multi-line ValidationError and took wrong types a file may not hold)."""
    with pytest.raises(SceneError) as raised:
        bundled_scene("vibrating_bar").with_overrides(**changes)
    message = str(raised.value)
    assert "\n" not in message and words in message


def test_overrides_take_numpy_numbers():
    """numpy scalars are numbers (``np.int64(2)`` was "must be a number")."""
    scene = bundled_scene("vibrating_bar").with_overrides(**{"bodies.0.points_per_cell": np.int64(2),
                                                             "time.dt": np.float64(0.001)})
    assert scene.bodies[0].points_per_cell == 2 and scene.time.dt == 0.001
    path = Path(__file__).parents[1] / "scenes" / "vibrating_bar.toml"
    assert load_scene(path, {"bodies.0.points_per_cell": np.int64(4)}).bodies[0].points_per_cell == 4
    with pytest.raises(SceneError, match="overrides must be a dict"):
        load_scene(path, [("time.end", 1.0)])


def test_simulation_refuses_a_non_finite_initial_velocity():
    """Through the Python API too (the command line refused it, ``Simulation`` did not)."""
    from femgrid_mpm.solver import Simulation

    scene = bundled_scene("vibrating_bar").with_overrides(**{"bodies.0.velocity": ["0", "sqrt(2.5 - x)"]})
    # NaN right of x = 2.5: 15 of the 30 columns of 6 points (3 x 3 per cell of 0.5 m; the bar is 5 x 1 m)
    with pytest.raises(ValueError, match=r"bodies\[0\]\.velocity: gives NaN or infinity at 90 point\(s\)"):
        Simulation(scene)


@pytest.mark.parametrize("speed", [1e160, 1e153, 1e152])
def test_an_initial_velocity_of_infinite_kinetic_energy_is_refused(tmp_path, capsys, speed):
    """The bar (5 x 1 m, 1e3 kg/m^3) at ``speed cos(pi x / 5)``: 1/2 m v^2 about 1250 speed^2
    J/m.  Beyond 1e308 (1e160, 1e153 m/s) it ran to its end with exit 0 (dt = 1e-170 s),
    every row of energy.csv infinite, energy_drift "nan" and no runaway bound: refused, nothing
    written.  Below (1e152 m/s, 1.25e307 J/m) it runs, its energy finite."""
    refused = 1250.0 * speed * speed > 1e308  # the reference, within a factor far from 1
    path = tmp_path / "fast.toml"
    path.write_text((Path(__file__).parents[1] / "femgrid_mpm" / "scenes" / "vibrating_bar.toml").read_text())
    out = tmp_path / "out"
    code, _, err = run_cli(["run", path, "--out", out, "--set", f'bodies.0.velocity=["{speed:g}*cos(pi*x/5)", "0"]',
                            "--set", "time.dt=1e-170", "--set", "time.end=1e-169"], capsys)
    if refused:
        assert code == cli.EXIT_BAD_INPUT and not out.exists() and len(err.splitlines()) == 1
        assert err.startswith("femgrid-mpm: error: ") and err.rstrip().endswith(
            "bodies[0].velocity: a kinetic energy beyond 1e308 J/m, the most at (0.0833333, 0.0833333) (are the "
            "velocity, the density and the sizes in the same units?)")
    else:
        assert code == cli.EXIT_DONE
        energy = np.loadtxt(out / "energy.csv", delimiter=",", skiprows=1, ndmin=2)
        assert np.isfinite(energy).all()
        assert energy[0, 1] == pytest.approx(1250.0 * speed * speed, rel=0.01)  # sum of cos^2 over the points: 1/2


def test_overlapping_bodies_are_warned_of(tmp_path, capsys):
    """Two bodies over the same space double its mass: allowed (it may be meant), but a
    one-line warning names them and the overlap; apart, there is none."""
    second = '\n[[bodies]]\nname = "other"\nlower = [LOWER, 0.5]\nupper = [3.0, 1.5]\npoints_per_cell = 2\n' \
             'material = { E = 1.0e4, nu = 0.3, density = 1.0e3 }\n'
    for lower, warned in (("1.25", True), ("1.75", False)):
        path = tmp_path / f"scene_{lower}.toml"
        path.write_text(BASE + second.replace("LOWER", lower))
        code, _, err = run_cli(["info", path], capsys)
        assert code == cli.EXIT_DONE
        lines = [line for line in err.splitlines() if "overlap" in line]
        if warned:
            assert lines == ["femgrid-mpm: warning: bodies 'block' and 'other' overlap in [1.25, 0.5] to [1.75, 1.5]: "
                             "their points fill the same space (mass counted twice there)"]
        else:
            assert lines == []
