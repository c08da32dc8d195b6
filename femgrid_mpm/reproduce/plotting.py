"""Matplotlib helpers shared by the reproduction scripts (Agg backend, no screen)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402

#: the paper's legend for its energy figures (Figs. 4-7, 14-16)
ENERGY_CURVES = (
    ("kinetic", "Kinetic energy (points)", "-"),
    ("kinetic_grid", "Kinetic energy (grid)", "--"),
    ("strain", "Potential energy", "-"),
    ("total", "Total energy", "-"),
    ("interpolation_error", "Interpolation error", ":"),
    ("algorithm_error", "Algorithm error", ":"),
    ("total_error", "Total error", "-."),
)


def energy_figure(energy: dict, title: str, path) -> None:
    """One of the paper's energy-measure figures, written to ``path`` (PNG).

    The paper draws energies and errors on one axis; the errors are two
    orders smaller, so they get a second panel of their own here.
    """
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True, height_ratios=(3, 2))
    for key, label, style in ENERGY_CURVES:
        axes = bottom if key.endswith("error") else top
        axes.plot(energy["time"], energy[key], style, label=label, linewidth=1.2)
    top.set_ylabel("Energy (J per m)")
    bottom.set_ylabel("Error (J per m)")
    bottom.set_xlabel("Time (s)")
    top.set_title(title)
    for axes in (top, bottom):
        axes.grid(alpha=0.3)
        axes.legend(fontsize=8, loc="upper right")
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def markdown_table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"
