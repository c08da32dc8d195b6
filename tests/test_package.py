"""What ``import femgrid_mpm`` offers: the public names, the bundled scenes, and a cheap import."""

import subprocess
import sys

import pytest

import femgrid_mpm
from femgrid_mpm.scene import BUNDLED_SCENES, SceneError


def test_every_public_name_is_the_one_of_its_module():
    from femgrid_mpm import grid, scene, solver

    modules = {"Grid": grid, "Simulation": solver, "RunResult": solver}
    for name in femgrid_mpm.__all__:
        value = getattr(femgrid_mpm, name)
        if name != "__version__":
            assert value is getattr(modules.get(name, scene), name), name
    assert set(femgrid_mpm.__all__) <= set(dir(femgrid_mpm))
    with pytest.raises(AttributeError, match="has no attribute 'Grids'"):
        femgrid_mpm.Grids  # noqa: B018


def test_import_loads_no_numerical_library():
    """The command line imports the package before it can catch a Ctrl-C: numpy, scipy,
    scikit-fem and pydantic load on the first use of a public name, not at import."""
    code = ("import sys, femgrid_mpm; heavy = {'numpy', 'scipy', 'skfem', 'pydantic', 'numba', 'matplotlib'}; "
            "print(sorted(heavy & set(sys.modules)))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert loaded.strip() == "[]"


def test_bundled_scenes_are_the_files_shipped_and_each_loads():
    names = femgrid_mpm.bundled_scenes()
    assert names == sorted(path.stem for path in BUNDLED_SCENES.glob("*.toml"))
    assert {"vibrating_bar", "cantilever", "box_impact"} <= set(names)
    for name in names:
        assert femgrid_mpm.bundled_scene(name).title


@pytest.mark.parametrize("name", ["bar", "vibrating_bar.toml", "../scenes/vibrating_bar", ""])
def test_an_unknown_bundled_scene_is_one_line_naming_the_scenes(name):
    with pytest.raises(SceneError) as raised:
        femgrid_mpm.bundled_scene(name)
    message = str(raised.value)
    assert "\n" not in message
    assert message == f"no bundled scene {name!r} (bundled scenes: {', '.join(femgrid_mpm.bundled_scenes())})"
