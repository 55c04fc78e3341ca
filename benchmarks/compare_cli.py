"""``jaxlimb compare`` (the command itself): every solver on the same realisations, compilation included.

Runs ``jaxlimb compare --n N --json`` as a user would, in a fresh process, with the persistent
compilation cache off (``JAXLIMB_CACHE_DIR=off``: every program compiled in the run), then with a fresh
empty cache directory and again with that directory filled (warm).  Records each process's wall time and
CPU time (user + system of the child, every thread), the load average before and after, and the command's
own JSON (per solver: success, failures, iterations, ms/fit wall and CPU, ``compile_s``, RMS/CRLB, the
largest difference from the first solver's estimate).

Run:  python benchmarks/compare_cli.py [--n 1000] [--runs off,cold,warm]
Writes benchmarks/results/compare.json.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

from _common import environment, save


def run_command(n: int, cache: str | None) -> dict:
    """One ``jaxlimb compare`` process: its JSON, wall and CPU seconds, load before and after."""
    env = dict(os.environ)
    env["JAXLIMB_CACHE_DIR"] = cache if cache is not None else "off"
    cmd = [sys.executable, "-m", "jaxlimb.cli", "compare", "--n", str(n), "--json", "-q"]
    load0, r0, t0 = os.getloadavg(), resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, check=True, env=env)
    wall, r1 = time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_CHILDREN)
    return {"command": " ".join(["jaxlimb", *cmd[3:]]), "cache": "off" if cache is None else "dir",
            "process_wall_s": wall, "process_cpu_s": (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime),
            "loadavg_before": list(load0), "loadavg_after": list(os.getloadavg()), "result": json.loads(p.stdout)}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--runs", default="off,cold,warm", help="comma-separated: off (no cache), cold (empty dir), warm")
    args = ap.parse_args(argv)
    runs = {}
    with tempfile.TemporaryDirectory() as cache_dir:
        for kind in args.runs.split(","):
            runs[kind] = run_command(args.n, None if kind == "off" else cache_dir)
            r = runs[kind]
            print(f"{kind}: wall {r['process_wall_s']:.1f} s, CPU {r['process_cpu_s']:.1f} s, "
                  f"load {r['loadavg_before'][0]:.1f} -> {r['loadavg_after'][0]:.1f}", flush=True)
    out = {"n": args.n, "runs": runs, "environment": environment()}
    print(save("compare", out))
    return out


if __name__ == "__main__":
    main()
