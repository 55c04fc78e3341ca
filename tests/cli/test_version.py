"""``jaxlimb --version``: the package's version, exit 0."""

from __future__ import annotations

import jaxlimb
from jaxlimb.cli import main


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"jaxlimb {jaxlimb.__version__}"
