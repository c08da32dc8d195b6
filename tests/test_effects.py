"""Each declared effect run alone, against an exact reference.

The references follow the step's arithmetic (:meth:`Simulation.advance`): the grid
velocity of time t moves the points (x += dt N v), the new acceleration updates
their velocity (v += dt N a), with lumped q1 mass ``m_i = sum_p m_p N_ip`` and
shape functions that sum to one.  A rigid motion has no strain, so the internal
force is zero and only the effect acts.  Tolerances are round-off: 1e-12 relative
where the reference is a closed form of the same recurrence.
"""

import xml.etree.ElementTree as ElementTree

import meshio
import numpy as np
import pytest

from femgrid_mpm.output import scene_to_toml
from femgrid_mpm.scene import Scene
from femgrid_mpm.solver import Simulation


def momentum(particles) -> np.ndarray:
    return (particles.mass[:, None] * particles.v).sum(axis=0)


def test_gravity_free_fall(block_scene):
    """No supports: f_i = m_i g, so a_i = g at every node and every point gains exactly
    g dt per step: v = g t.  The grid velocity of step k is k dt g, so the position is
    x0 + g dt^2 n (n - 1) / 2 after n steps (the discrete sum, not g t^2 / 2)."""
    g = np.array([0.5, -9.81])
    simulation = Simulation(block_scene(velocity=(0.0, 0.0), end=0.2, loads=[{"kind": "gravity", "acceleration": list(g)}]))
    assert simulation.active_effects == ["energy", "gravity"]  # in stage order
    result = simulation.run()
    n, dt, p = simulation.step_index, simulation.dt, result.particles
    assert n == 20
    np.testing.assert_allclose(p.v, np.broadcast_to(g * n * dt, p.v.shape), rtol=1e-12)
    np.testing.assert_allclose(p.x - p.x0, np.broadcast_to(g * dt**2 * n * (n - 1) / 2, p.x.shape), rtol=1e-12)
    assert abs(g[1]) * dt**2 * n / 2 > 1e3 * 1e-12  # the discrete and continuous positions differ measurably


def test_mass_damping_decays_by_one_minus_c_dt_per_step(block_scene):
    """f = -c M v with the step's lumped mass: a rigid motion's a_i = -c v, so v_{k+1} =
    (1 - c dt) v_k exactly (an explicit update; exp(-c t) only to first order: 1% off
    here) and x_n = x0 + v0 (1 - (1 - c dt)^n) / c."""
    c, v0 = 2.0, np.array([1.0, 0.25])
    simulation = Simulation(block_scene(velocity=v0, end=0.5, damping={"kind": "mass", "coefficient": c}))
    result = simulation.run()
    n, dt, p = simulation.step_index, simulation.dt, result.particles
    factor = (1 - c * dt) ** n
    np.testing.assert_allclose(p.v, np.broadcast_to(v0 * factor, p.v.shape), rtol=1e-12)
    np.testing.assert_allclose(p.x - p.x0, np.broadcast_to(v0 * (1 - factor) / c, p.x.shape), rtol=1e-12)
    assert abs(factor - np.exp(-c * n * dt)) > 1e-3  # the test tells the two apart
    # the damping's work, at the mid-step velocity, is exactly the kinetic energy lost:
    # dt c M v^2 (1 - c dt / 2) per step either way
    energy = result.energy
    np.testing.assert_allclose(energy["total_error"], 0.0, atol=1e-12 * energy["total"][0])


def test_point_load_impulse_with_ramp(block_scene):
    """Sum over nodes of m_i a_i is the total force (internal forces sum to zero): the
    body's momentum is the impulse, the right sum dt F sum_k min(1, k dt / t_ramp) of
    the force at each step's force time t + dt, the stress's instant (0.155 F here; the
    integral is 0.15 F, which the paper's step reaches at t + dt / 2: its velocities are
    those of the half step; the force at the step's start gave 0.145 F)."""
    force, ramp = np.array([3.0, -2.0]), 0.1
    load = {"kind": "point", "body": "block", "at": [1.75, 1.5], "force": list(force), "ramp": ramp}
    simulation = Simulation(block_scene(velocity=(0.0, 0.0), end=0.2, loads=[load]))
    result = simulation.run()
    dt = simulation.dt
    impulse = force * dt * sum(min(1.0, k * dt / ramp) for k in range(1, simulation.step_index + 1))
    np.testing.assert_allclose(impulse, 0.155 * force, rtol=1e-12)
    # round-off of the internal forces' sum, relative to the impulse
    np.testing.assert_allclose(momentum(result.particles), impulse, rtol=1e-10, atol=1e-12 * abs(force).max())


