"""The measurements of femgrid_mpm.analysis on plausible slips of a user: a probe reused for a
second run, records that are not one signal in time order, a misspelt plane."""

from __future__ import annotations

import numpy as np
import pytest

from femgrid_mpm.analysis import bar_axial_period_1d, modal_velocity_probe, zero_crossing_period
from femgrid_mpm.scene import bundled_scene
from femgrid_mpm.solver import Simulation


def test_a_probe_reused_for_a_second_run_holds_that_run_only():
    """The same probe passed to two simulations appended the second run's records to the
    first's, and the period measured on them was silently wrong; a fresh probe of the
    second run is the reference."""
    scene = bundled_scene("vibrating_bar").with_overrides(**{"time.end": 0.03, "solver.engine": "scipy"})
    reused, fresh = modal_velocity_probe(5.0), modal_velocity_probe(5.0)
    Simulation(scene, observers=[reused]).run()
    first_times = reused.times
    Simulation(scene, observers=[reused]).run()
    Simulation(scene, observers=[fresh]).run()
    np.testing.assert_array_equal(reused.arrays()[0], fresh.arrays()[0])
    np.testing.assert_array_equal(reused.arrays()[1], fresh.arrays()[1])
    assert len(first_times) == 11  # the first run's list, if kept, is left as it was


def test_zero_crossing_period_refuses_records_that_are_not_one_signal_in_time_order():
    """Two runs' records one after the other gave 1.29 for a period of 3 (no error); two
    signals side by side, or times shorter than the values, an IndexError from inside."""
    t = np.linspace(0.0, 10.0, 2001)
    v = np.cos(2 * np.pi * t / 3.0)
    assert zero_crossing_period(list(t), list(v)) == pytest.approx(3.0, rel=1e-12)
    with pytest.raises(ValueError, match=r"times must not decrease: times\[2001\] = 0 follows 10"):
        zero_crossing_period(np.r_[t, t], np.r_[v, v])
    with pytest.raises(ValueError, match=r"1D arrays of one length, got shapes \(2001,\) and \(2001, 2\)"):
        zero_crossing_period(t, np.c_[v, v])
    with pytest.raises(ValueError, match=r"got shapes \(1000,\) and \(2001,\)"):
        zero_crossing_period(t[:1000], v)


def test_a_plane_other_than_strain_or_stress_is_refused():
    """Any word but "stress" was taken for plane strain; the rod's 2 L / c with E' = E / (1 - nu^2)
    (strain) and E' = E (stress) is the reference."""
    assert bar_axial_period_1d(5.0, 1e4, 0.3, 1e3, "strain") == pytest.approx(2 * 5.0 / np.sqrt(1e4 / 0.91 / 1e3))
    assert bar_axial_period_1d(5.0, 1e4, 0.3, 1e3, "stress") == pytest.approx(2 * 5.0 / np.sqrt(1e4 / 1e3))
    with pytest.raises(ValueError, match="plane must be 'strain' or 'stress'.*got 'plane_stress'"):
        bar_axial_period_1d(5.0, 1e4, 0.3, 1e3, "plane_stress")
