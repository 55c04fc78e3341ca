"""``jaxlimb montecarlo --pipeline --families ...`` as a user runs it: ``locate`` with its defaults on frames of the
independent renderer's scene families, one new frame per trial, and per family the centre's bias, RMS, mean sigma,
Cramér--Rao bound, mean and median NEES and the coverage of its 68 % / 95 % ellipses.

Run::

    python benchmarks/pipeline_families.py                                   # every Moon family, 30 frames each
    python benchmarks/pipeline_families.py --families own,hapke,glow --n 36 --seed 0 --name pipeline_families_seed0

Writes ``benchmarks/results/pipeline_families.json`` (``--name``): the command's own JSON (its summary per family and
its failures by reason), the command line, its wall time and the environment.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import environment, save  # noqa: E402


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", default="all", help="comma-separated Moon families, or all (default)")
    ap.add_argument("--n", type=int, default=420, help="trials (spread over the families in turn; default 420)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--name", default="pipeline_families", help="results file name (default pipeline_families)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="pipeline_families_") as d:
        cmd = ["jaxlimb", "montecarlo", "--pipeline", "--families", args.families, "--n", str(args.n), "--seed",
               str(args.seed), "--out", str(Path(d) / "study"), "--json"]
        t0 = time.perf_counter()
        p = subprocess.run([sys.executable, "-m", "jaxlimb.cli", *cmd[1:]], capture_output=True, text=True, check=False)
        wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} -> exit {p.returncode}: {p.stderr.strip()[-400:]}")
    out = json.loads(p.stdout)
    out.pop("result_file", None)
    result = {"command": " ".join(cmd[:-3] + ["--out", "DIR", "--json"]), "process_wall_s": wall, **out,
              "environment": environment()}
    for fam, s in out["summary"].items():
        print(f"{fam:10s} {s['n_ok']:3d}/{s['n']:3d}  NEES mean {s['nees_mean']:.2f} median {s['nees_median']:.2f}  "
              f"coverage 68 % {s['coverage']['68']:.2f} 95 % {s['coverage']['95']:.2f}")
    print(f"wrote {save(args.name, result)}")
    return result


if __name__ == "__main__":
    main()
