"""The README's first lines and its Python example stay true."""

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_first_lines_give_the_two_commands():
    head = README.read_text().splitlines()[:6]
    assert any(line.startswith("make demo") for line in head)
    assert any(line.startswith("make test") for line in head)


def test_quick_start_example_runs():
    text = README.read_text()
    block = re.search(r"## Quick start \(Python\)\n\n```python\n(.*?)```", text, re.S)
    assert block, "README lost its quick-start example"
    ns: dict = {}
    exec(compile(block.group(1), "README.md", "exec"), ns)  # noqa: S102 - our own README
    res = ns["res"]
    assert bool(res.converged)
    assert abs(float(res.params.r0) - 200.3) < 5 * float(res.std["r0"])


def test_locate_example_runs():
    import math

    text = README.read_text()
    block = re.search(r"## Locate a body \(Python\)\n\n```python\n(.*?)```", text, re.S)
    assert block, "README lost its locate example"
    ns: dict = {}
    exec(compile(block.group(1), "README.md", "exec"), ns)  # noqa: S102 - our own README
    m, truth = ns["m"], ns["truth"]
    assert math.dist(m.center_rc, truth.center_rc) < 0.05
    assert abs(m.radius_px - truth.apparent_radius_px) < 0.05
    assert m.extras["profile"]["model"] == "lunar-lambert"
