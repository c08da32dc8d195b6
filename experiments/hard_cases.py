"""The tables of docs/hard_cases.md: HRZ and the mass threshold against row sums.

Run: ``python experiments/hard_cases.py`` (about a minute).  Prints

1. the vibrating bar (paper resolution, 8 s) with lumped and HRZ mass for
   q1, q2, serendipity and bspline3: period against the 2D modal reference,
   energy drift, the largest interpolation error, the stable step in element
   widths over the p-wave speed;
2. q2's hard cases under ``negative_mass`` = error, warn, threshold and
   under ``mass = "hrz"``: how each run ends, its energy and momentum;
3. the issue's global HRZ variant (``m_i = M_ii sum m / sum M_jj``, velocity
   ``sum m_p N_ip^2 v_p / M_ii``, G2P through N) against HRZ per point: a
   block in free fall, and the drifting bar.
"""

from __future__ import annotations

import os
import warnings

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from femgrid_mpm.engines import ScipyTransfer  # noqa: E402
from femgrid_mpm.mass import Assembly, Inertia, MassModel  # noqa: E402
from femgrid_mpm.analysis import bar_axial_period_2d, modal_velocity_probe, zero_crossing_period  # noqa: E402
from femgrid_mpm.diagnostics import SimulationStopped  # noqa: E402
from femgrid_mpm.scene import Scene, bundled_scene  # noqa: E402
from femgrid_mpm.solver import Simulation  # noqa: E402

POLICIES = [("lumped", "error"), ("lumped", "warn"), ("lumped", "threshold"), ("hrz", "error")]


def run(simulation):
    """(result, stop or None)."""
    try:
        return simulation.run(), None
    except SimulationStopped as stop:
        return stop.result, stop


def bar_table():
    print("| basis | mass | period (s) | vs 2D | energy drift | max abs E_int | stable step (width / c_p) |")
    print("|---|---|---|---|---|---|---|")
    reference = bar_axial_period_2d(5.0, 1.0, 1e4, 0.3, 1e3, "strain")
    for basis in ("q1", "q2", "serendipity", "bspline3"):
        for mass in ("lumped", "hrz"):
            scene = bundled_scene("vibrating_bar").with_overrides(
                **{"grid.basis": basis, "solver.mass": mass, "solver.negative_mass": "warn"})
            probe = modal_velocity_probe(5.0)
            simulation = Simulation(scene, observers=[probe])
            critical = simulation.critical_dt * simulation.materials[0].wave_speed / simulation.grid.discretization.element_width
            result, _ = run(simulation)
            period = zero_crossing_period(*probe.arrays())
            total = result.energy["total"]
            print(f"| {basis} | {mass} | {period:.4f} | {100 * (period / reference - 1):+.2f}% | "
                  f"{100 * np.max(np.abs(total - total[0])) / total[0]:.2f}% | "
                  f"{np.max(np.abs(result.energy['interpolation_error'])):.2e} | {critical:.2f} |", flush=True)


def q2_cases():
    drifting = {"grid.lower": (-2.0, 0.0), "grid.upper": (18.0, 1.0), "output.every": 10}
    cases = {
        "box impact, 3 s": bundled_scene("box_impact"),
        "bar ending inside an element (4.75 m)": bundled_scene("vibrating_bar").with_overrides(**{"bodies.0.upper": (4.75, 1.0)}),
        "bar, amplitude 0.5": bundled_scene("vibrating_bar").with_overrides(
            **{"grid.lower": (-1.0, 0.0), "bodies.0.velocity": ("0.5*cos(pi*x/5)", "0"), "output.every": 10}),
        "bar drifting at 1 m/s, amplitude 0.2": bundled_scene("vibrating_bar").with_overrides(
            **{**drifting, "bodies.0.velocity": ("1.0 + 0.2*cos(pi*x/5)", "0")}),
    }
    for name, scene in cases.items():
        print(f"\n{name}:")
        for mass, policy in POLICIES:
            simulation = Simulation(scene.with_overrides(**{"grid.basis": "q2", "solver.mass": mass, "solver.negative_mass": policy}))
            initial_momentum = (simulation.particles.mass[:, None] * simulation.particles.v).sum(axis=0)
            result, stop = run(simulation)
            p = result.particles
            momentum = (p.mass[:, None] * p.v).sum(axis=0)
            drift = 0.5 * p.mass.sum() * (initial_momentum[0] / p.mass.sum()) ** 2  # the drift's kinetic energy
            vibration = result.energy["total"] - drift
            ending = f"stopped at step {stop.step} ({stop.reason})" if stop else "completed"
            if len(vibration) == 0:  # stopped before the first record
                print(f"  {mass:6s} {policy:9s}: {ending}", flush=True)
                continue
            print(f"  {mass:6s} {policy:9s}: {ending}; energy within {100 * np.max(np.abs(vibration - vibration[0])) / vibration[0]:.1f}%"
                  f" (max {100 * (vibration.max() / vibration[0] - 1):+.1f}%), momentum change {np.abs(momentum - initial_momentum).max():.3g}",
                  flush=True)