def test_supports_hold_a_clamped_end(block_scene):
    """A block falling under gravity, its nodes at x <= 1 fixed: the points in the
    cells between x = 0.5 and 1 (all their nodes fixed) get zero acceleration and
    move with zero grid velocity, so they stay where they were seeded (to the
    round-off of the partition of unity, 1e-14 m) with zero velocity, while the
    free end falls."""
    gravity = [{"kind": "gravity", "acceleration": [0.0, -9.81]}]
    scene = block_scene(velocity=(0.0, 0.0), end=0.2, loads=gravity, supports=[{"where": "x <= 1", "fix": ["x", "y"]}])
    result = Simulation(scene).run()
    p = result.particles
    clamped = p.x0[:, 0] < 1.0
    assert clamped.sum() == 6  # the column at x = 5/6 (the next one is on the node line x = 1)
    np.testing.assert_allclose(p.x[clamped], p.x0[clamped], rtol=0, atol=1e-14)
    np.testing.assert_allclose(p.v[clamped], 0.0, rtol=0, atol=1e-14)
    free_end = p.x0[:, 0] > 1.5
    assert (p.x0[free_end, 1] - p.x[free_end, 1]).min() > 1e-3  # it does fall


def two_blocks(contact=None, velocities=((0.93, 0.2), (-1.07, 0.0))) -> Scene:
    """Two blocks 1 m apart approaching at 2 m/s, wave speed sqrt(E / rho) = 31.6 m/s
    (the speeds keep every point away from the grid's node lines: see
    :func:`test_frictional_contact_with_a_point_on_a_node_line`)."""
    material = {"E": 1e6, "nu": 0.3, "density": 1e3}
    data = {
        "grid": {"basis": "q1", "lower": [0, 0], "upper": [6, 3], "spacing": 0.5},
        "time": {"dt": 0.005, "end": 0.6},
        "bodies": [
            {"name": "left", "lower": [1.0, 1.0], "upper": [2.0, 2.0], "points_per_cell": 2,
             "velocity": list(velocities[0]), "material": material},
            {"name": "right", "lower": [3.0, 1.0], "upper": [4.5, 2.0], "points_per_cell": 2,
             "velocity": list(velocities[1]), "material": material},
        ],
    }
    if contact is not None:
        data["contact"] = contact
    return Scene.model_validate(data)


def test_frictional_contact_conserves_momentum_and_stops_interpenetration():
    """The correction is equal and opposite at every shared node (n_left = -n_right,
    sum_b m_b (v_b - v_cm) = 0): the total momentum is the initial one to round-off
    (1e-12 of its size).  The bodies meet and part again: their points never come
    closer than one point spacing (0.25 m, when the surfaces touch) less twice what
    one step can overlap (v dt = 0.01 m) and the elastic compression of the two
    surface half-spacings (strain v / 2c: 0.008 m); measured 0.018 m in all.  Without
    the correction the points would pass each other."""
    simulation = Simulation(two_blocks({"kind": "frictional", "friction": 0.3}))
    assert "contact" in simulation.active_effects
    p = simulation.particles
    left, right = simulation.body_slices
    initial = momentum(p)
    closest, near_node_line = np.inf, np.inf
    for _ in range(simulation.n_steps):
        simulation.advance()
        np.testing.assert_allclose(momentum(p), initial, rtol=0, atol=1e-12 * np.abs(p.mass * p.v[:, 0]).sum())
        closest = min(closest, p.x[right, 0].min() - p.x[left, 0].max())
        offset = p.x / 0.5 - np.round(p.x / 0.5)
        near_node_line = min(near_node_line, np.abs(offset).min() * 0.5)
    assert near_node_line > 1e-9  # the case this test covers (see two_blocks)
    assert closest < 0.25 + 0.05  # they did meet
    assert closest > 0.25 - 2.0 * (2.0 * simulation.dt + 0.008)
    left_velocity, right_velocity = ((p.mass[m, None] * p.v[m]).sum(axis=0) / p.mass[m].sum() for m in (left, right))
    assert left_velocity[0] < right_velocity[0]  # parting: the approach stopped


def test_frictional_contact_with_a_point_on_a_node_line():
    """Speeds of 1 m/s put a column of the right body's points on the node line
    x = 3 at step 75 (to 8e-15 m): its momentum must still be conserved to round-off
    while the bodies are still 0.2 m apart and the contact does nothing (each field
    computes in the frame of its own body's first point: in body 0's frame, a node the
    right body touches with a round-off weight took body 0's velocity and strained it)."""
    simulation = Simulation(two_blocks({"kind": "frictional"}, velocities=((1.0, 0.2), (-1.0, 0.0))))
    p = simulation.particles
    initial = momentum(p)
    for _ in range(80):
        simulation.advance()
    np.testing.assert_allclose(momentum(p), initial, rtol=0, atol=1e-12 * np.abs(p.mass * p.v[:, 0]).sum())


