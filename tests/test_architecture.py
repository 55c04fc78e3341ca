"""The package's architecture (docs/design.md): the import-linter contract of pyproject.toml (layers, no import
circle, private modules kept private), no private name taken across files, small files and, in the pipeline,
small functions."""

from __future__ import annotations

import ast
import pathlib
import shutil
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PKG = ROOT / "jaxlimb"
def _lint_imports() -> str | None:
    exe = shutil.which("lint-imports") or str(pathlib.Path(sys.executable).with_name("lint-imports"))
    return exe if pathlib.Path(exe).exists() else None


@pytest.mark.skipif(_lint_imports() is None, reason="import-linter is not installed (pip install -e '.[test]')")
def test_import_contracts_are_kept():
    r = subprocess.run([_lint_imports(), "--no-cache"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "0 broken" in r.stdout


def _module_dir(path: pathlib.Path, node: ast.ImportFrom) -> pathlib.Path:
    """The directory of the package ``from X import ...`` names (a private module of it is not a private name)."""
    if node.level == 0:
        return ROOT.joinpath(*(node.module or "").split("."))
    base = path.parent
    for _ in range(node.level - 1):
        base = base.parent
    return base.joinpath(*node.module.split(".")) if node.module else base


def _private_imports() -> set[tuple[str, str]]:
    out = set()
    for path in sorted(PKG.rglob("*.py")):
        rel = str(path.relative_to(ROOT))
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.level > 0 or (node.module or "").startswith("jaxlimb")):
                d = _module_dir(path, node)
                out |= {(rel, a.name) for a in node.names if a.name.startswith("_") and not a.name.startswith("__")
                        and not (d / f"{a.name}.py").exists() and not (d / a.name).is_dir()}
    return out


def test_no_private_name_crosses_a_file():
    assert not _private_imports(), sorted(_private_imports())


def test_files_are_small_and_functions_short():
    large = {str(p.relative_to(ROOT)) for p in PKG.rglob("*.py") if len(p.read_text().splitlines()) > 500}
    assert not large, sorted(large)
    long = []
    for path in sorted(PKG.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.end_lineno - node.lineno >= 60:
                long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}")
    assert long == [], long


def test_no_internal_import_inside_a_function_in_the_pipeline():
    """Function-local imports are for optional heavy dependencies only; the pipeline imports its own modules at the
    top (an import circle cannot hide there)."""
    local = []
    for path in sorted((PKG / "pipeline").rglob("*.py")):
        for fn in ast.walk(ast.parse(path.read_text())):
            if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                local += [f"{path.relative_to(ROOT)}:{n.lineno}" for n in ast.walk(fn)
                          if isinstance(n, ast.ImportFrom) and (n.level > 0 or (n.module or "").startswith("jaxlimb"))]
    assert local == [], local
