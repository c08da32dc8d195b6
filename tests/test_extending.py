"""The worked examples of docs/extending.md, run from the page itself.

A new basis: the page's file and registry line, added to a copy of the package,
must make a working basis (the linear B-spline reproduces q1 on the vibrating
bar to 1e-12, with both engines).  A new effect: the page shows the library's
own ``body_force`` file and registry line verbatim, and the effect run alone
gives its exact result.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import femgrid_mpm
from femgrid_mpm.scene import Scene
from femgrid_mpm.solver import Simulation

PAGE = Path(__file__).parents[1] / "docs" / "extending.md"
PACKAGE = Path(femgrid_mpm.__file__).parent


def code_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", PAGE.read_text(), flags=re.S)


def block_containing(text: str) -> str:
    (block,) = [block for block in code_blocks() if text in block]
    return block


BAR = """
import json, sys
import numpy as np
import pytest
from femgrid_mpm.scene import bundled_scene
from femgrid_mpm.solver import Simulation
from femgrid_mpm.bases import BASES
out = {"registered": sorted(BASES)}
for engine in ("scipy", "numba"):
    runs = {}
    for basis in ("q1", "bspline1"):
        scene = bundled_scene("vibrating_bar").with_overrides(**{
            "grid.basis": basis, "time.end": 0.3, "solver.engine": engine})
        result = Simulation(scene).run()
        runs[basis] = result.particles
    q1, new = runs["q1"], runs["bspline1"]
    out[engine] = {"x": float(np.abs(new.x - q1.x).max()), "v": float(np.abs(new.v - q1.v).max()),
                   "stress": float(np.abs(new.stress - q1.stress).max() / np.abs(q1.stress).max()),
                   "moved": float(np.abs(q1.x - q1.x0).max())}
print(json.dumps(out))
"""


def test_a_new_basis_is_one_file_and_its_registry_line(tmp_path):
    """The page's linear B-splines, added to a copy of the package as one file and the
    registry line, run the vibrating bar (100 steps) with q1's positions and velocities
    to 1e-12 (they are q1's functions; the tolerance allows the rounding of their
    monomial fit) and stresses to 1e-9 relative (stresses integrate gradients over the
    steps)."""
    copy = tmp_path / "femgrid_mpm"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    source = block_containing("# femgrid_mpm/bases/bspline1.py")
    (copy / "bases" / "bspline1.py").write_text(source)
    registry = block_containing("BASES[BSPLINE1.name] = BSPLINE1")
    with (copy / "bases" / "__init__.py").open("a") as init:
        init.write("\n" + registry)
    env = dict(os.environ, PYTHONPATH=str(tmp_path), OPENBLAS_NUM_THREADS="1")
    env.pop("NUMBA_CACHE_DIR", None)
    # from the copy's folder: `python -c` puts the working directory before PYTHONPATH
    done = subprocess.run([sys.executable, "-c", BAR], env=env, cwd=tmp_path, capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout.splitlines()[-1])
    assert "bspline1" in out["registered"]
    for engine in ("scipy", "numba"):
        assert out[engine]["moved"] > 1e-4  # the bar moved: the comparison is not of two rests
        assert out[engine]["x"] < 1e-12 and out[engine]["v"] < 1e-12, (engine, out[engine])
        assert out[engine]["stress"] < 1e-9, (engine, out[engine])


def test_the_effect_example_is_the_library_file_and_its_registry_line():
    """The page shows ``effects/body_force.py`` verbatim, and the registry line it names is
    the registry's."""
    block = block_containing("# femgrid_mpm/effects/body_force.py")
    shown = block.split("\n", 1)[1]
    assert shown == (PACKAGE / "effects" / "body_force.py").read_text()
    line = block_containing("Entry(BodyForce").strip()
    assert line in (PACKAGE / "effects" / "__init__.py").read_text()