def test_shared_contact_runs_no_code_of_its_own():
    """``kind = "shared"`` is the single-field step: bit for bit the run without [contact]
    (the bodies meet and stick within the run)."""
    plain = Simulation(two_blocks())
    shared = Simulation(two_blocks({"kind": "shared"}))
    assert shared.active_effects == plain.active_effects == []
    first, second = plain.run().particles, shared.run().particles
    for name in ("x", "v", "stress", "strain", "density"):
        np.testing.assert_array_equal(getattr(second, name), getattr(first, name))


def test_energy_observer_records_the_particles_energies(block_scene):
    """The last record is taken at the final state: its kinetic energy is
    1/2 sum m |v|^2 and its strain energy 1/2 sum (m / rho) sigma : eps (the tensor
    shear counted twice) of the final points; the first is 1/2 sum m |v0(x0)|^2 with
    no strain.  1e-12 relative: only the order of the sums differs."""
    velocity = ("0.2*sin(pi*x/2)", "0.1*cos(pi*y)")
    result = Simulation(block_scene(velocity=velocity, end=0.2, every=4)).run()
    p, energy = result.particles, result.energy
    v0 = np.column_stack([0.2 * np.sin(np.pi * p.x0[:, 0] / 2), 0.1 * np.cos(np.pi * p.x0[:, 1])])
    assert energy["kinetic"][0] == pytest.approx(0.5 * np.sum(p.mass[:, None] * v0**2), rel=1e-12)
    assert energy["strain"][0] == 0.0
    kinetic = 0.5 * np.sum(p.mass[:, None] * p.v**2)
    double_contraction = p.stress[:, 0] * p.strain[:, 0] + p.stress[:, 1] * p.strain[:, 1] + 2 * p.stress[:, 2] * p.strain[:, 2]
    strain = 0.5 * np.sum(p.mass / p.density * double_contraction)
    assert strain > 1e-3 * kinetic  # the block deformed
    assert energy["time"][-1] == pytest.approx(0.2, rel=1e-12)
    assert energy["kinetic"][-1] == pytest.approx(kinetic, rel=1e-12)
    assert energy["strain"][-1] == pytest.approx(strain, rel=1e-12)
    assert energy["total_error"][-1] == pytest.approx(kinetic + strain - energy["total"][0], rel=1e-12)


def test_particle_output_writes_the_series(tmp_path, block_scene, run_cli):
    """``[output] particles = true`` through the command line: one file per record
    (steps 0, 4, ..., 20, the last the final state), listed in ``particles.pvd`` with
    its time, holding the state an in-process run has at that step (stored in float64:
    equal to 1e-15)."""
    scene = block_scene(velocity=("0.2*sin(pi*x/2)", "0.1*cos(pi*y)"), end=0.2, output={"every": 4, "particles": True})
    path = tmp_path / "scene.toml"
    path.write_text(scene_to_toml(scene))
    code, _, err = run_cli(["run", path, "--out", tmp_path / "out"])
    assert code == 0, err
    root = ElementTree.parse(tmp_path / "out" / "particles.pvd").getroot()
    series = [(float(d.get("timestep")), d.get("file")) for d in root.find("Collection").findall("DataSet")]
    simulation = Simulation(scene)
    expected = []
    for step in range(simulation.n_steps + 1):
        if step % 4 == 0:
            p = simulation.particles
            expected.append((simulation.time, p.x.copy(), p.v.copy(), p.x - p.x0, p.stress[:, 0].copy()))
        if step < simulation.n_steps:
            simulation.advance()
    assert [t for t, _ in series] == pytest.approx([t for t, *_ in expected], rel=1e-12, abs=1e-15)
    for (_, name), (_, x, v, displacement, stress_xx) in zip(series, expected):
        mesh = meshio.read(tmp_path / "out" / name)
        np.testing.assert_allclose(mesh.points[:, :2], x, rtol=1e-15)
        np.testing.assert_allclose(mesh.point_data["velocity"][:, :2], v, rtol=1e-15, atol=1e-18)
        np.testing.assert_allclose(mesh.point_data["displacement"][:, :2], displacement, rtol=1e-15, atol=1e-18)
        np.testing.assert_allclose(mesh.point_data["stress_xx"], stress_xx, rtol=1e-15, atol=1e-12)


def test_every_registry_entry_is_its_class_kind():
    """A table of several kinds dispatches on ``kind``: each registry entry's ``kind`` must be
    its class's own (a mismatch would route a scene's table to another class)."""
    import typing

    from femgrid_mpm.effects import REGISTRY

    kinds = [entry for entry in REGISTRY if entry.kind is not None]
    assert kinds  # the loads and damping tables have kinds
    for entry in kinds:
        assert typing.get_args(typing.get_type_hints(entry.effect)["kind"]) == (entry.kind,), entry
