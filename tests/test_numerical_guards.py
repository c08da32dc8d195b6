"""Results that must not be silently wrong: bodies of very different densities, the state
after the last step, a second run, units slips, the energy balance."""

import warnings

import numpy as np
import pytest

from femgrid_mpm.diagnostics import ENERGY_DRIFT_LIMIT, EnergyDriftWarning, ScaleWarning, SimulationStopped
from femgrid_mpm.scene import Scene, bundled_scene
from femgrid_mpm.solver import Simulation

#: a body 1e12 times lighter than the other: E / density as for a soft solid, p-wave speed ~120 m/s
LIGHT = {"E": 1e-2, "nu": 0.3, "density": 1e-6}
HEAVY = {"E": 1e4, "nu": 0.3, "density": 1e6}


def pair_scene(with_heavy=True, heavy_at=3.0, contact=None, basis="q1", mass="lumped", engine="numba",
               dt=1e-3, end=0.02) -> Scene:
    """A light block [0.5, 1.5] x [0.5, 1] stretched by its initial velocity, and (optionally)
    a heavy block at rest from ``heavy_at`` (3.0: no node shared; 1.5: touching)."""
    bodies = [{"name": "light", "lower": [0.5, 0.5], "upper": [1.5, 1.0], "points_per_cell": 2,
               "velocity": ["0.1*(x-1.0)", "0"], "material": LIGHT}]
    if with_heavy:
        bodies.append({"name": "heavy", "lower": [heavy_at, 0.5], "upper": [heavy_at + 1.0, 1.0],
                       "points_per_cell": 2, "material": HEAVY})
    data = {"grid": {"basis": basis, "lower": [0, 0], "upper": [5, 1.5], "spacing": 0.25},
            "time": {"dt": dt, "end": end}, "solver": {"mass": mass, "engine": engine, "negative_mass": "warn",
                                                       "consistent_fallback": "blend"},
            "bodies": bodies}
    if contact:
        data["contact"] = {"kind": contact}
    return Scene.model_validate(data)


def light_displacement(scene: Scene) -> np.ndarray:
    simulation = Simulation(scene)
    result = simulation.run()
    assert result.status == "completed"
    p = result.particles
    return (p.x - p.x0)[p.body == 0]


@pytest.mark.parametrize("basis, mass, engine, tolerance", [
    ("q1", "lumped", "numba", 1e-12), ("q1", "lumped", "scipy", 1e-12), ("bspline3", "lumped", "numba", 1e-12),
    ("q1", "hrz", "numba", 1e-12),
    # one matrix for both bodies, its entries 1e12 apart: the solve's rounding differs (measured 6e-9)
    ("q1", "consistent", "numba", 1e-6),
])
def test_a_light_body_moves_as_when_alone(basis, mass, engine, tolerance):
    """Far from a body 1e12 times heavier, sharing no node, the light body moves as it does
    alone (its nodes were empty against the heavy body's full cell: it moved rigidly)."""
    alone = light_displacement(pair_scene(with_heavy=False, basis=basis, mass=mass, engine=engine))
    beside = light_displacement(pair_scene(basis=basis, mass=mass, engine=engine))
    assert np.abs(alone).max() > 2e-5  # it does move: 5.4e-5 m at its ends (q1 lumped)
    np.testing.assert_allclose(beside, alone, rtol=0, atol=tolerance * np.abs(alone).max())


def test_frictional_fields_measure_empty_by_their_own_body():
    """One field per body: each body's field is empty or not against its own full cell."""
    alone = light_displacement(pair_scene(with_heavy=False, engine="scipy"))
    beside = light_displacement(pair_scene(contact="frictional"))
    np.testing.assert_allclose(beside, alone, rtol=0, atol=1e-12 * np.abs(alone).max())


