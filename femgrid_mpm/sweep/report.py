"""A sweep's report from its ``runs.csv``: ``report.md``, ``report.html`` (figures inline)
and the figures as PNG files beside them.

The report answers, for each method (basis and mass, with any other key
varied), how far its runs are from the exact answer and at what cost: the
cheapest run for each target error, the work-precision diagram with its
Pareto front, the convergence with the spacing (observed orders, a fitted
order, Richardson's estimate), the error against the time step when the sweep
varies it, and the cost split (steps, time per step, CG iterations).
"""

from __future__ import annotations

import base64
import html
import math
from dataclasses import dataclass, field
from pathlib import Path

from . import analysis, figures
from .spec import SPACING_KEY, TIME_STEP_KEYS, ReportSpec, SweepError, read_sweep, read_values
from .table import RUNS_FILE, read_runs

REPORT_FILE, HTML_FILE = "report.md", "report.html"
FIGURES = {"work_precision": "work_precision.png", "convergence": "convergence.png", "time_step": "time_step.png",
           "cost": "cost.png"}
#: keys of a method besides the basis and the mass
METHOD_KEYS_SHOWN_APART = ("grid.basis", "solver.mass", SPACING_KEY, *TIME_STEP_KEYS)


@dataclass
class Report:
    """The report as blocks: ``("h", level, text)``, ``("p", text)``, ``("table", header, rows)``,
    ``("figure", file, caption)``, rendered as Markdown or HTML."""

    blocks: list = field(default_factory=list)

    def heading(self, text: str, level: int = 2) -> None:
        self.blocks.append(("h", level, text))

    def paragraph(self, text: str) -> None:
        self.blocks.append(("p", text))

    def table(self, header: list[str], rows: list[list]) -> None:
        if rows:
            self.blocks.append(("table", header, rows))

    def figure(self, file: str, caption: str) -> None:
        self.blocks.append(("figure", file, caption))

    def markdown(self) -> str:
        out = []
        for block in self.blocks:
            if block[0] == "h":
                out.append("#" * block[1] + " " + block[2])
            elif block[0] == "p":
                out.append(block[1])
            elif block[0] == "table":
                header, rows = block[1], block[2]
                out.append("\n".join(["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
                                     + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]))
            else:
                out.append(f"![{block[2]}]({block[1]})\n\n*{block[2]}*")
        return "\n\n".join(out) + "\n"

    def html(self, directory: Path, title: str) -> str:
        out = [f"<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{html.escape(title)}</title>"
               "<style>body{font-family:sans-serif;max-width:60em;margin:2em auto;line-height:1.4}"
               "table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:0.2em 0.5em;text-align:right}"
               "img{max-width:100%}figcaption{font-style:italic}</style></head><body>"]
        for block in self.blocks:
            if block[0] == "h":
                out.append(f"<h{block[1]}>{html.escape(block[2])}</h{block[1]}>")
            elif block[0] == "p":
                out.append(f"<p>{html.escape(block[1]).replace('`', '')}</p>")
            elif block[0] == "table":
                head = "".join(f"<th>{html.escape(str(c))}</th>" for c in block[1])
                body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in block[2])
                out.append(f"<table><tr>{head}</tr>{body}</table>")
            else:
                data = base64.b64encode((directory / block[1]).read_bytes()).decode()
                out.append(f"<figure><img src=\"data:image/png;base64,{data}\" alt=\"{html.escape(block[2])}\">"
                           f"<figcaption>{html.escape(block[2])}</figcaption></figure>")
        return "\n".join(out) + "\n</body></html>\n"


def settings(directory: Path) -> tuple[str, ReportSpec]:
    """The sweep's title and ``[report]`` table from its copy ``DIR/sweep.toml`` (defaults without one)."""
    path = directory / "sweep.toml"
    if not path.is_file():
        return f"Sweep in {directory}", ReportSpec()
    try:
        spec = read_sweep(path)
    except SweepError as error:
        raise ValueError(str(error)) from None
    return spec.title or f"Sweep of {spec.scene}", spec.report


