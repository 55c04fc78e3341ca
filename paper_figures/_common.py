"""Helpers shared by the paper-figure scripts: style, captions, command line.

Each script is run as ``python paper_figures/<name>.py [--quick] [--out DIR]`` (its directory
is then on ``sys.path``, which is how it finds this module) or through ``make_all.py``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
STYLE = HERE / "paper.mplstyle"
DEFAULT_OUT = HERE.parent / "out" / "paper_figures"  # /out/ is git-ignored


def setup() -> Any:
    """Enable float64 and the shared style; return ``matplotlib.pyplot``."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.style.use(str(STYLE))
    return plt


def command(stem: str, quick: bool) -> str:
    """The command that makes a figure (written into its caption)."""
    return f"python paper_figures/{stem}.py{' --quick' if quick else ''} --out OUT_DIR"


def git_sha() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=HERE, capture_output=True, text=True, timeout=5)
        return out.stdout.strip() or "uncommitted"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def write_caption(out_dir: Path, stem: str, title: str, body: str, quick: bool, data: dict[str, Any] | None = None) -> Path:
    """Write ``<stem>.md`` (caption with the command) and, if given, ``<stem>.json`` (the numbers)."""
    from jaxlimb._io import atomic_open, write_json_atomic

    out_dir.mkdir(parents=True, exist_ok=True)
    md = out_dir / f"{stem}.md"
    with atomic_open(md) as fh:
        fh.write(f"# {title}\n\n{body.strip()}\n\nMade by: `{command(stem, quick)}` (git {git_sha()}"
                 f"{', quick mode' if quick else ''}).\n")
    if data is not None:
        data = dict(data, command=command(stem, quick), quick=quick)
        write_json_atomic(out_dir / f"{stem}.json", json.loads(json.dumps(data, default=float)))
    return md


def save(fig: Any, out_dir: Path, stem: str) -> Path:
    from jaxlimb._io import atomic_path

    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{stem}.png"
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return path


def cli(main: Callable[..., Any], stem: str) -> None:
    p = argparse.ArgumentParser(prog=f"{stem}.py", description=(main.__doc__ or "").strip().splitlines()[0])
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output directory (default {DEFAULT_OUT})")
    p.add_argument("--quick", action="store_true", help="small settings for tests (seconds)")
    a = p.parse_args()
    for path in main(a.out, quick=a.quick):
        print(path)
