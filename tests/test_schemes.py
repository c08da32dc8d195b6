"""The time integration schemes (``[solver] scheme``): the paper's order, the centred
difference and Yoshida's fourth-order composition of it.

The paper's step is the central difference of the positions once the points'
velocity is that of t + dt/2; started from v(0) it keeps an error dt/2 a(0)
(first order in dt), which the centred scheme's starting half step removes
(docs/accuracy.md).
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from femgrid_mpm.scene import Scene, SceneError, bundled_scene
from femgrid_mpm.schemes import SCHEMES
from femgrid_mpm.solver import Simulation

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "experiments"))
from error_sources import run, scene  # noqa: E402
from helpers import bundled_variant  # noqa: E402


def oscillator_step(scheme, h: float, last: bool = False) -> np.ndarray:
    """The scheme's map of (x, v) for x'' = -x over one step h in its staggered form (the start
    kick before, the end's shortened kick after), written from its table alone."""
    kick = lambda c: np.array([[1.0, 0.0], [-c * h, 1.0]])  # noqa: E731
    drift = lambda d: np.array([[1.0, d * h], [0.0, 1.0]])  # noqa: E731
    step = np.eye(2)
    for index, (d, c) in enumerate(zip(scheme.drifts, scheme.kicks)):
        if last and index == scheme.passes - 1:
            c -= scheme.start_kick
        step = kick(c) @ drift(d) @ step
    return step


@pytest.mark.parametrize("name", sorted(SCHEMES))
def test_each_scheme_has_its_order_and_its_stability_limit_on_the_harmonic_oscillator(name):
    """x'' = -x from (1, 0) to t = 1 in n steps: the error against (cos t, -sin t) falls as h^order
    (log2 of the ratio from n = 16 to 32 within 0.1 of the declared order; the paper's order is
    first order from this start, a(0) = -1); and the one-step map's spectral radius is 1 below
    ``stability_limit`` (at 0.999 of it, to 1e-9) and above 1 beyond it (at 1.001)."""
    scheme = SCHEMES[name]

    def error(n: int) -> float:
        h = 1.0 / n
        state = np.array([1.0, 0.0])
        state = np.array([[1.0, 0.0], [-scheme.start_kick * h, 1.0]]) @ state
        for k in range(n):
            state = oscillator_step(scheme, h, last=k == n - 1) @ state
        return float(np.hypot(state[0] - np.cos(1.0), state[1] + np.sin(1.0)))

    assert abs(np.log2(error(16) / error(32)) - scheme.order) < 0.1, (error(16), error(32))
    radius = lambda h: np.abs(np.linalg.eigvals(oscillator_step(scheme, h))).max()  # noqa: E731
    assert radius(0.999 * scheme.stability_limit) < 1 + 1e-9
    assert radius(1.001 * scheme.stability_limit) > 1 + 1e-3


@pytest.mark.parametrize("basis", ["q1", "bspline3"])
def test_a_falling_block_falls_exactly_with_the_centred_and_fourth_order_schemes_and_half_a_step_behind_with_the_paper_one(
        block_scene, basis):
    """Free fall from rest, g = -9.81, dt = 0.01, 20 steps: the centred scheme is velocity
    Verlet, exact for a constant acceleration, y - y0 = g T^2/2 and v = g T; the paper's order
    moves by sum_k dt (k dt g) = g dt^2 n (n - 1)/2 = g T^2/2 - g T dt/2 (to 1e-12 m)."""
    g, dt, n = -9.81, 0.01, 20
    end = n * dt
    fallen = {}
    for scheme in ("paper", "centred", "yoshida4"):
        current = block_scene(basis, velocity=(0.0, 0.0), dt=dt, end=end, every=None,
                              loads=[{"kind": "gravity", "acceleration": [0.0, g]}],
                              solver={"mass": "lumped", "negative_mass": "warn", "scheme": scheme})
        p = Simulation(current).run().particles
        np.testing.assert_allclose(p.x[:, 0], p.x0[:, 0], rtol=0, atol=1e-12)
        fallen[scheme] = (p.x[:, 1] - p.x0[:, 1], p.v[:, 1])
    np.testing.assert_allclose(fallen["centred"][0], 0.5 * g * end**2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fallen["centred"][1], g * end, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fallen["yoshida4"][0], 0.5 * g * end**2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fallen["yoshida4"][1], g * end, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fallen["paper"][0], 0.5 * g * end**2 - 0.5 * g * end * dt, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fallen["paper"][1], g * end, rtol=0, atol=1e-12)