def block_with_loads(*loads, engine="scipy") -> Scene:
    return Scene.model_validate({
        "grid": {"basis": "q1", "lower": [0, 0], "upper": [4, 4], "spacing": 0.5},
        "time": {"dt": 0.01, "end": 0.2},
        "solver": {"engine": engine},
        "bodies": [{"name": "block", "lower": [1, 1], "upper": [3, 3], "velocity": ["0.01*cos(x)", "0"],
                    "material": {"E": 1e4, "nu": 0.3, "density": 1e3}}],
        "loads": list(loads),
    })


def test_a_constant_body_force_is_gravity_bit_for_bit():
    """``m_p b`` with a constant ``b`` is the weight ``m_p g``: the same products, so the
    same bits, with both engines."""
    for engine in ("scipy", "numba"):
        gravity = Simulation(block_with_loads({"kind": "gravity", "acceleration": [0.0, -9.81]}, engine=engine))
        body = Simulation(block_with_loads({"kind": "body_force", "acceleration": [0.0, -9.81]}, engine=engine))
        gravity.run()
        body.run()
        assert body.active_effects == ["body_force"]
        np.testing.assert_array_equal(body.particles.x, gravity.particles.x)
        np.testing.assert_array_equal(body.particles.v, gravity.particles.v)


def test_a_body_force_growing_in_time_gives_its_impulse():
    """``b = (c t, 0)``, applied at each step's end time ``t_k = (k + 1) dt``: with lumped q1 mass
    and no supports the points' momentum gains exactly ``dt sum_k M c t_k`` in x (the nodal
    forces sum to the point forces, the lumped solve keeps ``sum m_i a_i = sum f_i``), to
    round-off (1e-12 of it), and nothing in y beyond round-off of the vibration's momentum."""
    c = 3.0
    simulation = Simulation(block_with_loads({"kind": "body_force", "acceleration": [f"{c}*t", "0"]}))
    p = simulation.particles
    before = (p.mass[:, None] * p.v).sum(axis=0)
    simulation.run()
    after = (p.mass[:, None] * p.v).sum(axis=0)
    n, dt = simulation.step_index, simulation.dt
    impulse = dt * p.mass.sum() * c * dt * n * (n + 1) / 2
    assert abs((after[0] - before[0]) - impulse) < 1e-12 * impulse
    assert abs(after[1] - before[1]) < 1e-12 * impulse
    assert simulation.context.work["body_force"] > 0  # its work is booked


def test_a_body_force_with_an_unknown_variable_is_refused():
    """Expressions take the initial position and the time only."""
    import pytest

    from femgrid_mpm.scene import SceneError

    with pytest.raises(SceneError, match="name 'z' is not allowed"):
        block_with_loads().with_overrides(**{"loads": [{"kind": "body_force", "acceleration": ["z", "0"]}]})


def test_a_new_engine_is_one_file_and_its_registry_line():
    """docs/architecture.md: an engine is one file and its line in ``ENGINES``; the scene's
    ``solver.engine`` was a fixed list and refused the new name.  An engine registered before
    the scene is loaded, as the registry line is (a subclass of the scipy engine), runs the
    bar, bit for bit the scipy engine's run."""
    code = """
import json, sys, numpy as np
from femgrid_mpm.engines import ENGINES, ScipyTransfer
class Mine(ScipyTransfer):
    pass
ENGINES["mine"] = Mine
from femgrid_mpm.scene import bundled_scene
from femgrid_mpm.solver import Simulation
runs = {e: Simulation(bundled_scene("vibrating_bar").with_overrides(**{"time.end": 0.3, "solver.engine": e})).run()
        for e in ("scipy", "mine")}
print(json.dumps({"same": bool(np.array_equal(runs["scipy"].particles.x, runs["mine"].particles.x))}))
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                          env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.splitlines()[-1]) == {"same": True}


#: a load of its own, with only the members given (an AttributeError at the simulation's set-up
#: without a name, a TypeError from inside the scene's validation without a bind)
LIFT = """from typing import Literal
from pydantic.dataclasses import dataclass
from femgrid_mpm import effects
from femgrid_mpm.effects import Stage
from femgrid_mpm.effects.base import Effect
@dataclass(frozen=True)
class Lift(Effect):
    kind: Literal['lift']
    {members}
