"""Exact references declared in scenes (``[reference]``), the error reported against them, and
the bundled scenes that carry one: each reference checked against an independent derivation."""

import csv
import json
import warnings

import numpy as np
import pytest

from femgrid_mpm.analysis import modal_velocity_probe, zero_crossing_period
from femgrid_mpm.beam_theory import timoshenko_goodier_displacement
from femgrid_mpm.effects.body_force import VARIABLES as FORCE_VARIABLES
from femgrid_mpm.expressions import compile_expression
from femgrid_mpm.scene import bundled_scene
from femgrid_mpm.solver import Simulation

SCENES_WITH_REFERENCE = ("vibrating_bar_exact", "manufactured", "cantilever_quasistatic", "manufactured_large",
                         "drifting_bar", "manufactured_rollers")


def test_a_rigid_motion_has_no_error_and_a_wrong_reference_the_error_it_should(block_scene):
    """A block moving rigidly at v moves exactly, so against ``u = v t`` the error is round-off;
    against ``u = 2 v t`` it is ``|v| t_end`` over the scale ``2 |v| t_end``: 1/2 at the end, and
    the records' largest error is the last one, also 1/2."""
    exact = block_scene(velocity=(1.0, 0.25), reference={"displacement": ["1.0*t", "0.25*t"]})
    result = Simulation(exact).run()
    assert result.summary["reference"]["error_end"] < 1e-12
    assert result.summary["reference"]["error_max"] < 1e-12
    doubled = block_scene(velocity=(1.0, 0.25), reference={"displacement": ["k*t", "k*t/4"], "constants": {"k": 2.0}})
    reference = Simulation(doubled).run().summary["reference"]
    assert reference["error_end"] == pytest.approx(0.5, rel=1e-9)
    assert reference["error_max"] == pytest.approx(0.5, rel=1e-9)
    assert reference["scale"] == pytest.approx(2 * np.hypot(1.0, 0.25) * 1.0, rel=1e-9)


def test_without_a_reference_nothing_is_recorded(block_scene):
    """A scene without ``[reference]`` runs no reference code and reports no error."""
    simulation = Simulation(block_scene())
    result = simulation.run()
    assert "reference" not in result.summary and "reference" not in simulation.active_effects
    assert "reference_error" not in result.energy


def test_a_static_reference_counts_only_the_last_record(block_scene):
    """``when = "end"``: the error is the last record's over that record's own scale."""
    scene = block_scene(velocity=(1.0, 0.0), end=0.5, reference={"displacement": ["0.25", "0"], "when": "end"})
    reference = Simulation(scene).run().summary["reference"]
    # the block moved 0.5 m, the reference says 0.25 m: |0.5 - 0.25| / 0.25
    assert reference["error_end"] == pytest.approx(1.0, rel=1e-9)
    assert reference["error_max"] == reference["error_end"]


