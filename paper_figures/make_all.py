"""Run every paper-figure script in this directory: ``python paper_figures/make_all.py [--quick] [--out DIR]``.

Each ``figNN_*.py`` / ``tabNN_*.py`` script defines ``main(out_dir, quick=False)``; this
imports them in name order, runs each (one failure does not stop the others) and exits 1
if any failed.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
import traceback
from pathlib import Path

import _common


def scripts() -> list[str]:
    return sorted(p.stem for p in _common.HERE.glob("*.py") if p.stem.split("_")[0][:3] in ("fig", "tab"))


def main(out_dir: Path | str = _common.DEFAULT_OUT, quick: bool = False) -> dict[str, object]:
    """Run all scripts; return ``{name: [paths] | "error: ..."}``."""
    out: dict[str, object] = {}
    for name in scripts():
        t0 = time.perf_counter()
        try:
            paths = importlib.import_module(name).main(Path(out_dir), quick=quick)
            out[name] = [str(p) for p in paths]
            print(f"{name}: {len(paths)} files in {time.perf_counter() - t0:.1f} s", flush=True)
        except Exception as e:  # report and continue with the other figures
            traceback.print_exc()
            out[name] = f"error: {type(e).__name__}: {e}"
            print(f"{name}: FAILED ({e})", flush=True)
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=_common.DEFAULT_OUT)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    res = main(a.out, a.quick)
    sys.exit(1 if any(isinstance(v, str) for v in res.values()) else 0)
