"""Execute every notebook with nbmake in a subprocess (STYLE.md Sec. 10: CI runs the notebooks)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def test_notebooks_present_and_clean():
    names = {p.stem for p in NOTEBOOKS}
    assert {"01_quick_start", "02_solver_comparison", "03_montecarlo_vs_crlb", "04_posterior"} <= names
    for p in NOTEBOOKS:
        nb = json.loads(p.read_text())
        code = [c for c in nb["cells"] if c["cell_type"] == "code"]
        assert all(not c.get("outputs") and c.get("execution_count") is None for c in code), f"{p.name} has outputs"
        assert "jax_enable_x64" in "".join(code[0]["source"]), f"{p.name} must enable x64 in its first code cell"


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs(notebook):
    """One notebook executed by nbmake in a subprocess (one test each: the test runner's workers share them)."""
    out = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "--nbmake", "--nbmake-timeout=300", "-p", "no:cacheprovider",
         "-o", "addopts=", str(notebook)],
        capture_output=True, text=True, timeout=400, cwd=ROOT,
    )
    assert out.returncode == 0, out.stdout[-6000:] + out.stderr[-2000:]
    assert "1 passed" in out.stdout
