"""``femgrid-mpm sweep`` and ``femgrid-mpm report``: the contract of docs/sweep.md.

References: the report's computations against values worked by hand
(``e = 0.001 + 2 h^2`` has order 2 and the limit 0.001); a sweep's runs on a
Dask cluster of two workers against the same runs made one by one with
``femgrid-mpm run`` (the same files, byte for byte, and the same numbers in
``runs.csv``); a sweep killed midway against its rerun (only the missing runs
computed, the finished ones untouched).
"""

import csv
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest

from femgrid_mpm.sweep import analysis
from femgrid_mpm.sweep.report import write_report
from femgrid_mpm.sweep.table import RESULT_COLUMNS, text

ROOT = Path(__file__).parents[1]
VIBRATING_BAR = ROOT / "scenes" / "vibrating_bar.toml"
EXACT_BAR = ROOT / "scenes" / "vibrating_bar_exact.toml"
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}


def read_csv(path: Path) -> list[dict]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


# -- the report's computations ---------------------------------------------------------


def test_observed_and_fitted_orders_of_a_power_law():
    spacings = [0.5, 0.25, 0.125, 0.0625]
    errors = [3.0 * h**2 for h in spacings]
    assert analysis.observed_orders(spacings, errors) == pytest.approx([2.0, 2.0, 2.0], abs=1e-12)
    order, constant = analysis.fitted_order(list(reversed(spacings)), list(reversed(errors)))
    assert order == pytest.approx(2.0, abs=1e-12) and constant == pytest.approx(3.0, rel=1e-12)
    # by hand: log2(0.1/0.03) = 1.7370, log2(3) = 1.5850
    assert analysis.observed_orders([0.5, 0.25, 0.125], [0.1, 0.03, 0.01]) == pytest.approx([1.7370, 1.5850], abs=1e-4)


def test_richardson_finds_the_order_and_the_error_the_spacing_leaves():
    # e = 0.001 + 2 h^2: (e1 - e2) / (e2 - e3) = 0.375 / 0.09375 = 4 = 2^2; e0 = 0.03225 - 0.09375 / 3
    estimate = analysis.richardson([0.5, 0.25, 0.125], [0.501, 0.126, 0.03225])
    assert estimate.order == pytest.approx(2.0, abs=1e-9)
    assert estimate.limit == pytest.approx(0.001, abs=1e-12)
    # spacings of unequal ratios, the three finest of four: e = 0.01 + 0.5 h^1.5
    spacings = [2.0, 1.0, 0.6, 0.3]
    estimate = analysis.richardson(spacings, [0.01 + 0.5 * h**1.5 for h in spacings])
    assert estimate.order == pytest.approx(1.5, abs=1e-9) and estimate.limit == pytest.approx(0.01, abs=1e-12)
    assert analysis.richardson([0.5, 0.25, 0.125], [0.1, 0.2, 0.05]) is None  # not monotone
    with pytest.raises(ValueError):
        analysis.richardson([0.5, 0.25], [0.1, 0.05])


def test_convergence_verdicts():
    spacings = [0.5, 0.25, 0.125]
    assert analysis.convergence_verdict(spacings, [0.1, 0.025, 0.00625]) is None  # second order
    flat = analysis.convergence_verdict(spacings, [0.1, 0.11, 0.1])
    assert flat.startswith("does not converge") and "grows from h = 0.5 to 0.25 m" in flat
    assert analysis.convergence_verdict(spacings, [0.1, 0.09, 0.08]).startswith("does not converge (fitted order 0.16")
    plateau = analysis.convergence_verdict(spacings, [0.05 + 2 * h**2 for h in spacings])  # e0 = 0.05 > e3 / 2
    assert plateau is not None and plateau.startswith("levels off near an error of 0.05,")


