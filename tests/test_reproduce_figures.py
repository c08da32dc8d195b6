"""The drawing helpers of ``reproduce``: which records of a stopped run are drawn, how a stop
is named, and that an energy figure of a stopped run is written and not blank."""

import matplotlib.image
import numpy as np

from femgrid_mpm.observers.energy import COLUMNS
from femgrid_mpm.reproduce.plotting import ENERGY_CREATED, energy_figure, stop_reason, valid_records


def record(total, work=None):
    """An energy record with the given ``total`` (kinetic half, strain half) and external work."""
    total = np.asarray(total, dtype=float)
    energy = {key: np.zeros_like(total) for key in COLUMNS}
    energy.update(time=0.01 * np.arange(len(total)), total=total, kinetic=total / 2, strain=total / 2)
    if work is not None:
        energy["external_work"] = np.asarray(work, dtype=float)
    return energy


def test_records_are_drawn_until_the_total_first_exceeds_the_bound():
    # 1 + ENERGY_CREATED is the bound for an initial energy 1 and no work: the first record
    # above it is the fourth (index 3); the record at the bound itself is still drawn
    total = [1.0, 1.0 + ENERGY_CREATED, 1.05, 1.0 + 2 * ENERGY_CREATED, 1.0, 50.0]
    assert valid_records(record(total)) == 3


def test_work_put_in_raises_the_bound_and_work_taken_out_does_not_lower_it():
    total = [1.0, 1.4, 1.6]
    assert valid_records(record(total, work=[0.0, 0.5, 0.5])) == 3  # bound 1.1 x 1.5 = 1.65
    assert valid_records(record([1.0, 1.05, 1.2], work=[0.0, -0.5, -0.5])) == 2  # bound stays 1.1


def test_a_run_that_keeps_its_energy_is_drawn_whole():
    assert valid_records(record(np.ones(7))) == 7


def test_a_stop_is_named_by_its_reason_and_time():
    message = "step 44 (t = 0.22 s): the energy ran away: the total energy 101847 J/m exceeds 10 x ..."
    assert stop_reason(message, 0.22) == "the energy ran away at t = 0.22 s"
    assert stop_reason("interrupted", 1.5) == "interrupted at t = 1.50 s"


def test_the_energy_figure_of_a_stopped_run_is_written_and_not_blank(tmp_path):
    path = tmp_path / "energy.png"
    energy_figure(record([1.0, 1.0, 0.9, 3.0]), "a stopped run", path, stopped=stop_reason("step 3 (t = 0.03 s): x: y", 0.03))
    image = matplotlib.image.imread(path)
    assert image.shape[0] > 400 and image.shape[1] > 800  # 150 dpi, 8 x 5.5 in before the legends
    assert image[..., :3].std() > 0.05  # curves, labels and legends on white
