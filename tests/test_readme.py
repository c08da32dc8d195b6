"""The README's Python example runs and prints what it says."""

import re
from pathlib import Path

README = Path(__file__).parents[1] / "README.md"


def test_readme_python_example(capsys):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert blocks, "README has no python example"
    for block in blocks:
        exec(compile(block, str(README), "exec"), {})
    steps, total = capsys.readouterr().out.split()
    assert steps == "334"
    assert abs(float(total) - 0.125) < 0.125 * 0.01  # total energy conserved within 1%