effects.REGISTRY = effects.REGISTRY + (effects.Entry(Lift, 'loads', kind='lift'),)
"""

REGISTRY_SLIPS = {
    "a basis without sized": (
        "from femgrid_mpm.bases import BASES, Q1\n"
        "class Old:\n"
        "    name = 'old'; degree = 1; cells_per_element = 1; support_width = 2; nonnegative = True\n"
        "    critical_step_factors = {'lumped': 1.0}; tensor_gram = False; mass_threshold = True\n"
        "    def build(self, *args): return Q1.build(*args)\n"
        "BASES['old'] = Old()\n",
        "TypeError: bases.BASES['old']: a Old without sized (femgrid_mpm.bases.BasisDefinition)"),
    "an effect listed twice": (
        "from femgrid_mpm import effects\n"
        "effects.REGISTRY = effects.REGISTRY + (effects.REGISTRY[0],)\n",
        "ValueError: effects.REGISTRY: PointLoad is listed twice"),
    "an effect in a table the scene lacks": (
        "from femgrid_mpm import effects\n"
        "from femgrid_mpm.effects.gravity import Gravity\n"
        "class Lift(Gravity):\n"
        "    pass\n"
        "effects.REGISTRY = effects.REGISTRY + (effects.Entry(Lift, 'lods', kind='lift'),)\n",
        "ValueError: effects.REGISTRY: Lift: the scene has no table 'lods' (its tables: loads, damping, contact, "
        "supports, reference)"),
    "an effect without a name": (
        LIFT.format(members="stage = Stage.EXTERNAL_FORCE\n"
                            "    def bind(self, simulation): return lambda ctx: None"),
        "TypeError: effects.REGISTRY: Lift has no name (a str: its key in the work ledger)"),
    "an effect without bind": (
        LIFT.format(members="name = 'lift'; stage = Stage.EXTERNAL_FORCE"),
        "TypeError: effects.REGISTRY: Lift has no bind"),
}


@pytest.mark.parametrize("slip", sorted(REGISTRY_SLIPS))
def test_a_registry_entry_the_scene_cannot_use_is_named_when_the_scene_loads(slip):
    """A registry line of a basis or effect that lacks part of its interface failed later,
    inside the package (AttributeError from the scene's checks, 'too many values to unpack'),
    or was ignored (an effect's unknown table)."""
    setup, message = REGISTRY_SLIPS[slip]
    done = subprocess.run([sys.executable, "-c", setup + "import femgrid_mpm.scene\n"], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 1
    assert done.stderr.strip().splitlines()[-1] == message


def test_observers_that_are_not_effects_are_refused_before_the_run():
    """observers=[object()] or a string: AttributeError 'stage' from inside the simulation; an
    observer whose bind returned None: TypeError at the first record; an effect class without a
    Stage fails when it is made."""
    from femgrid_mpm.effects import Stage
    from femgrid_mpm.effects.base import Effect
    from femgrid_mpm.scene import bundled_scene

    class Silent(Effect):
        name = "silent"
        stage = Stage.OBSERVE

        def bind(self, simulation):
            return None

    for stage, message in ((None, "effect NoStage: no stage"), ("observe", "effect NoStage: stage 'observe' is not a Stage")):
        with pytest.raises(TypeError, match=message):  # when the class is made, not at the first step
            type("NoStage", (Effect,), {"name": "none", "bind": lambda self, simulation: None,
                                        **({} if stage is None else {"stage": stage})})
    class Nameless(Effect):
        stage = Stage.OBSERVE

        def bind(self, simulation):
            return lambda ctx: None

    scene = bundled_scene("vibrating_bar").with_overrides(**{"time.end": 0.3})
    for observers, message in ((object(), "observers: a list of Effect objects, got object"),
                               ([Nameless()], r"observers\[0\]: a Nameless without a name"),
                               ("ab", "observers: a list of Effect objects, got str"),
                               ([object()], r"observers\[0\]: a object, not an Effect"),
                               ([Silent()], "effect 'silent': bind\\(\\) returned a NoneType, not an action")):
        with pytest.raises(TypeError, match=message):
            Simulation(scene, observers=observers)