def time_order(from_rest: bool, scheme: str, steps=(20, 40, 80)) -> tuple[float, float]:
    """Order in dt of lumped q1 at h = 1/16 on the manufactured solution: the log2 ratio of
    the time errors |u(dt) - u(dt/2)| at the end (the spatial error is the same in both runs),
    and the largest error against the exact field at the finest step."""
    runs = [run(scene("q1", "lumped", 1 / 16, steps=n, from_rest=from_rest, **{"solver.scheme": scheme}))
            for n in steps]
    differences = [np.sqrt(np.mean(np.sum((a["u"] - b["u"]) ** 2, axis=1))) for a, b in zip(runs, runs[1:])]
    return float(np.log2(differences[0] / differences[1])), runs[-1]["whole"]


def test_the_centred_scheme_is_second_order_in_dt_where_the_paper_one_is_first():
    """From rest (u = A s (1 - cos w t), a(0) != 0), dt = T/20, T/40, T/80 (0.92 to 0.23 of
    the critical step): the paper's order is 1 (measured 1.00, error 4.6e-2 at T/80 against the
    exact field), the centred scheme's 2 (measured 1.94, error 6.1e-3, the spatial error);
    both within 0.15."""
    paper, paper_error = time_order(True, "paper")
    centred, centred_error = time_order(True, "centred")
    assert abs(paper - 1.0) < 0.15, paper
    assert abs(centred - 2.0) < 0.15, centred
    assert centred_error < 0.2 * paper_error, (centred_error, paper_error)


def test_the_fourth_order_scheme_is_fourth_order_in_dt_from_rest():
    """The same field from rest at dt = T/40, T/80, T/160 (0.59 to 0.15 of its critical step,
    which is 0.787 of the centred one's): order 4 (measured 4.02) within 0.3; the error against
    the exact field is then the spatial one (6.2e-3, as the centred scheme's within 5%)."""
    order, error = time_order(True, "yoshida4", steps=(40, 80, 160))
    assert abs(order - 4.0) < 0.3, order
    centred = run(scene("q1", "lumped", 1 / 16, steps=160, from_rest=True, **{"solver.scheme": "centred"}))["whole"]
    assert error == pytest.approx(centred, rel=0.05)


def test_the_fourth_order_scheme_refuses_contact():
    """Contact corrects a velocity over one step; a composition's sub-steps (one of them
    negative) have no such step: the scene is refused with the key named."""
    data = {"grid": {"basis": "q1", "lower": [0, 0], "upper": [4, 4], "spacing": 0.5},
            "time": {"dt": 0.01, "end": 0.1}, "solver": {"scheme": "yoshida4"}, "contact": {"kind": "shared"},
            "bodies": [{"name": "a", "lower": [0.5, 0.5], "upper": [1.5, 1.5],
                        "material": {"E": 1e4, "nu": 0.3, "density": 1e3}}]}
    with pytest.raises(SceneError, match="solver.scheme: 'yoshida4'"):
        Scene.model_validate(data)
    data["solver"]["scheme"] = "centred"
    Scene.model_validate(data)


def test_the_paper_order_is_second_order_when_the_initial_acceleration_is_zero():
    """The bundled manufactured field (u = A s sin w t: a(0) = 0): the paper's order is
    second order in dt already (measured 2.00), and the centred scheme the same (within 0.15)."""
    assert abs(time_order(False, "paper")[0] - 2.0) < 0.15
    assert abs(time_order(False, "centred")[0] - 2.0) < 0.15