def test_the_critical_step_sees_the_light_body():
    """In contact with a heavy body the critical step is the light body's (it was 3.39 s,
    the heavy body's, against 3.39e-3 s for the light body alone)."""
    alone = Simulation(pair_scene(with_heavy=False)).critical_dt
    far = Simulation(pair_scene()).critical_dt
    frictional = Simulation(pair_scene(heavy_at=1.5, contact="frictional")).critical_dt
    shared = Simulation(pair_scene(heavy_at=1.5, contact="shared")).critical_dt
    assert 1e-3 < alone < 1e-2
    assert far == pytest.approx(alone, rel=1e-9)  # nothing couples them: the lighter's
    assert frictional == pytest.approx(alone, rel=1e-9)  # each body in its own field
    # glued at the shared nodes, a little stiffer or softer than alone: within 5%
    assert shared == pytest.approx(alone, rel=0.05)


def test_auto_step_with_a_light_body_in_contact_stays_stable():
    """``dt = "auto"`` takes the light body's step and the run keeps its energy."""
    scene = pair_scene(heavy_at=1.5, contact="shared").with_overrides(**{"time.dt": "auto", "time.end": 0.05})
    simulation = Simulation(scene)
    result = simulation.run()
    assert result.status == "completed"
    assert simulation.dt < 0.01  # the heavy body's step would be ~3 s
    assert simulation.n_steps > 10


# -- the state after the last step -------------------------------------------------------------

def without_output(scene: Scene) -> Scene:
    data = scene.model_dump(mode="json", exclude_none=True)
    data.pop("output", None)
    return Scene.model_validate(data)


@pytest.mark.parametrize("recorded", [True, False])
def test_the_state_after_the_last_step_is_guarded(recorded):
    """One step at 4.6 times the critical step: the energy it ends with is checked (the run
    reported "completed" with 77 times the initial energy)."""
    bar = bundled_scene("vibrating_bar")
    critical = Simulation(bar).critical_dt
    scene = bar.with_overrides(**{"time.dt": 4.6 * critical, "time.end": 4.6 * critical})
    simulation = Simulation(scene if recorded else without_output(scene))
    assert simulation.n_steps == 1
    with pytest.raises(SimulationStopped) as stop:
        simulation.run()
    assert stop.value.reason == "runaway_energy"
    assert stop.value.step == 1  # after the last step, not before it
    assert stop.value.result.status == "stopped"


def test_a_stable_run_ends_completed_after_the_final_check(block_scene):
    simulation = Simulation(block_scene(end=0.1))
    assert simulation.run().status == "completed"


# -- a second run() ------------------------------------------------------------------------------

def test_a_second_run_is_refused(block_scene):
    """A completed (or stopped) run is not run again: a second call appended a second
    final record at the same time."""
    scene = block_scene(end=0.1, every=1).with_overrides(**{"output.energy": True})
    simulation = Simulation(scene)
    result = simulation.run()
    records = len(simulation.energy.rows)
    assert records == simulation.n_steps + 1  # every step's start and the end
    with pytest.raises(ValueError, match=r"has completed \(step 10, t = 0.1 s\).*time\.end"):
        simulation.run()
    assert len(simulation.energy.rows) == records
    assert simulation.step_index == 10 and result.status == "completed"


def test_a_stopped_run_is_not_run_again():
    bar = bundled_scene("vibrating_bar")
    critical = Simulation(bar).critical_dt
    simulation = Simulation(bar.with_overrides(**{"time.dt": 4.6 * critical, "time.end": 10 * critical}))
    with pytest.raises(SimulationStopped):
        simulation.run()
    with pytest.raises(ValueError, match="has stopped"):
        simulation.run()
    with pytest.raises(ValueError, match="has stopped"):
        simulation.advance()