def method_of(row: dict, varied: list[str]) -> str:
    """A run's method: its basis and mass, with the values of the other keys varied
    (not the spacing or the time step, the axes of the report, nor a solver key its mass
    does not read, :data:`femgrid_mpm.mass.OWN_KEYS`: lumped mass is not "mass_corrections=1")."""
    shown = {key: row[key] for key in varied if key not in METHOD_KEYS_SHOWN_APART}
    others = [f"{key}={row[key]}" for key, _ in read_values(shown, row["mass"])]
    return " ".join([row["basis"], row["mass"]] + ([", ".join(others)] if others else []))


def distinct_rows(varied: list[str], rows: list[dict]) -> list[dict]:
    """``rows`` without those that repeat an earlier one's run: the same values of every varied
    key its mass reads (:func:`.spec.read_values`; a sweep plans such runs once, a ``runs.csv``
    written before it did may hold them all)."""
    seen, kept = set(), []
    for row in rows:
        read = read_values({key: row[key] for key in varied}, row["mass"])
        if read not in seen:
            seen.add(read)
            kept.append(row)
    return kept


def step_setting(row: dict, varied: list[str]) -> str:
    """The time-step keys varied, as text (empty when the sweep does not vary them)."""
    return ", ".join(f"{key}={row[key]}" for key in varied if key in TIME_STEP_KEYS)


def number(value, digits: int = 3) -> str:
    return "" if value is None else f"{value:.{digits}g}"


def write_report(directory) -> Path:
    """Write the report of the sweep in ``directory``; the path of ``report.md``.

    Raises
    ------
    ValueError
        If ``runs.csv`` or ``sweep.toml`` there does not read.
    OSError
        If the files cannot be written.
    """
    from ..output import atomic_write

    directory = Path(directory)
    title, spec = settings(directory)
    varied, rows = read_runs(directory / RUNS_FILE)
    rows = distinct_rows(varied, rows)
    report = Report()
    report.heading(title, 1)
    compose(report, directory, varied, rows, spec)
    atomic_write(directory / REPORT_FILE, report.markdown())
    atomic_write(directory / HTML_FILE, report.html(directory, title))
    return directory / REPORT_FILE


def compose(report: Report, directory: Path, varied: list[str], rows: list[dict], spec: ReportSpec) -> None:
    """The report's sections, drawing their figures into ``directory``."""
    error = spec.error
    ended = [r for r in rows if r["status"] in ("completed", "stopped")]
    # on log axes: a finite error and a wall time above 0 (a run stopped at once may have neither)
    measured = [r for r in ended if r[error] is not None and math.isfinite(r[error])
                and r["wall_time"] is not None and r["wall_time"] > 0]
    workers = sorted({int(r["workers"]) for r in rows if r["workers"] is not None})
    counts = {status: sum(r["status"] == status for r in rows) for status in ("completed", "stopped", "failed")}
    values = "; ".join(f"{key}: {', '.join(dict.fromkeys(r[key] for r in rows))}" for key in varied)
    at_once = (f"{workers[0]}" if len(workers) == 1 else f"between {workers[0]} and {workers[-1]}") if workers else "?"
    report.paragraph(
        f"{len(rows)} runs ({counts['completed']} completed, {counts['stopped']} stopped, {counts['failed']} failed)"
        + (f" over {values}." if values else ".")
        + f" Up to {at_once} ran at once; each run's wall time is measured inside it (its time stepping), and runs "
        "sharing cores slow each other: `--workers 1` gives timing-grade numbers. "
        + ("The error is the RMS over the points of |u - u_exact| over the largest |u_exact| over the run, "
           + ("its largest value over the records (error_max)." if error == "error_max" else "at the end (error_end).")))
    if not ended:
        report.paragraph("No run finished: there is no error and no cost to compare.")
    elif not any(r[error] is not None for r in ended):
        report.paragraph(f"No run has a {error} (the scene declares no [reference], or no run recorded one: they "
                         "stopped at their first step), so there is nothing to compare against; below is what the runs "
                         "cost.")
    elif not measured:
        report.paragraph(f"No finished run has a finite {error} and a wall time above 0: there is nothing to compare; "
                         "below is what the runs cost.")
    if measured:
        answer(report, measured, varied, spec)
        work_precision(report, directory, measured, varied, error)
        convergence(report, directory, measured, varied, error)
        time_steps(report, directory, measured, varied, error)
    cost_split(report, directory, ended, varied)
    unfinished = [r for r in rows if r["status"] != "completed"]
    if unfinished:
        report.heading("Runs that did not complete")
        report.table(["run", "status", "steps", "reason"], [[r["run"], r["status"], number(r["steps"], 6), r["reason"]]
                                                             for r in unfinished])


