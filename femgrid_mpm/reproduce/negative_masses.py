"""Where negative lumped grid masses appear: the nodes of the paper's scenes at t = 0.

A node's lumped mass is the row sum ``m_i = sum_p N_i(x_p) m_p``; where a basis'
functions turn negative and the points do not fill the function's whole
support, it can be negative.  Serendipity's corner functions integrate to
-1/12 of an element, so its corners are negative in every filled element;
q2's are negative only where a body's edge lies inside an element (the box
of the box impact; the bar's edges lie on element edges, so the bar has none).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt

from ..scene import bundled_scene
from ..solver import Simulation
from .plotting import save, styled

#: (panel title, bundled scene, basis)
PANELS = (("serendipity, vibrating bar", "vibrating_bar", "serendipity"),
          ("q2, box impact", "box_impact", "q2"))


def nodal_masses(scene_name: str, basis: str):
    """The grid's nodes, their lumped masses over a full cell of their densest body, and the points."""
    scene = bundled_scene(scene_name).with_overrides(**{"grid.basis": basis, "solver.mass": "lumped",
                                                        "solver.negative_mass": "warn"})
    simulation = Simulation(scene)
    grid, particles = simulation.grid, simulation.particles
    N, _, _ = grid.shape_functions(particles.x)
    mass = N.T @ particles.mass
    full_cell = max(body.material.density for body in scene.bodies) * grid.spacing**2
    return grid.nodes, mass / full_cell, particles.x


@styled
def figure(path: Path) -> dict:
    """Draw :data:`PANELS` into ``path``; the count of negative nodes per panel."""
    fig, axes = plt.subplots(len(PANELS), 1, figsize=(8, 7.5))
    counts = {}
    for ax, (title, scene_name, basis) in zip(axes, PANELS):
        nodes, ratio, points = nodal_masses(scene_name, basis)
        touched = ratio != 0.0
        negative = ratio < -1e-12
        counts[title] = int(negative.sum())
        ax.scatter(points[:, 0], points[:, 1], s=2, color="0.75", zorder=1)
        shown = ax.scatter(nodes[touched, 0], nodes[touched, 1], c=ratio[touched], cmap="coolwarm_r",
                           vmin=-1.5, vmax=1.5, s=28, edgecolors="0.3", linewidths=0.4, zorder=2)
        ax.scatter(nodes[negative, 0], nodes[negative, 1], s=90, facecolors="none", edgecolors="crimson",
                   linewidths=1.4, zorder=3)
        ax.set_title(f"{title}: {counts[title]} nodes of negative lumped mass at t = 0\n(circled; grey: the points)",
                     fontsize=10)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_aspect("equal")
        fig.colorbar(shown, ax=ax, label="nodal mass / full cell's mass", shrink=0.8)
    fig.tight_layout()
    save(fig, path)
    return counts
