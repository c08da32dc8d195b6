"""The cost-accuracy case's table of orders (``femgrid_mpm.reproduce.cost_accuracy``), on a
``runs.csv`` written by hand with errors of known order."""

import csv

import pytest

from femgrid_mpm.reproduce.cost_accuracy import SWEEPS, order_table
from femgrid_mpm.sweep import plan, read_sweep
from femgrid_mpm.sweep.spec import BUNDLED_SWEEPS
from femgrid_mpm.sweep.table import DESCRIPTION_COLUMNS, RESULT_COLUMNS


def test_the_order_table_fits_the_order_of_each_method(tmp_path):
    """Errors ``e = 3 h^2`` (q1) and ``e = 0.5 h`` (bspline3) give orders 2 and 1 to 1e-12; a
    stopped run is left out."""
    (tmp_path / "sweep.toml").write_text('scene = "vibrating_bar_exact"\n[vary]\n"grid.basis" = ["q1", "bspline3"]\n'
                                         '"grid.spacing" = [0.5, 0.25, 0.125]\n')
    header = ["grid.basis", "grid.spacing", *RESULT_COLUMNS, *DESCRIPTION_COLUMNS]
    with open(tmp_path / "runs.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, header)
        writer.writeheader()
        for basis, error in (("q1", lambda h: 3 * h**2), ("bspline3", lambda h: 0.5 * h)):
            for h in (0.5, 0.25, 0.125):
                writer.writerow({"grid.basis": basis, "grid.spacing": h, "status": "completed", "spacing": h, "dt": 0.01 * h,
                                 "error_max": error(h), "error_end": error(h)})  # (a run that ran has its step)
        writer.writerow({"grid.basis": "q1", "grid.spacing": 0.0625, "status": "stopped", "spacing": 0.0625,
                         "dt": 1e-4, "error_max": 9.0})
    orders, table = order_table(tmp_path)
    assert orders["q1"] == pytest.approx(2.0, abs=1e-12)
    assert orders["bspline3"] == pytest.approx(1.0, abs=1e-12)
    assert "| q1 | 0.75 | 0.188 | 0.0469 |  | 2.00 |" in table


@pytest.mark.parametrize("name", SWEEPS)
def test_every_bundled_sweep_plans(name):
    """Each sweep of the case reads and every one of its combinations validates (nothing runs)."""
    path = BUNDLED_SWEEPS / f"{name}.toml"
    runs = plan(read_sweep(path), path)
    # eight bases x three masses x four spacings (x three schemes on rollers); the cantilever seven bases
    # (not serendipity) x three spacings; the two cases of cell crossing five bases, two masses on
    # three spacings and lumped on four
    assert len(runs) == {"bar_convergence": 8 * 3 * 4, "manufactured_convergence": 8 * 3 * 4,
                         "cantilever_convergence": 7 * 3, "bar_time_steps": 16,
                         "manufactured_large_convergence": 5 * 2 * 3, "drifting_bar_convergence": 5 * 4,
                         "manufactured_rollers": 8 * 3 * 3 * 4, "rollers_quadrature": 2 * 2 * 2 * 3,
                         "mixed_mass": 3 * (3 + 1) * 4,  # three mixes of consistent mass, and lumped
                         # three bases x (three corrections of the iterated mass, consistent, lumped)
                         # x two schemes x three spacings
                         "iterated_mass": 3 * (3 + 2) * 2 * 3}[name]


def test_the_vibration_energy_error_is_the_balance_over_the_largest_strain(tmp_path):
    """A record whose strain energy peaks at 2.0 and whose balance errs by -0.5 at most: 0.25,
    however large the kinetic energy of the rigid motion it rides on."""
    from femgrid_mpm.reproduce.cost_accuracy import vibration_energy_error

    path = tmp_path / "energy.csv"
    path.write_text("time,kinetic,strain,total_error\n0,1000,0.0,0.0\n1,998,2.0,0.1\n2,1000,0.5,-0.5\n")
    assert vibration_energy_error(path) == pytest.approx(0.25, rel=1e-15)