def test_a_finished_run_takes_no_more_steps_and_its_result_stays(block_scene):
    """advance() after run(): it stepped on past time.end and moved the returned result's
    points (the result holds the simulation's arrays)."""
    simulation = Simulation(block_scene(end=0.05, every=1))
    result = simulation.run()
    x = result.particles.x.copy()
    with pytest.raises(ValueError, match=r"has completed \(step 5, t = 0.05 s\): it takes no steps but run\(\)'s"):
        simulation.advance()
    with pytest.raises(ValueError, match="has completed: restore into a new Simulation"):
        simulation.restore(*Simulation(block_scene(end=0.05, every=1)).state())
    assert simulation.step_index == 5 and np.array_equal(result.particles.x, x)


def test_run_called_again_while_it_runs_is_refused_and_an_interrupted_run_goes_on(block_scene):
    """A second run() while the first runs (from another thread, or its progress callback) was
    let through: both stepped the one state and both wrote the final record."""
    simulation = Simulation(block_scene(end=0.1, every=1).with_overrides(**{"output.energy": True}))
    refused = []

    def progress(step, time):
        if step == 3:
            with pytest.raises(ValueError, match=r"has begun \(step 3"):
                simulation.run()
            with pytest.raises(ValueError, match=r"has begun \(step 3.*no steps but run\(\)'s"):
                simulation.advance()  # it was taken: the run's count of steps included it
            refused.append(step)
        if step == 6 and len(refused) == 1:
            refused.append(step)
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        simulation.run(progress=progress)
    assert refused == [3, 6] and simulation.step_index == 6 and simulation.outcome is None
    result = simulation.run(progress=progress)  # an interrupted run goes on to its end, once
    reference = Simulation(block_scene(end=0.1, every=1).with_overrides(**{"output.energy": True})).run()
    assert result.status == "completed" and len(simulation.energy.rows) == simulation.n_steps + 1
    assert np.array_equal(result.particles.x, reference.particles.x)


def test_a_simulation_is_not_pickled_or_copied_but_its_state_is(block_scene):
    """pickle failed on pydantic's mappingproxy, naming nothing of ours; copy.copy shared the
    arrays of the points between the copy and the original."""
    import copy
    import pickle

    simulation = Simulation(block_scene(end=0.05))
    for attempt in (pickle.dumps, copy.copy, copy.deepcopy):
        with pytest.raises(TypeError, match=r"not copied or pickled: take its state\(\) and restore\(\) it"):
            attempt(simulation)
    arrays, values = pickle.loads(pickle.dumps(simulation.state()))
    other = Simulation(block_scene(end=0.05))
    other.restore(arrays, values)
    assert np.array_equal(other.run().particles.x, simulation.run().particles.x)


# -- units slips -----------------------------------------------------------------------------------

def test_a_soft_body_beside_a_stiff_body_of_one_point_keeps_its_step():
    """The round-off floor of the critical step is the softest body's (c_p / h)^2: with the
    stiffest's, a body of one point with E = 1e15 beside one of E = 10 Pa was refused, where the
    soft body's own step is the run's (the scene without the point: the same step to 1e-6)."""
    def body(name, upper, points, E, density):
        return {"name": name, "lower": [5.0, 5.0] if name == "point" else [1.0, 1.0], "upper": upper,
                "points_per_cell": points, "velocity": [0.1, 0.0], "material": {"E": E, "nu": 0.3, "density": density}}

    soft = body("soft", [4.0, 3.0], 2, 10.0, 1e3)
    scene = Scene.model_validate({"grid": {"basis": "q1", "lower": [0, 0], "upper": [8, 8], "spacing": 1.0},
                                  "time": {"dt": "auto", "end": 1.0}, "bodies": [soft]})
    alone = Simulation(scene).critical_dt
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the point's thinness
        beside = Simulation(scene.with_overrides(bodies=[soft, body("point", [5.5, 5.5], 2, 1e15, 7800.0)])).critical_dt
    assert 1.0 < alone < 100.0 and beside == pytest.approx(alone, rel=1e-6)