def test_the_energy_record_ends_with_the_summary_error_and_the_cli_writes_both(tmp_path, run_cli):
    """``energy.csv`` gains ``reference_error``; its last row is ``summary.json``'s ``error_end``,
    and ``info`` lists the reference among the effects."""
    scene = tmp_path / "bar.toml"
    text = (bundled_scene_path("vibrating_bar_exact").read_text()
            .replace("end = 8.0", "end = 1.0").replace('basis = "q1"', 'basis = "q2"'))
    scene.write_text(text)
    code, out, _ = run_cli(["info", scene])
    assert code == 0 and "reference" in out.split("effects:")[1].splitlines()[0]
    code, _, err = run_cli(["run", scene, "--out", tmp_path / "out", "--no-progress"])
    assert code == 0, err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    with open(tmp_path / "out" / "energy.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert float(rows[-1]["reference_error"]) == summary["reference"]["error_end"]
    assert 0 < summary["reference"]["error_end"] < 0.05


def bundled_scene_path(name):
    from femgrid_mpm.scene.loading import BUNDLED_SCENES

    return BUNDLED_SCENES / f"{name}.toml"


def test_a_resumed_run_reports_the_same_reference_errors(block_scene):
    """The reference's record goes through a checkpoint: the run continued from the state
    half-way reports the uninterrupted run's errors bit for bit."""
    scene = block_scene(basis="bspline3", velocity=("0.01*cos(x)", "0"), end=0.4, every=2,
                        reference={"displacement": ["0.01*cos(x)*t", "0"], "period": 1.0})
    whole = Simulation(scene).run().summary["reference"]
    first = Simulation(scene)
    first.n_steps = 20
    first.run()
    arrays, values = first.state()
    second = Simulation(scene)
    second.restore(arrays, values)
    assert second.run().summary["reference"] == whole


@pytest.mark.parametrize("name", SCENES_WITH_REFERENCE)
def test_a_bundled_reference_starts_at_the_scene_initial_state(name):
    """Each bundled reference is zero at t = 0 and its time derivative there (central
    differences, step 1e-6 of the run) is the scene's initial velocity, to 1e-6 of it."""
    scene = bundled_scene(name)
    simulation = Simulation(scene)
    exact = scene.reference.exact()
    p = simulation.particles
    x, y = p.x0[:, 0], p.x0[:, 1]
    if scene.reference.when == "end":  # a static solution: no initial state to match
        return
    assert np.abs(exact(x, y, 0.0)).max() == 0.0
    step = 1e-6 * scene.time.end
    velocity = (exact(x, y, step) - exact(x, y, -step)) / (2 * step)
    assert np.abs(velocity - p.v).max() <= 1e-6 * np.abs(p.v).max()


def test_the_rollers_mode_is_free_and_on_rollers_by_finite_differences():
    """scenes/manufactured_rollers.toml: with nu = 0, rho u_tt = E u_xx (and the same in y) with no
    body force, to 1e-6 relative (central differences, step 1e-4), and u_x = 0 on x = 0, 1."""
    scene = bundled_scene("manufactured_rollers")
    exact = scene.reference.exact()
    material = scene.bodies[0].material
    x, y = np.meshgrid(np.linspace(0.05, 0.95, 7), np.linspace(0.05, 0.95, 7))
    x, y, t, d = x.ravel(), y.ravel(), 0.3, 1e-4
    u_tt = (exact(x, y, t + d) - 2 * exact(x, y, t) + exact(x, y, t - d)) / d**2
    u_xx = (exact(x + d, y, t) - 2 * exact(x, y, t) + exact(x - d, y, t)) / d**2
    u_yy = (exact(x, y + d, t) - 2 * exact(x, y, t) + exact(x, y - d, t)) / d**2
    balance = material.density * u_tt - material.E * np.column_stack([u_xx[:, 0], u_yy[:, 1]])
    assert np.abs(balance).max() <= 1e-6 * material.density * np.abs(u_tt).max()
    edges = np.array([0.0, 1.0])
    assert np.abs(exact(edges, np.array([0.3, 0.7]), t)[:, 0]).max() < 1e-24


def test_the_manufactured_body_force_balances_its_displacement_by_finite_differences():
    """``b = d2u/dt2 - (1/rho) div sigma(u)`` for the linear law with nu = 0 (sigma_xx = E du_x/dx,
    sigma_yy = E du_y/dy, sigma_xy = (E/2)(du_x/dy + du_y/dx)), every derivative by central
    differences of the scene's displacement (step 1e-4): the scene's body force agrees to 1e-6
    of its largest value at 200 random points and times."""
    scene = bundled_scene("manufactured")
    material = scene.bodies[0].material
    assert material.nu == 0.0
    exact = scene.reference.exact()
    load = scene.loads[0]
    force = [compile_expression(c, FORCE_VARIABLES, load.constants) for c in load.acceleration]
    rng = np.random.default_rng(7)
    x, y = rng.uniform(0, 1, 200), rng.uniform(0, 1, 200)
    t = rng.uniform(0, scene.time.end, 200)
    h = 1e-4

    def u(dx=0.0, dy=0.0, dt=0.0):
        return np.array([exact(x[i:i + 1] + dx, y[i:i + 1] + dy, t[i] + dt)[0] for i in range(len(x))])

    acceleration = (u(dt=h) - 2 * u() + u(dt=-h)) / h**2
    u_xx = (u(dx=h) - 2 * u() + u(dx=-h)) / h**2
    u_yy = (u(dy=h) - 2 * u() + u(dy=-h)) / h**2
    u_xy = (u(h, h) - u(h, -h) - u(-h, h) + u(-h, -h)) / (4 * h**2)
    E, mu = material.E, material.E / 2
    divergence_x = E * u_xx[:, 0] + mu * (u_yy[:, 0] + u_xy[:, 1])
    divergence_y = E * u_yy[:, 1] + mu * (u_xx[:, 1] + u_xy[:, 0])
    expected = acceleration - np.stack([divergence_x, divergence_y], axis=1) / material.density
    given = np.stack([force[axis](x=x, y=y, t=t) for axis in range(2)], axis=1)
    assert np.abs(given - expected).max() < 1e-6 * np.abs(given).max()


def test_the_large_manufactured_body_force_balances_the_neo_hookean_stress_by_finite_differences():
    """``b = d2u/dt2 - (1/rho_0) div_X P(F)`` with the first Piola-Kirchhoff stress of the
    library's neo-Hookean law (:class:`~femgrid_mpm.materials.NeoHookean`'s Cauchy stress
    ``sigma`` turned into ``P = J sigma F^-T``), ``F = I + grad_X u`` and every derivative by
    central differences of the scene's displacement (steps 1e-4 in X, 1e-5 in t): the scene's
    body force agrees to 1e-5 of its largest value at 200 random points and times, and the
    amplitude is large (strains of 0.1 or more at some of them)."""
    from femgrid_mpm.materials import make_material

    scene = bundled_scene("manufactured_large")
    body = scene.bodies[0]
    assert body.material.model == "neo_hookean" and body.material.nu == 0.0
    law = make_material(body.material)
    exact = scene.reference.exact()
    load = scene.loads[0]
    force = [compile_expression(c, FORCE_VARIABLES, load.constants) for c in load.acceleration]
    rng = np.random.default_rng(11)
    x, y, t = rng.uniform(0, 1, 200), rng.uniform(0, 1, 200), rng.uniform(0, scene.time.end, 200)
    h, k = 1e-4, 1e-5

    def u(X, Y, T):
        return np.array([exact(X[i:i + 1], Y[i:i + 1], T[i])[0] for i in range(len(X))])

    def piola(X, Y):
        """P(F(X, Y, t)) per point, shape (n, 2, 2)."""
        F = np.empty((len(X), 2, 2))
        F[:, :, 0] = (u(X + h, Y, t) - u(X - h, Y, t)) / (2 * h)
        F[:, :, 1] = (u(X, Y + h, t) - u(X, Y - h, t)) / (2 * h)
        F += np.eye(2)
        sigma = law.cauchy_stress(F)
        cauchy = np.stack([np.stack([sigma[:, 0], sigma[:, 2]], -1), np.stack([sigma[:, 2], sigma[:, 1]], -1)], 1)
        J = np.linalg.det(F)
        return J[:, None, None] * cauchy @ np.linalg.inv(F).transpose(0, 2, 1)

    acceleration = (u(x, y, t + k) - 2 * u(x, y, t) + u(x, y, t - k)) / k**2
    divergence = ((piola(x + h, y) - piola(x - h, y))[:, :, 0] + (piola(x, y + h) - piola(x, y - h))[:, :, 1]) / (2 * h)
    expected = acceleration - divergence / body.material.density
    given = np.stack([force[axis](x=x, y=y, t=t) for axis in range(2)], axis=1)
    strain = np.abs((u(x + h, y, t) - u(x - h, y, t))[:, 0] / (2 * h))
    assert strain.max() > 0.1
    assert np.abs(given - expected).max() < 1e-5 * np.abs(given).max()


def test_the_cantilever_reference_is_timoshenko_goodier_with_a_vertical_root_element():
    """The quasi-static cantilever's reference expressions equal
    :func:`~femgrid_mpm.beam_theory.timoshenko_goodier_displacement` (root condition b,
    nu = 0, P = the scene's load) at the beam's points, to 1e-12 of the tip deflection."""
    scene = bundled_scene("cantilever_quasistatic")
    body, (load,) = scene.bodies[0], scene.loads
    material = body.material
    points = Simulation(scene).particles.x0
    x, y = points[:, 0] - body.lower[0], points[:, 1] - (body.lower[1] + body.upper[1]) / 2
    u, v = timoshenko_goodier_displacement(x, y, -load.force[1], body.upper[0] - body.lower[0],
                                           body.upper[1] - body.lower[1], material.E, material.nu,
                                           root="vertical_element", plane=material.plane)
    given = scene.reference.exact()(points[:, 0], points[:, 1], 0.0)
    scale = np.abs(v).max()
    assert np.abs(given[:, 0] - u).max() < 1e-12 * scale
    assert np.abs(given[:, 1] - v).max() < 1e-12 * scale


def test_the_bar_reference_period_is_the_modal_probe_period():
    """The period the reference measures (zero crossings of the displacement projected on the
    exact mode) is the period of the modal velocity's zero crossings, the measurement the
    paper's bar uses, to 2e-3, and both are within 2% of the exact 2 L / c at spacing 0.5."""
    scene = bundled_scene("vibrating_bar_exact")
    probe = modal_velocity_probe(5.0)
    result = Simulation(scene, observers=[probe]).run()
    reference = result.summary["reference"]
    assert reference["period"] == pytest.approx(zero_crossing_period(*probe.arrays()), rel=2e-3)
    assert abs(reference["period_error"]) < 0.02
    assert reference["period_error"] == pytest.approx(reference["period"] / reference["period_exact"] - 1, rel=1e-12)


def test_lumped_q1_converges_at_second_order_on_the_manufactured_solution():
    """On the manufactured solution (no boundary effects), lumped q1 at dt = 0.5 x critical:
    the largest error over the run falls by 4 (order 2, within 0.25) from spacing 1/8 to 1/16;
    measured 2.77e-2 and 6.76e-3, order 2.03."""
    errors = []
    for spacing in (0.125, 0.0625):
        scene = bundled_scene("manufactured").with_overrides(**{"grid.basis": "q1", "grid.spacing": spacing})
        errors.append(Simulation(scene).run().summary["reference"]["error_max"])
    order = np.log2(errors[0] / errors[1])
    assert abs(order - 2.0) < 0.25, errors


# -- a reference that has no value, overflows or is 0 ------------------------------------------------


@pytest.mark.parametrize("displacement, where", [
    (["sqrt(x - 1)", "0"], lambda x0: x0[:, 0] < 1.0),  # NaN left of x = 1
    (["exp(1000*x)", "0"], lambda x0: np.ones(len(x0), bool)),  # exp(750) and more: inf
    (["10**400", "0"], lambda x0: np.ones(len(x0), bool)),
])
def test_a_reference_without_a_value_at_t0_is_refused_as_a_velocity_is(block_scene, run_cli, tmp_path,
                                                                       displacement, where):
    """Refused when the run is built, naming reference.displacement, the count (counted here
    from the seeded points) and the first point; the command line: exit 2, one line."""
    x0 = Simulation(block_scene()).particles.x0
    bad = where(x0)
    first = x0[np.argmax(bad)]
    with pytest.raises(ValueError) as error:
        Simulation(block_scene(reference={"displacement": displacement}))
    assert str(error.value) == (f"reference.displacement: gives NaN or infinity at {int(bad.sum())} point(s) at "
                                f"t = 0 s, the first at ({first[0]:g}, {first[1]:g})")
    scene = tmp_path / "bar.toml"
    scene.write_text(bundled_scene_text("vibrating_bar_exact"))
    code, out, err = run_cli(["info", scene, "--set", f"reference.displacement={json.dumps(displacement)}"])
    assert code == 2 and out == ""
    assert len(err.splitlines()) == 1 and "reference.displacement: gives NaN or infinity at " in err


def bundled_scene_text(name: str) -> str:
    from importlib.resources import files

    return (files("femgrid_mpm") / "scenes" / f"{name}.toml").read_text()


def test_a_reference_of_1e300_m_gives_its_error_without_overflow(block_scene):
    """``u = A t`` with A = 1e300 m/s against a block moving at (1, 0.25) m/s: the error is
    |A - 1| t (to 1e-300) over the scale A t, i.e. 1 at the end; their squares would overflow."""
    scene = block_scene(reference={"displacement": ["A*t", "0"], "constants": {"A": 1e300}})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        reference = Simulation(scene).run().summary["reference"]
    assert reference["scale"] == pytest.approx(1e300, rel=1e-12)
    assert reference["error_end"] == pytest.approx(1.0, rel=1e-12)
    assert reference["rms_end"] == pytest.approx(1e300, rel=1e-12)


def test_a_reference_that_is_0_reports_absolute_errors_and_says_so(block_scene):
    """Against u = 0 no relative error exists: the summary says so and gives the RMS error in
    metres, the block's rigid displacement |v| t_end (it moves exactly: round-off)."""
    reference = Simulation(block_scene(reference={"displacement": [0.0, "0"]})).run().summary["reference"]
    assert reference["error_end"] is None and reference["error_max"] is None and reference["scale"] == 0.0
    assert reference["rms_end"] == pytest.approx(np.hypot(1.0, 0.25) * 1.0, rel=1e-9)
    assert reference["rms_max"] == reference["rms_end"]
    assert reference["note"].startswith("the exact displacement is 0 at every record counted")


def test_a_reference_without_a_value_at_a_later_record_leaves_the_errors_undefined(block_scene):
    """``1 / (|t - 0.3| > 0.001)`` is 1 except within 1 ms of t = 0.3 s (a record; no time
    checked at set-up is that close): one warning, and errors None with a note, never inf."""
    scene = block_scene(reference={"displacement": ["1/(abs(t - 0.3) > 0.001)", "0"]})
    with pytest.warns(RuntimeWarning, match=r"^reference.displacement: gives NaN or infinity at t = 0.3 s") as caught:
        reference = Simulation(scene).run().summary["reference"]
    assert sum("reference.displacement" in str(w.message) for w in caught) == 1
    assert reference["error_end"] is None and reference["error_max"] is None and reference["period"] is None
    assert reference["note"] == "reference.displacement gives NaN or infinity at t = 0.3 s: the errors are undefined"