def test_pareto_front_and_cheapest_for_a_target():
    costs, errors = [1.0, 2.0, 1.5, 3.0, 4.0, 2.0], [0.1, 0.05, 0.2, 0.05, 0.01, 0.06]
    assert analysis.pareto_front(costs, errors) == [0, 1, 4]
    methods = ["q1", "q1", "q2", "q2", "bspline3", "bspline3"]
    choice = analysis.cheapest_for_target(methods, costs, errors, 0.05)
    # reaching 0.05: runs 1 (q1, 2 s), 3 (q2, 3 s), 4 (bspline3, 4 s): q1, then q2 at 1.5x
    assert (choice.best, choice.runner_up, choice.ratio, choice.missing) == (1, 3, 1.5, ())
    choice = analysis.cheapest_for_target(methods, costs, errors, 0.02)
    assert (choice.best, choice.runner_up, choice.ratio, choice.missing) == (4, None, None, ("q1", "q2"))
    assert analysis.cheapest_for_target(methods, costs, errors, 1e-3).best is None


def report_of(directory: Path, header: list, rows: list, targets: str) -> str:
    """The report of a runs.csv of these rows, the bar's sweep with these target errors."""
    with (directory / "runs.csv").open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(rows)
    (directory / "sweep.toml").write_text(f'scene = "vibrating_bar"\n[report]\ntargets = {targets}\n')
    return write_report(directory).read_text()


