"""``jaxlimb figures``: regenerate the paper figures (``paper_figures/make_all.py`` of a source checkout)."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

_SCRIPT = Path(__file__).resolve().parents[2] / "paper_figures" / "make_all.py"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("figures", help="regenerate the paper figures (ours beside the papers')",
                       description="Run every script in paper_figures/ (a source checkout is needed).")
    p.add_argument("--quick", action="store_true", help="small versions (seconds, as in the tests)")
    p.add_argument("--out", default="out/paper_figures",
                   help="output directory, relative to the current directory (default out/paper_figures)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .._validate import output_dir
    from ..errors import CheckFailed, ConfigError

    # relative to the current directory (the scripts run from the checkout): resolved here
    out = output_dir(args.out, "--out")
    if not _SCRIPT.exists():
        raise ConfigError(f"paper_figures/make_all.py not found beside the package ({_SCRIPT}): run from a source checkout")
    cmd = [sys.executable, str(_SCRIPT), "--out", str(out)] + (["--quick"] if args.quick else [])
    rc = subprocess.run(cmd, cwd=_SCRIPT.parent.parent).returncode
    if rc != 0:
        raise CheckFailed(f"some figure scripts failed (exit {rc}); see the output above")
    return 0