@pytest.mark.parametrize("soft_E, stiff_E", [(1e3, 1e9), (1e6, 1e12), (10.0, 1e15)])
def test_bodies_of_one_point_each_are_refused_whatever_their_stiffnesses(soft_E, stiff_E):
    """Two bodies of one point each leave the grid nothing to deform: the critical step is
    infinite and dt = "auto" is refused.  The stiff point's round-off (~1e-16 of its (c_p / h)^2)
    was above the softest body's floor: steps of 889 s to 3.4e5 s were taken as the critical one."""
    def body(name, lower, E, density):
        return {"name": name, "lower": lower, "upper": [lower[0] + 0.5, lower[1] + 0.5], "points_per_cell": 2,
                "velocity": [0.1, 0.0], "material": {"E": E, "nu": 0.3, "density": density}}

    scene = Scene.model_validate({"grid": {"basis": "q1", "lower": [0, 0], "upper": [8, 8], "spacing": 1.0},
                                  "time": {"dt": "auto", "end": 1.0},
                                  "bodies": [body("soft", [1.0, 1.0], soft_E, 1e3), body("point", [5.0, 5.0], stiff_E, 7800.0)]})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the points' thinness
        with pytest.raises(ValueError, match=r"^time\.dt: dt = 'auto' has nothing to limit the step"):
            Simulation(scene)


def test_a_spacing_in_millimetres_warns_and_info_states_the_end_reached(run_cli, tmp_path):
    """``spacing = 250`` for a bar 5 x 1 m: one point per body (a warning), a step longer
    than the run (a warning), and info's end time is the run's (it said t = 1 s, the run
    ended at 13.5 s).  With ``dt = "auto"`` the one point leaves nothing to bound the step
    (its grid velocity is uniform: omega_max^2 was 7.5e-20, round-off): refused, after the
    warning that names the slip."""
    scene = bundled_scene("vibrating_bar").with_overrides(
        **{"grid.spacing": 250.0, "time.dt": 20.0, "time.end": 1.0})
    with pytest.warns(ScaleWarning) as caught:
        simulation = Simulation(scene)
    messages = [str(w.message) for w in caught if issubclass(w.category, ScaleWarning)]
    assert any("1 point(s) across" in m and "fewer than the 2 that q1 needs" in m for m in messages)
    assert any(m.startswith("dt = 20 s exceeds time.end = 1 s: the run takes one step, to t = 20 s") for m in messages)
    assert simulation.dt == 20.0 and simulation.n_steps == 1
    with pytest.warns(ScaleWarning, match=r"1 point\(s\) across"), \
            pytest.raises(ValueError, match=r"^time\.dt: dt = 'auto' has nothing to limit the step"):
        Simulation(scene.with_overrides(**{"time.dt": "auto"}))
    result = simulation.run()
    assert result.summary["time"] == simulation.end_time == simulation.dt

    path = tmp_path / "slip.toml"
    path.write_text(bundled_scene_text("vibrating_bar"))
    code, out, err = run_cli(["info", path, "--set", "grid.spacing=250", "--set", "time.dt=20",
                              "--set", "time.end=1"])
    assert code == 0
    steps = next(line for line in out.splitlines() if line.startswith("steps:"))
    assert steps.split(None, 1)[1] == "1 to t = 20 s (time.end = 1 s, rounded up to whole steps)"
    assert "point(s) across" in err and "exceeds time.end" in err
    code, out, err = run_cli(["info", path, "--set", "grid.spacing=250", "--set", "time.dt='auto'", "--set", "time.end=1"])
    assert code == 2 and out == "" and "point(s) across" in err.splitlines()[0]
    assert "time.dt: dt = 'auto' has nothing to limit the step" in err.splitlines()[-1]


