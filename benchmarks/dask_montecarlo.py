"""Dask scale-out of the full-pipeline Monte Carlo: 2 local workers vs 1, same run.

Runs ``jaxlimb montecarlo --pipeline --n N --sigma 10 --seed 0 --out DIR --workers W --json``
(rendered 1944x2592 lunar-Lambert Moons through ``locate``) with W = 1 and W = 2, alternating,
``--repeats`` times each, into fresh directories; reports the median wall times, the speed-up
and the load average (the machine is shared: read the ratio with it).  The two result files
(``DIR/result.json``) must be identical: the chunks do not depend on who ran them.

Run:  python benchmarks/dask_montecarlo.py [--n 200] [--repeats 1]
Writes benchmarks/results/dask_montecarlo.json.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from _common import environment, save


def _load() -> list[float]:
    return [float(v) for v in Path("/proc/loadavg").read_text().split()[:3]]


def _run(n: int, workers: int, out: Path) -> dict:
    cmd = [sys.executable, "-m", "jaxlimb.cli", "montecarlo", "--pipeline", "--n", str(n), "--sigma", "10", "--seed", "0",
           "--out", str(out), "--workers", str(workers), "--json"]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, check=True)
    res = json.loads(p.stdout)
    return {"process_s": time.perf_counter() - t0, "wall_s": res["wall_s"], "n_ok": res["n_ok"],
            "command": " ".join(["jaxlimb", *cmd[3:]]), "result": (out / "result.json").read_text()}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="dask_mc_"))
    load0 = _load()
    runs: dict[int, list[dict]] = {1: [], 2: []}
    for r in range(args.repeats):
        for w in (1, 2):
            runs[w].append(_run(args.n, w, tmp / f"w{w}_{r}"))
            print(f"workers {w}: {runs[w][-1]['process_s']:.1f} s (wall {runs[w][-1]['wall_s']:.1f} s), "
                  f"{runs[w][-1]['n_ok']}/{args.n} ok, load {_load()}", flush=True)
    load1 = _load()
    med = {w: float(np.median([x["process_s"] for x in v])) for w, v in runs.items()}
    same = len({x["result"] for v in runs.values() for x in v}) == 1
    out = {"n": args.n, "median_process_s": med, "speedup_2_vs_1": med[1] / med[2], "identical_result_files": same,
           "runs": {w: [{k: x[k] for k in ("process_s", "wall_s", "n_ok", "command")} for x in v] for w, v in runs.items()},
           "loadavg_before": load0, "loadavg_after": load1, "environment": environment()}
    print(f"{args.n} frames: 1 worker {med[1]:.1f} s, 2 workers {med[2]:.1f} s -> {out['speedup_2_vs_1']:.2f}x; "
          f"result files identical: {same}; load {load0} -> {load1}")
    path = save("dask_montecarlo", out)
    print(f"wrote {path}")
    return out


if __name__ == "__main__":
    main()
