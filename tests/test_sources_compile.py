"""Every module compiles without a warning (an invalid escape in a docstring prints a SyntaxWarning on the CLI's
stderr the first time a process compiles it, which the CLI contract forbids)."""

from __future__ import annotations

import warnings
from pathlib import Path

import jaxlimb


def test_no_module_compiles_with_a_warning():
    root = Path(jaxlimb.__file__).parent
    bad = []
    for p in sorted(root.rglob("*.py")):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            try:
                compile(p.read_text(encoding="utf-8"), str(p), "exec")
            except (SyntaxError, SyntaxWarning) as e:
                bad.append(f"{p.relative_to(root)}: {e}")
    assert not bad, bad