@pytest.mark.parametrize("settings", [
    ['supports=[{where = "x <= 100"}]'],  # every node fixed: no free stiffness at all
    ["grid.spacing=1e100"],  # one cell of 1e100 m over the bar: K / M underflows
    ["bodies.0.upper=[1e-300, 1e-300]"],  # a body of 1e-300 m: its stiffness is 0 in floating point
    # one point: its grid velocity, projected afresh, is uniform (the estimate was round-off, 4.8e11 s)
    ["bodies.0.upper=[0.5, 0.5]", "bodies.0.points_per_cell=1"],
])
def test_an_infinite_auto_step_is_refused_naming_time_dt(run_cli, tmp_path, settings):
    """Nothing limits the step (the critical step is infinite): dt = "auto" would be inf and
    the run one step to t = inf. Refused, naming time.dt, in Python and on the command line."""
    path = tmp_path / "bar.toml"
    path.write_text(bundled_scene_text("vibrating_bar"))
    settings = ["time.dt='auto'", *settings]
    code, out, err = run_cli(["run", path, "--out", tmp_path / "out", "--no-progress",
                              *[word for setting in settings for word in ("--set", setting)]])
    assert code == 2 and out == "" and not (tmp_path / "out").exists()
    assert err.splitlines()[-1:] == [f"femgrid-mpm: error: {path}: time.dt: dt = 'auto' has nothing to limit the step "
                                "(an infinite critical step: every node fixed, a body of one point, or a stiffness "
                                "that vanishes in floating point, e.g. a spacing or a body size far from metres); "
                                "give dt in seconds"]
    import tomllib

    changes = {key: tomllib.loads(f"v = {text}")["v"] for key, _, text in (s.partition("=") for s in settings)}
    with pytest.raises(ValueError, match=r"^time\.dt: dt = 'auto' has nothing to limit the step"):
        Simulation(bundled_scene("vibrating_bar").with_overrides(**changes))


def bundled_scene_text(name: str) -> str:
    from importlib.resources import files

    return (files("femgrid_mpm") / "scenes" / f"{name}.toml").read_text()


@pytest.mark.parametrize("name", ["vibrating_bar", "cantilever", "box_impact"])
@pytest.mark.parametrize("basis", ["q1", "q2", "serendipity", "bspline3"])
def test_the_paper_scenes_are_not_units_slips(name, basis):
    with warnings.catch_warnings():
        warnings.simplefilter("error", ScaleWarning)
        Simulation(bundled_scene(name).with_overrides(**{"grid.basis": basis}))


def test_a_body_thinner_than_the_cubic_support_warns(block_scene):
    """Cubic B-splines span 4 spacings: a body 3 points thick is seen from one side."""
    scene = block_scene("bspline3", upper=(1.75, 1.0), points_per_cell=3)  # 0.5 m thick: 3 points
    with pytest.warns(ScaleWarning, match=r"3 point\(s\) across in y, fewer than the 4 that bspline3 needs"):
        Simulation(scene)


# -- the energy balance ------------------------------------------------------------------------------

def test_energy_drift_is_recorded_and_warned_once():
    """Frictional contact at dt = 0.005 to t = 1.5 s: the balance is off by 15% of the energy
    scale; ``energy_drift`` is the last total error over the largest kinetic + strain +
    |external work| of the records, and one warning names the remedy."""
    scene = bundled_scene("box_impact").with_overrides(**{"contact.kind": "frictional", "time.end": 1.5})
    simulation = Simulation(scene)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = simulation.run()
    table = result.energy
    scale = np.max(table["kinetic"] + table["strain"] + np.abs(table["external_work"]))
    expected = table["total_error"][-1] / scale
    assert result.summary["energy_drift"] == pytest.approx(expected, rel=1e-12)
    assert expected == pytest.approx(0.152, rel=0.01)
    drifts = [w for w in caught if issubclass(w.category, EnergyDriftWarning)]
    assert len(drifts) == 1
    assert "time.safety" in str(drifts[0].message) and f"{expected:.3g}" in str(drifts[0].message)
    assert drifts[0].filename == __file__  # the caller of run(), not a wrapper of it (numpy's errstate)