@pytest.mark.parametrize("scheme", ["centred", "yoshida4"])
@pytest.mark.parametrize("basis, mass", [("bspline3", "consistent"), ("q2", "hrz")])
def test_the_engines_agree_on_the_centred_and_fourth_order_schemes(basis, mass, scheme):
    """scipy and numba, 60 steps of the manufactured solution from rest at h = 1/8: the
    displacement, velocity and stress agree to 1e-12 of each field's largest value."""
    results = {}
    for engine in ("scipy", "numba"):
        simulation = Simulation(scene(basis, mass, 1 / 8, steps=300, from_rest=True,
                                      **{"solver.scheme": scheme, "solver.engine": engine, "time.end": 0.126}))
        results[engine] = simulation.run().particles
    expected, actual = results["scipy"], results["numba"]
    assert simulation.n_steps == 60
    for name, of in (("displacement", lambda p: p.x - p.x0), ("velocity", lambda p: p.v),
                     ("stress", lambda p: p.stress)):
        reference = of(expected)
        np.testing.assert_allclose(of(actual), reference, rtol=0, atol=1e-12 * np.abs(reference).max(), err_msg=name)


def bar_errors(spacing: float) -> tuple[float, float]:
    """The exact first mode of the free bar (nu = 0, 1e-6 m/s: linear to 1e-7), consistent cubic
    splines, ``scheme = "yoshida4"`` at ``dt = "auto"`` (its time error far below its spatial one),
    to t = 1 s: the largest |u - u_exact| / (A / w) over the points within one cell of the bar's
    ends, and its root mean square over the points more than 1 m from them."""
    amplitude, w = 1e-6, 1.9869176531592203
    current = bundled_variant("vibrating_bar_exact", "bspline3", "consistent", **{
        "solver.scheme": "yoshida4", "grid.spacing": spacing, "time.end": 1.0, "output": None,
        "bodies.0.velocity": [f"{amplitude}*cos(pi*x/5)", "0"],
        "reference.constants": {"A": amplitude, "L": 5.0, "w": w}})
    simulation = Simulation(current)
    p = simulation.run().particles
    exact = (amplitude / w) * np.cos(np.pi * p.x0[:, 0] / 5) * np.sin(w * simulation.end_time)
    error = np.hypot(p.x[:, 0] - p.x0[:, 0] - exact, p.x[:, 1] - p.x0[:, 1]) / (amplitude / w)
    ends = np.minimum(p.x0[:, 0], 5 - p.x0[:, 0])
    return float(error[ends < spacing].max()), float(np.sqrt(np.mean(error[ends > 1.0] ** 2)))


def test_the_bars_remaining_error_is_second_order_at_its_free_ends_and_higher_inside():
    """docs/accuracy.md: with the time error gone, consistent cubic splines on the free bar err at
    the ends by the points' sum truncated there, ~(w h / c)^2 / (24 ppc^2), second order (measured
    4.37e-4 -> 1.11e-4 from h = 0.5 to 0.25, ratio 3.93: within 4 +- 0.4), while the interior
    converges at third order or better (4.93e-5 -> 1.82e-6, ratio 27: above 8)."""
    ends_coarse, inside_coarse = bar_errors(0.5)
    ends_fine, inside_fine = bar_errors(0.25)
    assert 3.6 < ends_coarse / ends_fine < 4.4, (ends_coarse, ends_fine)
    assert inside_coarse / inside_fine > 8, (inside_coarse, inside_fine)


@pytest.mark.parametrize("scheme", ["centred", "yoshida4"])
def test_a_run_resumed_half_way_repeats_the_whole_run_bit_for_bit(scheme):
    """The mode on rollers at h = 1/8 to t = 0.05 s (16 or 20 steps): the state half-way (``Simulation.state``) taken
    into a new simulation that runs on gives the same positions and velocities, bit for bit (the
    start kick belongs to step 0 alone, the shortened last kick to the run's last step)."""
    current = bundled_scene("manufactured_rollers").with_overrides(**{
        "grid.spacing": 0.125, "solver.scheme": scheme, "time.end": 0.05, "output": None})
    whole = Simulation(current).run().particles
    first = Simulation(current)
    assert first.n_steps >= 16
    for _ in range(first.n_steps // 2):
        first.advance()
    resumed = Simulation(current)
    resumed.restore(*first.state())
    rest = resumed.run().particles
    assert np.array_equal(rest.x, whole.x) and np.array_equal(rest.v, whole.v)