class GlobalHrz(MassModel):
    """HRZ over the whole grid, for comparison only: transfers through N (the scipy engine)."""

    kind = "hrz"
    assembly = Assembly()

    def __init__(self, simulation):
        self.simulation = simulation

    def assemble(self, N, m_p, volume_p=None):
        self.lumped = N.T @ m_p
        self.squares = N.multiply(N).tocsr()
        self.m_ii = self.squares.T @ m_p
        self.diagonal = self.m_ii * m_p.sum() / self.m_ii.sum()
        self.active = self.m_ii > 0
        self._inverse = np.divide(1.0, self.diagonal, out=np.zeros_like(self.diagonal), where=self.active)

    def grid_velocity(self, relative_momentum, frame_velocity):
        p = self.simulation.particles
        weighted = self.squares.T @ (p.mass[:, None] * (p.v - frame_velocity))
        velocity = np.divide(weighted, self.m_ii[:, None], out=np.zeros_like(weighted), where=self.active[:, None]) + frame_velocity
        return self.diagonal[:, None] * velocity, velocity

    def solve(self, rhs, kind="velocity"):
        return rhs * self._inverse[:, None]

    def assemble_sums(self, sums):
        raise NotImplementedError("assembled from the matrices only")

    def inertia(self, N):
        return Inertia(inverses=(self._inverse, self._inverse), transfer=N)

    def apply(self, vector):
        return vector * self.diagonal[:, None]


def with_global_hrz(scene):
    simulation = Simulation(scene)
    simulation.mass = GlobalHrz(simulation)
    simulation.transfer = ScipyTransfer(simulation)
    simulation.context = simulation.transfer.context(simulation, simulation.dt)
    return simulation


def global_against_per_point():
    g = -9.81
    for basis in ("q2", "serendipity"):
        block = Scene.model_validate({
            "grid": {"basis": basis, "lower": [0, -4], "upper": [4, 3], "spacing": 0.5}, "time": {"dt": 0.01, "end": 0.3},
            "solver": {"mass": "hrz", "engine": "scipy"},
            "bodies": [{"name": "block", "lower": [0.75, 0.5], "upper": [1.75, 1.5], "points_per_cell": 3,
                        "material": {"E": 1e4, "nu": 0.3, "density": 1e3}}],
            "loads": [{"kind": "gravity", "acceleration": [0.0, g]}], "output": {"every": 10}})
        bar = bundled_scene("vibrating_bar").with_overrides(**{
            "grid.basis": basis, "solver.mass": "hrz", "solver.engine": "scipy", "grid.lower": (-2.0, 0.0),
            "grid.upper": (18.0, 1.0), "bodies.0.velocity": ("1.0 + 0.2*cos(pi*x/5)", "0"), "output.every": 10})
        for name, build in (("per point", Simulation), ("global", with_global_hrz)):
            result, _ = run(build(block))
            v = result.particles.v[:, 1]
            print(f"{basis} {name}: free fall 0.3 s, v_y mean {v.mean():.4f} m/s (exact {g * 0.3:.4f}), spread {np.ptp(v):.3g} m/s")
            result, stop = run(build(bar))
            p = result.particles
            momentum = (p.mass[:, None] * p.v).sum(axis=0)
            ending = f"stopped at step {stop.step} ({stop.reason})" if stop else "completed"
            print(f"{basis} {name}: drifting bar, {ending}, momentum {momentum[0]:.6g}, {momentum[1]:.3g} (exact 5000, 0)", flush=True)


if __name__ == "__main__":
    warnings.simplefilter("ignore")  # negative masses under "warn" are expected here
    bar_table()
    q2_cases()
    print()
    global_against_per_point()