def test_report_of_a_runs_table(tmp_path):
    """A runs.csv of two methods, e = C h^p exactly, and its report: orders, front, answer."""
    header = ["grid.basis", "grid.spacing", *RESULT_COLUMNS, "critical_dt", "basis", "mass", "spacing", "workers",
              "reason", "run"]
    rows = []
    for basis, constant, order, seconds in (("q1", 0.2, 1.0, 1.0), ("bspline3", 0.1, 2.0, 3.0)):
        for h in (0.5, 0.25, 0.125):
            error = constant * h**order
            wall = seconds / h  # cost grows as the spacing shrinks
            rows.append([basis, h, "completed", 100, 10, 10, 0.01, wall, error, error, "", "", "", 0.1, basis,
                         "lumped", h, 1, "reached t = 1 s", f"{basis}-{h}"])
    report = report_of(tmp_path, header, rows, "[0.03, 0.0001]")
    # the orders: 1 and 2 per pair and fitted; Richardson's limit 0 (printed as 0 to 3 digits)
    assert "| q1 lumped | 0.5, 0.25, 0.125 | 1.00, 1.00 | 1.00 | 1.00 |" in report
    assert "| bspline3 lumped | 0.5, 0.25, 0.125 | 2.00, 2.00 | 2.00 | 2.00 |" in report
    # 3% : q1 at 0.125 (0.025, 8 s); bspline3 at 0.5 (0.025, 6 s): bspline3 cheapest, q1 takes 8/6 = 1.33x
    assert ("For 3%, the cheapest is bspline3 lumped at h = 0.5 m (6 s, error 2.5%); the next method, q1 lumped at "
            "h = 0.125 m, takes 1.33x as long.") in report
    assert "No run reaches 0.01% (the smallest error is 0.156%, bspline3 lumped)." in report
    # the front, cheapest first: q1 0.5 (2 s, 0.1), q1 0.25 (4 s, 0.05), bspline3 0.5 (6 s, 0.025), ...
    front = re.findall(r"^\| (\S+) \| [^|]+ \| [^|]+ \| [^|]+ \| [^|]+ \| [^|]+ \|$", report.split("Pareto front, cheapest first")[1].split("##")[0], re.M)
    assert front[1:] == ["q1-0.5", "q1-0.25", "bspline3-0.5", "bspline3-0.25", "bspline3-0.125"]
    html = (tmp_path / "report.html").read_text()
    for name in ("work_precision.png", "convergence.png", "cost.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert f"({name})" in report
    assert html.count("data:image/png;base64,") == 3


# -- sweeps on Dask --------------------------------------------------------------------


def sweep_file(directory: Path, vary: str, end: float, extra: str = "", scene: Path = VIBRATING_BAR) -> Path:
    path = directory / "sweep.toml"
    path.write_text(f'scene = "{scene}"\n[vary]\n{vary}\n[set]\n"time.end" = {end}\n{extra}')
    return path


def test_sweep_on_two_workers_is_the_runs_made_one_by_one(tmp_path, run_cli):
    vary = '"grid.basis" = ["q1", "q2", "serendipity"]\n"grid.spacing" = [0.5, 0.25]'
    path = sweep_file(tmp_path, vary, 1.0, scene=EXACT_BAR)
    code, out, err = run_cli(["sweep", path, "--out", tmp_path / "out", "--workers", "2"])
    assert code == 0, err
    assert "6 runs: 6 computed (2 at once), 0 reused, 0 failed" in out
    rows = read_csv(tmp_path / "out" / "runs.csv")
    assert [(r["grid.basis"], r["grid.spacing"]) for r in rows] == [
        (b, h) for b in ("q1", "q2", "serendipity") for h in ("0.5", "0.25")]
    for row in rows:
        single = tmp_path / "single" / row["run"]
        code, _, _ = run_cli(["run", EXACT_BAR, "--out", single, "--set", "time.end=1.0",
                              "--set", f"grid.basis={row['grid.basis']}", "--set", f"grid.spacing={row['grid.spacing']}"])
        swept = tmp_path / "out" / "runs" / row["run"]
        summary = json.loads((single / "summary.json").read_text())
        assert code == (3 if row["grid.basis"] == "serendipity" else 0)  # lumped serendipity: negative masses
        assert (swept / "energy.csv").read_bytes() == (single / "energy.csv").read_bytes()
        assert (swept / "scene.toml").read_text().split("\n", 3)[-1] == (single / "scene.toml").read_text().split("\n", 3)[-1]
        reference = summary.get("reference") or {}
        assert row["status"] == summary["status"] and row["reason"] == summary["reason"]
        for column in ("steps", "points", "nodes", "dt", "critical_dt"):
            assert row[column] == text(summary[column]), column
        for column in ("error_end", "error_max", "period_error"):
            assert row[column] == text(reference.get(column)), column
        assert row["energy_drift"] == text(summary.get("energy_drift"))
        if row["status"] == "completed":
            assert float(row["error_max"]) > 0 and float(row["error_end"]) <= float(row["error_max"])
    stopped = [r for r in rows if r["status"] == "stopped"]
    assert [r["grid.basis"] for r in stopped] == ["serendipity"] * 2
    assert all("negative grid mass" in r["reason"] for r in stopped)
    assert not (tmp_path / "out" / "runs" / "q1-0.5" / "particles.pvd").exists()
    assert (tmp_path / "out" / "report.md").is_file() and (tmp_path / "out" / "cost.png").is_file()
    # all finished: a rerun computes nothing and starts no cluster
    code, out, _ = run_cli(["sweep", path, "--out", tmp_path / "out", "--workers", "2"])
    assert code == 0 and "6 runs: 0 computed, 6 reused, 0 failed" in out
    assert read_csv(tmp_path / "out" / "runs.csv") == rows


def test_a_killed_sweep_loses_no_finished_run(tmp_path):
    """SIGKILL to the sweep's process group (the client and its workers) once one run is
    in runs.csv; the rerun computes only the runs that were missing."""
    vary = '"bodies.0.points_per_cell" = [2, 3, 4, 5]'
    path = sweep_file(tmp_path, vary, 2.0, '"grid.spacing" = 0.0625\n')
    out = tmp_path / "out"
    command = [sys.executable, "-m", "femgrid_mpm.cli", "sweep", str(path), "--out", str(out), "--workers", "1"]
    process = subprocess.Popen(command, cwd=ROOT, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and process.poll() is None:
            if (out / "runs.csv").is_file() and len(read_csv(out / "runs.csv")) >= 1:
                break
            time.sleep(0.02)
        os.killpg(process.pid, signal.SIGKILL)
    finally:
        process.wait(timeout=30)
    finished = read_csv(out / "runs.csv")
    # the finished runs: those in runs.csv, and one that may have ended just before the kill
    done = [p.name for p in (out / "runs").iterdir() if not p.name.startswith(".")]
    assert {r["run"] for r in finished} <= set(done)
    assert 1 <= len(done) < 4, "the sweep must be killed midway (make its runs longer)"
    before = {name: (out / "runs" / name / "summary.json").stat().st_mtime_ns for name in done}
    rerun = subprocess.run(command, cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    assert f"4 runs: {4 - len(done)} computed (1 at once), {len(done)} reused, 0 failed" in rerun.stdout
    rows = read_csv(out / "runs.csv")
    assert [r["bodies.0.points_per_cell"] for r in rows] == ["2", "3", "4", "5"]
    assert all(r["status"] == "completed" for r in rows)
    assert {r: (out / "runs" / r / "summary.json").stat().st_mtime_ns for r in before} == before
    assert [r for r in rows if r["run"] in {f["run"] for f in finished}] == finished
    assert sorted(p.name for p in (out / "runs").iterdir()) == sorted(r["run"] for r in rows)  # no temporary left


def test_ctrl_c_keeps_the_finished_runs(tmp_path):
    """SIGINT to the process group (as Ctrl-C on a terminal) once a run is in runs.csv:
    exit 130, one line, the finished runs kept and reused by the rerun."""
    path = sweep_file(tmp_path, '"bodies.0.points_per_cell" = [2, 3, 4, 5]', 2.0, '"grid.spacing" = 0.0625\n')
    out = tmp_path / "out"
    command = [sys.executable, "-m", "femgrid_mpm.cli", "sweep", str(path), "--out", str(out), "--workers", "1"]
    process = subprocess.Popen(command, cwd=ROOT, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and process.poll() is None:
            if (out / "runs.csv").is_file() and len(read_csv(out / "runs.csv")) >= 1:
                break
            time.sleep(0.02)
        os.killpg(process.pid, signal.SIGINT)
        _, err = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
    finished = read_csv(out / "runs.csv")
    assert process.returncode == 130 and 1 <= len(finished) < 4
    assert err.strip().splitlines()[-1].startswith("femgrid-mpm: interrupted: the finished runs are kept in")
    # a run may end between the interrupt and the cluster's close: its directory is whole, and
    # the rerun reuses it; no run is half written
    kept = sorted(p.name for p in (out / "runs").iterdir())
    assert set(r["run"] for r in finished) <= set(kept) and not any(name.startswith(".") for name in kept)
    for name in kept:
        assert json.loads((out / "runs" / name / "summary.json").read_text())["status"] == "completed"


def test_a_changed_scene_is_run_again(tmp_path, run_cli):
    path = sweep_file(tmp_path, '"grid.spacing" = [0.5, 0.25]', 0.03)
    assert run_cli(["sweep", path, "--out", tmp_path / "out", "--workers", "1"])[0] == 0
    path.write_text(path.read_text().replace('"time.end" = 0.03', '"time.end" = 0.06'))
    code, out, _ = run_cli(["sweep", path, "--out", tmp_path / "out", "--workers", "1"])
    assert code == 0 and "2 runs: 2 computed (1 at once), 0 reused" in out
    assert {r["steps"] for r in read_csv(tmp_path / "out" / "runs.csv")} == {"20"}  # 0.06 / 0.003


# -- bad sweep files ------------------------------------------------------------------


@pytest.mark.parametrize("content, key", [
    ('scene = "vibrating_bar"\n[vary]\n"grid.basis" = ["q1", "q7"]\n', "grid.basis"),
    ('scene = "vibrating_bar"\n[vary]\n"grid.spacing" = []\n', 'vary."grid.spacing"'),
    ('scene = "vibrating_bar"\n[vary]\n"grid.spacing" = [0.5, 0.5]\n', 'vary."grid.spacing"[1]'),
    ('scene = "vibrating_bar"\n[vary]\n"grid.spacin" = [0.5]\n', "grid.spacin"),
    ('scene = "vibrating_bar"\nworkers = 3\n', "workers"),
    ('scene = "no_such_scene"\n', "scene"),
    ('scene = "vibrating_bar"\n[vary]\n"time.end" = [1.0]\n[set]\n"time.end" = 2.0\n', 'set."time.end"'),
    ('scene = "vibrating_bar"\n[set]\n"time.dt" = -1.0\n', "time.dt"),
    ('scene = "vibrating_bar"\n[report]\nerror = "error_min"\n', "report.error"),
    ('scene = "vibrating_bar"\n[report]\ntargets = [inf]\n', "report.targets[0]"),
    ('scene = "vibrating_bar"\n[vary\n', "not valid TOML"),
    ('[vary]\n"grid.basis" = ["q1"]\n', "scene"),
    ('scene = "vibrating_bar"\n[vary]\n"grid.basis" = ["q1"]\n[[skip]]\n"grid.spacing" = 0.5\n', "skip[0]"),
    ('scene = "vibrating_bar"\n[vary]\n"grid.basis" = ["q1", "q2"]\n[[skip]]\n"grid.basis" = "q3"\n', "skip[0]"),
    ('scene = "vibrating_bar"\n[vary]\n"grid.basis" = ["q1"]\n[[skip]]\n"grid.basis" = "q1"\n', "skip"),
    # an empty list matched nothing: the entry was taken and left nothing out
    ('scene = "vibrating_bar"\n[vary]\n"grid.basis" = ["q1", "q2"]\n[[skip]]\n"grid.basis" = []\n', "skip[0]: grid.basis = []"),
])
def test_a_bad_sweep_file_is_one_line_and_nothing_runs(tmp_path, run_cli, content, key):
    path = tmp_path / "bad.toml"
    path.write_text(content)
    code, out, err = run_cli(["sweep", path, "--out", tmp_path / "out"])
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and str(path) in err and key in err, err
    assert not (tmp_path / "out").exists()


def test_report_of_a_directory_without_runs(tmp_path, run_cli):
    code, _, err = run_cli(["report", tmp_path])
    assert code == 2 and "has no runs.csv" in err and len(err.strip().splitlines()) == 1


def test_bundled_sweep_files_plan(run_cli):
    from femgrid_mpm.sweep import plan, read_sweep
    from femgrid_mpm.sweep.spec import BUNDLED_SWEEPS, MergedRunsWarning

    files = sorted(BUNDLED_SWEEPS.glob("*.toml"))
    assert files
    for path in files:
        spec = read_sweep(path)
        with warnings.catch_warnings():  # their [[skip]] leaves no combination that would run again
            warnings.simplefilter("error", MergedRunsWarning)
            runs = plan(spec, path)
        product = math.prod(len(v) for v in spec.vary.values())
        assert len({run.key for run in runs}) == len(runs) == (product if not spec.skip else len(runs))
        assert len(runs) <= product


def test_skip_leaves_out_the_matching_combinations(tmp_path):
    from femgrid_mpm.sweep import plan, read_sweep

    path = sweep_file(tmp_path, '"grid.basis" = ["q1", "q2"]\n"solver.mass" = ["consistent", "lumped"]\n'
                                '"solver.mix" = [0, 0.25, 0.5]', 0.1,
                      extra='[[skip]]\n"solver.mass" = "lumped"\n"solver.mix" = [0.25, 0.5]\n'
                            '[[skip]]\n"grid.basis" = "q2"\n"solver.mix" = 0.5\n')
    runs = plan(read_sweep(path), path)
    kept = {(r.varied["grid.basis"], r.varied["solver.mass"], r.varied["solver.mix"]) for r in runs}
    # 12 combinations; lumped with a mix (4) and q2 with mix 0.5 (2, one of them lumped already) out
    assert kept == {("q1", "consistent", 0), ("q1", "consistent", 0.25), ("q1", "consistent", 0.5),
                    ("q1", "lumped", 0), ("q2", "consistent", 0), ("q2", "consistent", 0.25), ("q2", "lumped", 0)}


def test_sweep_on_an_existing_scheduler(tmp_path, run_cli):
    from dask.distributed import LocalCluster

    path = sweep_file(tmp_path, '"grid.spacing" = [0.5, 0.25]', 0.03)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        code, out, err = run_cli(["sweep", path, "--out", tmp_path / "out", "--scheduler", cluster.scheduler_address])
    assert code == 0, err
    assert "2 runs: 2 computed (1 at once), 0 reused, 0 failed" in out
    assert [r["status"] for r in read_csv(tmp_path / "out" / "runs.csv")] == ["completed", "completed"]


def test_an_unreachable_scheduler_is_one_line_and_nothing_written(tmp_path, run_cli):
    path = sweep_file(tmp_path, '"grid.spacing" = [0.5]', 0.03)
    code, out, err = run_cli(["sweep", path, "--out", tmp_path / "out", "--scheduler", "tcp://127.0.0.1:1"])
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert "--scheduler tcp://127.0.0.1:1: cannot reach the Dask scheduler" in err
    assert not (tmp_path / "out").exists()


def test_report_of_a_time_step_sweep(tmp_path):
    """time.safety varied at one spacing: the report's error against dt, largest dt first."""
    header = ["time.safety", *RESULT_COLUMNS, "critical_dt", "basis", "mass", "spacing", "workers", "reason", "run"]
    rows = []
    for safety in (0.8, 0.4, 0.2):
        dt = 0.1 * safety
        rows.append([safety, "completed", round(1 / dt), 10, 10, dt, 1 / dt, 0.01 + dt, 0.01 + dt, "", "", "", 0.1, "q1",
                     "lumped", 0.5, 1, "reached t = 1 s", f"{safety}"])
    with (tmp_path / "runs.csv").open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(rows)
    report = write_report(tmp_path).read_text()
    assert "## Error against the time step" in report and (tmp_path / "time_step.png").is_file()
    assert "| q1 lumped, h = 0.5 m | 0.08, 0.04, 0.02 | 0.09, 0.05, 0.03 |" in report
    assert "## Convergence with the spacing" not in report  # one spacing


def test_the_warm_up_copy_reports_none_of_its_warnings():
    """The two-step copy a worker runs to load the kernels balances its energy over two steps
    of a ramped load (off by a third of its tiny energy): that warning is the copy's, and the
    run's own warnings are all a sweep reports."""
    import warnings

    from femgrid_mpm.scene import bundled_scene
    from femgrid_mpm.solver import Simulation
    from femgrid_mpm.sweep.runner import WARM_UP, _warm_up

    scene = bundled_scene("cantilever_quasistatic")
    with warnings.catch_warnings(record=True) as copied:
        warnings.simplefilter("always")
        Simulation(scene.with_overrides(**WARM_UP)).run()
    assert any("energy balance" in str(w.message) for w in copied)  # the copy itself warns
    with warnings.catch_warnings(record=True) as reported:
        warnings.simplefilter("always")
        _warm_up(scene)
    assert reported == []


def test_a_direct_consistent_solve_has_no_cg_iterations():
    """``cg_iterations`` is empty for a run that made none (solved directly), not 0."""
    from femgrid_mpm.sweep.table import row

    class Planned:
        varied = {"solver.mass": "consistent"}
        key = "consistent"

        class scene:
            class grid:
                basis, spacing = "q1", 0.5

            class solver:
                mass = "consistent"

    summary = {"status": "completed", "steps": 10, "consistent_mass": {"cg_iterations": 0}}
    assert row(Planned, summary, 1)["cg_iterations"] == ""
    summary["consistent_mass"]["cg_iterations"] = 25
    assert row(Planned, summary, 1)["cg_iterations"] == "2.5"


def test_runs_that_differ_only_in_keys_their_mass_does_not_read_run_once(tmp_path):
    """Lumped mass reads neither ``mass_corrections`` nor ``mix``; the iterated mass no ``mix``;
    consistent mass no ``mass_corrections``: 3 x 2 x 2 combinations are 2 + 2 + 1 distinct
    scenes, each run once (the first of its kind) and labelled by the keys its mass reads."""
    from femgrid_mpm.sweep import plan, read_sweep
    from femgrid_mpm.sweep.report import method_of
    from femgrid_mpm.sweep.spec import MergedRunsWarning

    path = sweep_file(tmp_path, '"solver.mass" = ["iterated", "consistent", "lumped"]\n'
                                '"solver.mass_corrections" = [1, 2]\n"solver.mix" = [0, 0.5]', 0.1)
    with pytest.warns(MergedRunsWarning, match="12 combinations, 5 distinct runs"):
        runs = plan(read_sweep(path), path)
    kept = [(r.varied["solver.mass"], r.varied["solver.mass_corrections"], r.varied["solver.mix"]) for r in runs]
    assert kept == [("iterated", 1, 0), ("iterated", 2, 0), ("consistent", 1, 0), ("consistent", 1, 0.5),
                    ("lumped", 1, 0)]
    varied = list(read_sweep(path).vary)
    labels = [method_of({"basis": "q1", "mass": r.varied["solver.mass"], **r.varied}, varied) for r in runs]
    assert labels == ["q1 iterated solver.mass_corrections=1", "q1 iterated solver.mass_corrections=2",
                      "q1 consistent solver.mix=0", "q1 consistent solver.mix=0.5", "q1 lumped"]


CHANGED = {"mass_corrections": 5, "weak_fraction": 0.3, "cg_tolerance": 1e-2, "linear_solver": "cg",
           "consistent_fallback": "blend", "blend": 0.7, "weak_ratio": 0.6, "weak_mix": 0.9, "mix": 0.5}


@pytest.mark.parametrize("mass", ["lumped", "hrz", "iterated", "consistent"])
def test_a_mass_runs_the_same_whatever_the_keys_it_does_not_read(mass):
    """The declaration the sweep's plan and labels rest on (``femgrid_mpm.mass.OWN_KEYS``),
    against the runs: the bar's points after 40 steps (q1, consistent mass's weak nodes and
    iterated mass's corrections both at work) with every solver key ``mass`` does not read
    changed from its default equal the default run's bit for bit."""
    import numpy as np

    from femgrid_mpm.mass import OWN_KEYS, reads
    from femgrid_mpm.solver import Simulation

    from helpers import bundled_variant

    assert set(CHANGED) == set(OWN_KEYS)
    others = {f"solver.{key}": value for key, value in CHANGED.items() if not reads(mass, key)}
    assert others
    states = []
    for overrides in ({}, others):
        simulation = Simulation(bundled_variant("vibrating_bar", "q1", mass, **{"time.dt": 1e-3, **overrides}))
        for _ in range(40):
            simulation.advance()
        states.append((simulation.particles.x.copy(), simulation.particles.v.copy()))
    assert np.array_equal(states[0][0], states[1][0]) and np.array_equal(states[0][1], states[1][1])


def test_a_runs_table_with_repeated_scenes_is_reported_once_per_scene(tmp_path):
    """A runs.csv that holds lumped runs differing only in ``solver.mix`` (a sweep written before
    such runs were merged): the report keeps the first of each, so the lumped line has one run per
    spacing, its convergence order 1 from e = 0.2 h exactly, not a line doubling back."""
    header = ["solver.mass", "solver.mix", "grid.spacing", *RESULT_COLUMNS, "critical_dt", "basis", "mass", "spacing",
              "workers", "reason", "run"]
    rows = []
    for mass, mix, constant in (("consistent", "0", 0.1), ("consistent", "0.5", 0.15), ("lumped", "0", 0.2),
                                ("lumped", "0.5", 0.2)):
        for h in (0.5, 0.25, 0.125):
            error = constant * h
            rows.append([mass, mix, h, "completed", 100, 10, 10, 0.01, 1 / h, error, error, "", "", "", 0.1, "q1",
                         mass, h, 1, "reached t = 1 s", f"{mass}-{mix}-{h}"])
    report = report_of(tmp_path, header, rows, "[0.03]")
    assert report.startswith("# Sweep of vibrating_bar\n\n9 runs (9 completed")
    assert "| q1 lumped | 0.5, 0.25, 0.125 | 1.00, 1.00 | 1.00 |" in report
    assert "| q1 consistent solver.mix=0.5 | 0.5, 0.25, 0.125 | 1.00, 1.00 | 1.00 |" in report


def test_a_line_with_an_error_of_zero_has_no_order_and_the_report_is_written(tmp_path):
    """A body at rest against a reference at rest: error_max exactly 0 at every spacing (was a
    math domain error, exit 2, no report.md).  The report names the line as having no order and
    draws nothing of it on the log axes (no matplotlib warning)."""
    header = ["grid.spacing", *RESULT_COLUMNS, "critical_dt", "basis", "mass", "spacing", "workers", "reason", "run"]
    rows = [[h, "completed", 100, 10, 10, 0.01, 1 / h, 0.0, 0.0, "", "", "", 0.1, "q1", "lumped", h, 1,
             "reached t = 1 s", f"r-{h}"] for h in (1.0, 0.5, 0.25)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        report = report_of(tmp_path, header, rows, "[0.03]")
    assert "q1 lumped: an error of 0 at some spacing, no order of convergence." in report
    assert "For 3%, the cheapest is q1 lumped at h = 1 m" in report


def test_a_list_index_of_other_digits_is_left_to_the_scene():
    """int() refuses "²" (which str.isdigit takes) and more than 4300 digits: such a part is no index."""
    from femgrid_mpm.sweep.spec import normal_key

    assert normal_key("bodies.00.name") == "bodies.0.name"
    assert normal_key("bodies.².name") == "bodies.².name"
    assert normal_key("bodies." + "9" * 5000 + ".x") == "bodies." + "9" * 5000 + ".x"


def test_varied_text_values_keep_their_difference_in_runs_csv():
    """Values of a text key that differ only in their spaces or line breaks were written alike
    (one line of single spaces) and read as one method by the report."""
    from femgrid_mpm.sweep.table import value_text

    values = ["a b", "a  b", "a\nb", " a b", '"a b"', "a\\nb", 0.5, 1, True, None]
    cells = [value_text(value) for value in values]
    assert len(set(cells)) == len(values)
    assert all("\n" not in cell for cell in cells)
    assert cells[0] == "a b" and cells[5] == "a\\nb" and cells[6:] == ["0.5", "1", "true", ""]
    assert [json.loads(cell) for cell in cells[1:5]] == values[1:5]


@pytest.mark.parametrize("finished", [0, 1])
def test_an_interrupt_says_runs_are_kept_only_where_runs_csv_has_one(tmp_path, run_cli, monkeypatch, finished):
    """The sweep writes runs.csv, its header alone, before any run ends: an interrupt then said
    "the finished runs are kept" of a table without a run."""
    import femgrid_mpm.sweep as sweep_module
    from femgrid_mpm.sweep.table import row, write_runs

    def interrupted(runs, out, **options):
        options["prepare"]()
        write_runs(out / "runs.csv", list(runs[0].varied), [row(runs[0], None, 1, failure="ValueError: x")][:finished])
        raise KeyboardInterrupt

    monkeypatch.setattr(sweep_module, "run_sweep", interrupted)
    path = sweep_file(tmp_path, '"grid.basis" = ["q1", "q2"]', 0.01)
    code, _, err = run_cli(["sweep", path, "--out", tmp_path / "out", "--workers", "1"])
    assert code == 130 and len(err.strip().splitlines()) == 1, err
    assert ("the finished runs are kept in" in err) == bool(finished), err
    assert ("before any run was computed" in err) == (not finished), err
