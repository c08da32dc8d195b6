"""Every notebook's code runs, in order, and its numbers are the ones the README reports."""

import json
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")

NOTEBOOKS = sorted((Path(__file__).parents[1] / "notebooks").glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, capsys):
    namespace: dict = {}
    for cell in json.loads(path.read_text())["cells"]:
        if cell["cell_type"] == "code":
            exec(compile("".join(cell["source"]), str(path), "exec"), namespace)
    output = capsys.readouterr().out
    if path.stem == "quickstart":
        # the bar's periods (README: q1 +1.58%, bspline3 consistent +0.00%) and the cantilever
        errors = {(basis, mass): error for basis, mass, error, _ in namespace["rows"]}
        assert errors[("q1", "lumped")] == pytest.approx(0.0158, abs=5e-4)
        assert abs(errors[("bspline3", "consistent")]) < 5e-4
        assert "bspline3_open  tip / T&G = 1.0" in output