def test_the_advice_lowers_the_drift():
    """Half the step (the warning's advice) brings the frictional box under the limit: 0.087
    against 0.152, about first order in dt; no warning then."""
    scene = bundled_scene("box_impact").with_overrides(
        **{"contact.kind": "frictional", "time.end": 1.5, "time.dt": 0.0025})
    with warnings.catch_warnings():
        warnings.simplefilter("error", EnergyDriftWarning)
        drift = Simulation(scene).run().summary["energy_drift"]
    assert 0.0 < drift < ENERGY_DRIFT_LIMIT
    assert drift == pytest.approx(0.0874, rel=0.01)


def test_shared_contact_keeps_its_balance_without_a_warning():
    """The paper's box impact (shared contact, dt = 0.005) is off by 1% at t = 1.5 s."""
    scene = bundled_scene("box_impact").with_overrides(**{"time.end": 1.5})
    with warnings.catch_warnings():
        warnings.simplefilter("error", EnergyDriftWarning)
        drift = Simulation(scene).run().summary["energy_drift"]
    assert abs(drift) < 0.02


@pytest.mark.parametrize("name, changes, recorded, warns", [
    # below the runaway guard's 10x: it warned with records only
    ("box_impact", {"time.end": 0.5, "time.dt": "auto", "time.safety": 1.0}, 0.687, True),
    ("box_impact", {"time.end": 1.5, "contact.kind": "frictional"}, 0.152, True),
    # the body force's work in and out: the ends alone (0.10) warned where the records (0.039) do not
    ("manufactured", {"time.end": 0.3}, 0.0388, False),
])
def test_energy_drift_without_records_follows_the_records(name, changes, recorded, warns):
    """Without energy records the drift is measured from the run's first and last states, over the
    largest energy the runaway guard checked (or the balance's initial + work) plus the work: within
    a quarter of the same run's recorded drift, and it warns where that does."""
    scene = bundled_scene(name).with_overrides(**changes)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with_records = Simulation(scene).run().summary["energy_drift"]
        bare = Simulation(scene.with_overrides(**{"output.energy": False})).run()
    assert with_records == pytest.approx(recorded, rel=0.01)
    assert bare.energy is None and 0.75 < bare.summary["energy_drift"] / with_records < 1.3
    assert len([w for w in caught if issubclass(w.category, EnergyDriftWarning)]) == (2 if warns else 0)


def test_energy_drift_without_records_is_exact_for_rigid_motion_and_kept_through_a_resume(block_scene):
    """A block in rigid motion keeps its energy (0 to round-off); a run restored from its state late
    in the run (after the energy's peak) reports the drift of the run that went on (the guard's peak
    is in the state)."""
    assert abs(Simulation(block_scene(end=0.05, every=None)).run().summary["energy_drift"]) < 1e-12
    scene = bundled_scene("manufactured").with_overrides(**{"time.end": 0.3, "output.energy": False})
    whole = Simulation(scene)
    states = []
    result = whole.run(checkpoint=lambda simulation: states.append(simulation.state()), checkpoint_every=2)
    assert len(states) > 4
    resumed = Simulation(scene)
    resumed.restore(*states[-1])  # after the energy's peak
    assert resumed.run().summary["energy_drift"] == result.summary["energy_drift"]


# -- body forces without a value ----------------------------------------------------------------------

def body_force_scene(block_scene, acceleration, constants=None):
    """The block (at rest) with one gravity load first, so that the body force is ``loads[1]``."""
    force = {"kind": "body_force", "acceleration": acceleration, "constants": constants or {}}
    return block_scene(velocity=(0.0, 0.0), end=0.05, loads=[{"kind": "gravity", "acceleration": [0.0, -1.0]}, force])


