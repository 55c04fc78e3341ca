"""docs/validation/constants.md: every tuned constant it states has that value in the package, and every anchor of
it a docstring points to exists."""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "validation" / "constants.md"


def test_the_page_states_the_package_values():
    stated = re.findall(r"`(jaxlimb(?:\.\w+)+)\.([A-Z][A-Z0-9_]*) = ([^`]+)`", PAGE.read_text())
    assert len(stated) >= 15, stated
    wrong = []
    for module, name, value in stated:
        actual = getattr(importlib.import_module(module), name)
        if actual != ast.literal_eval(value):
            wrong.append(f"{module}.{name}: the page says {value}, the package has {actual!r}")
    assert not wrong, wrong


def test_docstring_anchors_exist():
    anchors = set(re.findall(r"\{#([\w-]+)\}", PAGE.read_text()))
    cited = {(p.relative_to(ROOT), a) for p in (ROOT / "jaxlimb").rglob("*.py")
             for a in re.findall(r"docs/validation/constants\.md#([\w-]+)", p.read_text())}
    assert cited, "no docstring points to the page"
    missing = sorted(f"{p}: #{a}" for p, a in cited if a not in anchors)
    assert not missing, missing