def answer(report: Report, rows: list[dict], varied: list[str], spec: ReportSpec) -> None:
    methods = [method_of(r, varied) for r in rows]
    costs = [r["wall_time"] for r in rows]
    errors = [r[spec.error] for r in rows]
    sentences = []
    for target in spec.targets:
        choice = analysis.cheapest_for_target(methods, costs, errors, target)
        goal = f"{target * 100:g}%"
        if choice.best is None:
            best_error = min(errors)
            sentences.append(f"No run reaches {goal} (the smallest error is {best_error * 100:.3g}%, "
                             f"{methods[errors.index(best_error)]}).")
            continue
        best = rows[choice.best]
        text = (f"For {goal}, the cheapest is {methods[choice.best]} at h = {number(best['spacing'])} m "
                f"({number(best['wall_time'])} s, error {best[spec.error] * 100:.3g}%)")
        if choice.runner_up is not None:
            other = rows[choice.runner_up]
            text += (f"; the next method, {methods[choice.runner_up]} at h = {number(other['spacing'])} m, "
                     f"takes {choice.ratio:.2f}x as long")
        else:
            text += "; no other method reaches it"
        if choice.missing:
            text += f" ({', '.join(choice.missing)} never reach{'es' if len(choice.missing) == 1 else ''} it)"
        sentences.append(text + ".")
    report.heading("Which choice is cheapest")
    report.paragraph(" ".join(sentences))


def group_of(label: str, rows: list[dict]) -> tuple:
    """What a line's style follows: its colour the basis, its marker and line style the rest
    of its label (the mass, other keys varied)."""
    basis = rows[0]["basis"]
    return (basis, label.removeprefix(basis).strip())


def lines_over(rows: list[dict], varied: list[str], axis: str, within) -> dict:
    """The runs grouped by method (and ``within(row)``), each group sorted along ``axis``."""
    groups: dict = {}
    for row in rows:
        label = method_of(row, varied)
        extra = within(row)
        groups.setdefault(f"{label}, {extra}" if extra else label, []).append(row)
    return {label: sorted(group, key=lambda r: r[axis]) for label, group in groups.items()}


def work_precision(report: Report, directory: Path, rows, varied, error) -> None:
    lines = lines_over(rows, varied, "spacing", lambda r: step_setting(r, varied))
    costs = [r["wall_time"] for r in rows]
    errors = [r[error] for r in rows]
    front = analysis.pareto_front(costs, errors)
    figures.work_precision([(label, [r["wall_time"] for r in g], [r[error] for r in g], group_of(label, g))
                            for label, g in lines.items()],
                           ([costs[i] for i in front], [errors[i] for i in front]), directory / FIGURES["work_precision"])
    report.heading("Work and precision")
    report.figure(FIGURES["work_precision"], f"{error} against the wall time, one line per method across spacings; "
                  "dashed: the Pareto front (no run is both cheaper and more accurate)")
    report.paragraph("The Pareto front, cheapest first:")
    report.table(["run", "method", "h (m)", "dt (s)", "wall time (s)", error],
                 [[rows[i]["run"], method_of(rows[i], varied), number(rows[i]["spacing"]), number(rows[i]["dt"]),
                   number(rows[i]["wall_time"]), number(rows[i][error])] for i in front])