@pytest.mark.parametrize("acceleration, constants, step, points", [
    (["sqrt(-x)", "0"], None, 0, lambda x0: x0[:, 0] > 0),  # NaN wherever x > 0 from the first step
    (["B*(1 + t)", "0"], {"B": 1e308}, 0, lambda x0: x0[:, 0] == x0[:, 0]),  # m B (1 + t) > 1e308 N: inf
    (["1/(t - 0.03)", "0"], None, 2, lambda x0: x0[:, 0] == x0[:, 0]),  # 1/0 at t + dt = 0.03
])
def test_a_body_force_without_a_value_stops_naming_its_key(block_scene, acceleration, constants, step, points):
    """A stop (not_finite) naming loads[1].acceleration, the count, the time the force is taken
    at (t + dt) and the first point, without numpy's warnings; not "the state is no longer finite"."""
    scene = body_force_scene(block_scene, acceleration, constants)
    simulation = Simulation(scene)
    x0 = simulation.particles.x0
    first = int(np.argmax(points(x0)))
    with warnings.catch_warnings(), pytest.raises(SimulationStopped) as stop:
        warnings.simplefilter("error")
        simulation.run()
    assert stop.value.reason == "not_finite" and stop.value.step == step
    x = simulation.particles.x[first]  # where it is at the stop
    assert str(stop.value) == (
        f"step {step} (t = {step * 0.01:.6g} s): loads[1].acceleration: gives NaN or infinity (or a force beyond 1e308 N) "
        f"at {int(points(x0).sum())} point(s) at t = {(step + 1) * 0.01:.6g} s; first at point {first} of body "
        f"'block' at ({x[0]:.6g}, {x[1]:.6g}), seeded at ({x0[first, 0]:.6g}, {x0[first, 1]:.6g})")


def test_a_runaway_body_force_stops_without_numpys_warnings(block_scene):
    """Forces finite but huge (1e200 exp(100 t) m/s^2): the run stops (the points leave the grid
    or the state overflows) with no overflow warning from the energy record or the work."""
    simulation = Simulation(body_force_scene(block_scene, ["1e200*exp(100*t)", "0"]))
    with warnings.catch_warnings(), pytest.raises(SimulationStopped):
        warnings.simplefilter("error")
        simulation.run()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.isfinite(simulation.particles.mass).all() and simulation.particles.volume.shape == (simulation.particles.n,)


def test_a_stop_names_the_point_whose_volume_is_not_finite(block_scene):
    """A volume can overflow while the motion stays finite: the stop named no point."""
    from femgrid_mpm.diagnostics import first_not_finite

    simulation = Simulation(block_scene(end=0.05))
    p, bodies = simulation.particles, simulation.scene.bodies
    assert first_not_finite(p, bodies) == ""
    p.density[3] = 0.0  # mass over it: an infinite volume
    assert first_not_finite(p, bodies).startswith("; first at point 3 of body") and \
        first_not_finite(p, bodies).endswith("(its volume)")
    p.x[5, 1] = np.nan
    assert "(its" not in first_not_finite(p, bodies) and "point 3 of body" not in first_not_finite(p, bodies)


def test_a_cg_tolerance_out_of_reach_is_named_not_only_a_singular_matrix(block_scene):
    """``cg_tolerance = 1e-300`` (in its range (0, 1)) on a mass that is not singular (the direct
    solve and CG at 1e-6 run it): CG cannot converge, and the stop blamed only the matrix and too
    few points per cell; it names the tolerance too, with either fallback."""
    def scene(tolerance, solver="cg", fallback="error"):
        return block_scene(mass="consistent", velocity=("0.1*(x-1.25)", "0"), end=0.05, solver={
            "mass": "consistent", "linear_solver": solver, "cg_tolerance": tolerance, "consistent_fallback": fallback})
    for reference in (scene(1e-6), scene(1e-300, "direct")):
        assert Simulation(reference).run().status == "completed"
    for fallback, words in (("error", "CG did not converge to solver.cg_tolerance = 1e-300 on the velocity system"),
                            ("blend", "(velocity system, CG to solver.cg_tolerance = 1e-300)")):
        with pytest.raises(SimulationStopped) as stop:
            Simulation(scene(1e-300, fallback=fallback)).run()
        assert stop.value.reason == "singular_mass" and words in str(stop.value) and stop.value.step == 0
