"""Every public function of the research subpackages says what it takes and returns; entry points run as doctests.

A function is public when neither it, its class nor its module is private (a leading underscore). It needs a
numpydoc ``Parameters`` section when it takes an argument besides ``self``/``cls``, and a ``Returns`` (or
``Yields``) section when its body returns a value. Properties and dunder methods are exempt.
"""

from __future__ import annotations

import ast
import doctest
import importlib
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2] / "jaxlimb"
SUBPACKAGES = ("fitting", "models", "pipeline", "analysis", "irregular")
# The functions a reader starts from: each shows a runnable Example.
ENTRY_POINTS = (
    "jaxlimb.models.sigmoid.linear_intensity",
    "jaxlimb.models.sigmoid.circle_intensity",
    "jaxlimb.models.sigmoid.ellipse_intensity",
    "jaxlimb.fitting.fit.fit",
    "jaxlimb.pipeline.locate.locate",
    "jaxlimb.analysis.crlb.crlb",
    "jaxlimb.analysis.montecarlo.run_monte_carlo",
    "jaxlimb.analysis.posterior.sampler.sample_posterior",
    "jaxlimb.irregular.locate.locate_los",
)


def _section(doc: str, name: str) -> bool:
    lines = doc.splitlines()
    return any(
        line.strip() == name and i + 1 < len(lines) and set(lines[i + 1].strip()) == {"-"}
        for i, line in enumerate(lines)
    )


def _returns_value(fn: ast.FunctionDef) -> bool:
    nested = {id(n) for sub in ast.walk(fn) if sub is not fn and isinstance(sub, (ast.FunctionDef, ast.Lambda))
              for n in ast.walk(sub)}
    return any(isinstance(n, (ast.Return, ast.Yield)) and n.value is not None and id(n) not in nested
               and not (isinstance(n.value, ast.Constant) and n.value.value is None) for n in ast.walk(fn))


def _takes_arguments(fn: ast.FunctionDef, method: bool) -> bool:
    names = [a.arg for a in fn.args.posonlyargs + fn.args.args + fn.args.kwonlyargs]
    if method and names and names[0] in ("self", "cls"):
        names = names[1:]
    return bool(names or fn.args.vararg or fn.args.kwarg)


def _is_property(fn: ast.FunctionDef) -> bool:
    return any(isinstance(d, ast.Name) and d.id in ("property", "cached_property")
               or isinstance(d, ast.Attribute) and d.attr in ("setter", "cached_property")
               for d in fn.decorator_list)


def _public_functions(path: pathlib.Path):
    tree = ast.parse(path.read_text())
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and not node.name.startswith("_"):
            yield node.name, node, False
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            for sub in node.body:
                if isinstance(sub, ast.FunctionDef) and not sub.name.startswith("_") and not _is_property(sub):
                    yield f"{node.name}.{sub.name}", sub, True


def _modules(package: str):
    for path in sorted((ROOT / package).rglob("*.py")):
        parts = path.relative_to(ROOT).parts
        if not any(p.startswith("_") and p != "__init__.py" for p in parts):
            yield path


def undocumented(package: str) -> list[str]:
    """``module:function — missing sections`` for every public function of ``package`` short of the rule."""
    missing = []
    for path in _modules(package):
        for name, fn, method in _public_functions(path):
            doc = ast.get_docstring(fn) or ""
            lacks = []
            if _takes_arguments(fn, method) and not _section(doc, "Parameters"):
                lacks.append("Parameters")
            if _returns_value(fn) and not (_section(doc, "Returns") or _section(doc, "Yields")):
                lacks.append("Returns")
            if lacks:
                missing.append(f"{path.relative_to(ROOT.parent)}:{name} lacks {', '.join(lacks)}")
    return missing


@pytest.mark.parametrize("package", SUBPACKAGES)
def test_every_public_function_has_parameters_and_returns(package):
    missing = undocumented(package)
    assert not missing, f"{len(missing)} public functions short of the docstring rule:\n" + "\n".join(missing)


def _entry(dotted: str):
    module, name = dotted.rsplit(".", 1)
    return importlib.import_module(module), getattr(importlib.import_module(module), name)


@pytest.mark.parametrize("dotted", ENTRY_POINTS)
def test_entry_point_example_runs_as_a_doctest(dotted):
    module, obj = _entry(dotted)
    tests = doctest.DocTestFinder(recurse=False).find(obj, dotted, module=module, globs=vars(module).copy())
    examples = [t for t in tests if t.examples]
    assert examples and _section(obj.__doc__ or "", "Examples"), f"{dotted} shows no Examples section"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    for test in examples:
        runner.run(test)
    assert runner.failures == 0, f"{dotted}: {runner.failures} of its examples failed (see the output above)"