def convergence(report: Report, directory: Path, rows, varied, error) -> None:
    lines = {label: g for label, g in lines_over(rows, varied, "spacing", lambda r: step_setting(r, varied)).items()
             if len({r["spacing"] for r in g}) >= 2 and len({r["spacing"] for r in g}) == len(g)}
    # an order is a ratio of logarithms: a line with an error of exactly 0 (a motion the grid holds
    # exactly) has none, and is named instead
    exact = [label for label, g in lines.items() if any(r[error] <= 0 for r in g)]
    lines = {label: g for label, g in lines.items() if label not in exact}
    if not lines:
        if exact:
            report.heading("Convergence with the spacing")
            report.paragraph(f"{', '.join(exact)}: an error of 0 at some spacing, no order of convergence.")
        return
    figures.convergence([(label, [r["spacing"] for r in g], [r[error] for r in g], group_of(label, g))
                         for label, g in lines.items()],
                        directory / FIGURES["convergence"])
    report.heading("Convergence with the spacing")
    report.figure(FIGURES["convergence"], f"{error} against the grid spacing, one line per method; dotted: h^1 to h^4")
    table, remarks = [], []
    for label, group in lines.items():
        spacings, errors = [r["spacing"] for r in group], [r[error] for r in group]
        order, _ = analysis.fitted_order(spacings, errors)
        pairs = analysis.observed_orders(spacings, errors)
        estimate = analysis.richardson(spacings, errors) if len(group) >= 3 else None
        table.append([label, ", ".join(number(h) for h in sorted(spacings, reverse=True)),
                      ", ".join(f"{p:.2f}" for p in pairs), f"{order:.2f}",
                      f"{estimate.order:.2f}" if estimate else ("" if len(group) < 3 else "none (not monotone)"),
                      number(estimate.limit) if estimate else ""])
        verdict = analysis.convergence_verdict(spacings, errors)
        if verdict:
            remarks.append(f"{label} {verdict}.")
    report.table(["method", "h (m), coarsest first", "order per pair", "fitted order", "Richardson order",
                  "error as h -> 0"], table)
    report.paragraph("The order per pair is log(e1/e2)/log(h1/h2) of successive spacings; the fitted order the "
                     "least-squares slope of log e against log h; Richardson's estimate fits e = e0 + C h^p through "
                     "the three finest spacings, e0 the error the spacing does not control."
                     + (" " + " ".join(remarks) if remarks else "")
                     + (f" {', '.join(exact)}: an error of 0 at some spacing, no order." if exact else ""))


def time_steps(report: Report, directory: Path, rows, varied, error) -> None:
    if not any(key in varied for key in TIME_STEP_KEYS):
        return
    lines = {label: g for label, g in lines_over(rows, varied, "dt", lambda r: f"h = {number(r['spacing'])} m").items()
             if len({r["dt"] for r in g}) >= 2}
    if not lines:
        return
    figures.time_step([(label, [r["dt"] for r in g], [r[error] for r in g], group_of(label, g)) for label, g in lines.items()],
                      directory / FIGURES["time_step"])
    report.heading("Error against the time step")
    report.figure(FIGURES["time_step"], f"{error} against dt at fixed spacing: where it stays flat the spacing "
                  "dominates the error, where it moves with dt the time step does")
    report.table(["method, spacing", "dt (s), largest first", error],
                 [[label, ", ".join(number(r["dt"]) for r in reversed(g)), ", ".join(number(r[error]) for r in reversed(g))]
                  for label, g in lines.items()])


def cost_split(report: Report, directory: Path, rows, varied) -> None:
    timed = [r for r in rows if r["wall_time"] is not None and r["wall_time"] > 0 and r["steps"]]
    if not timed:
        return
    lines = lines_over(timed, varied, "spacing", lambda r: step_setting(r, varied))
    figures.cost([(label, [r["spacing"] for r in g], [r["steps"] for r in g], group_of(label, g)) for label, g in lines.items()],
                 [(label, [r["spacing"] for r in g], [1e3 * r["wall_time"] / r["steps"] for r in g], group_of(label, g))
                  for label, g in lines.items()], directory / FIGURES["cost"])
    report.heading("What the runs cost")
    report.figure(FIGURES["cost"], "Steps (set by each method's time step) and wall time per step, against spacing")
    report.table(["run", "method", "h (m)", "points", "nodes", "dt (s)", "critical dt (s)", "steps",
                  "time per step (ms)", "CG iterations per step", "wall time (s)"],
                 [[r["run"], method_of(r, varied), number(r["spacing"]), number(r["points"], 9), number(r["nodes"], 9),
                   number(r["dt"]), number(r["critical_dt"]), number(r["steps"], 9),
                   number(1e3 * r["wall_time"] / r["steps"]), number(r["cg_iterations"]), number(r["wall_time"])]
                  for g in lines.values() for r in g])
