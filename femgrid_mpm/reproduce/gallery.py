"""The README's gallery: which figure of which case each picture is.

``femgrid-mpm reproduce --gallery docs/gallery`` copies them there after the
run, so the pictures a reader sees first are the ones ``reproduce`` makes.

Examples
--------
>>> sorted({case for case, _ in GALLERY.values()})
['box_impact', 'cantilever', 'cost_accuracy', 'vibrating_bar']
"""

from __future__ import annotations

import shutil
from pathlib import Path

#: picture name -> (case of :data:`femgrid_mpm.reproduce.CASES`, the figure's path under the case's directory)
GALLERY = {
    "work_precision.png": ("cost_accuracy", "bar_convergence/work_precision.png"),
    "bar_energy_q1.png": ("vibrating_bar", "fig04_energy_q1.png"),
    "bar_energy_serendipity.png": ("vibrating_bar", "fig05_energy_serendipity.png"),
    "bar_energy_bspline3.png": ("vibrating_bar", "fig07_energy_bspline3.png"),
    "cantilever_stress.png": ("cantilever", "fig10_stress_xx.png"),
    "box_impact.png": ("box_impact", "fig17_box_height.png"),
    "negative_masses.png": ("vibrating_bar", "negative_masses.png"),
}


def copy_gallery(results: Path, gallery: Path, cases) -> list[Path]:
    """Copy the gallery's figures of ``cases`` from ``results/CASE/`` into ``gallery``.

    Returns the pictures written.  A figure its case did not write is an
    error of the case (``FileNotFoundError``), not of the user's input.
    """
    gallery = Path(gallery)
    gallery.mkdir(parents=True, exist_ok=True)
    written = []
    for name, (case, figure) in GALLERY.items():
        if case in cases:
            written.append(Path(shutil.copyfile(Path(results) / case / figure, gallery / name)))
    return written
