"""``jaxlimb montecarlo`` (the command itself) against the strongest SciPy baseline, same run.

1. Runs ``jaxlimb montecarlo --n N --seed 3 --json --out DIR`` as a user would (a fresh process,
   twice: the first may compile, the second loads the programs from the persistent cache) and
   reads its ``fit_s`` (fits only), ``compile_s`` and ``wall_s``.
2. Fits the same realisations (the same noise draws: the chunk files of ``--out DIR`` hold the
   seeds, the noise is redrawn by the package's own generator) with SciPy
   ``least_squares(method="lm")`` and the model + analytic Jacobian in NumPy
   (``benchmarks/_scipy_numpy.py``, the strongest baseline; single-threaded BLAS, its fastest
   setting here), and with the package's
   ``ScipyLeastSquares`` (SciPy driving the jitted JAX model: second row).
3. Reports ms per fit and the ratios, the agreement of the estimates, and the load average.

Run:  python benchmarks/montecarlo_cli.py [--n 1000] [--n-scipy 200]
Writes benchmarks/results/montecarlo_cli.json.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

_USER_ENV = dict(os.environ)  # the command runs with the user's environment
# the baseline at its best: single-threaded BLAS (on this shared 2-core machine OpenBLAS threads
# make MINPACK's small QR factorisations 2-3x slower)
for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from _common import environment, save  # noqa: E402
from _scipy_numpy import fit_circle_scipy  # noqa: E402
from jaxlimb.analysis.model_study import ModelStudyOptions, model_problem, noisy_intensities  # noqa: E402
from jaxlimb.analysis.montecarlo import load_monte_carlo  # noqa: E402
from jaxlimb.fitting import ScipyLeastSquares, fit  # noqa: E402


def _command(n: int, out: Path) -> dict:
    cmd = [sys.executable, "-m", "jaxlimb.cli", "montecarlo", "--n", str(n), "--seed", "3", "--json", "--out", str(out)]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, check=True, env=_USER_ENV)
    res = json.loads(p.stdout)
    res["process_s"] = time.perf_counter() - t0
    res["command"] = " ".join(["jaxlimb", *cmd[3:]])
    return res


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--n-scipy", type=int, default=200)
    ap.add_argument("--n-scipy-jax", type=int, default=50)
    args = ap.parse_args(argv)
    load = [float(v) for v in Path("/proc/loadavg").read_text().split()[:3]] if Path("/proc/loadavg").exists() else None
    tmp = Path(tempfile.mkdtemp(prefix="mc_cli_"))
    runs = [_command(args.n, tmp / f"run{i}") for i in range(2)]
    cmd = runs[1]
    study = load_monte_carlo(tmp / "run1")
    opt = ModelStudyOptions()
    model, truth, init, coords, _ = model_problem(opt)
    clean = np.asarray(model.intensity(truth, jnp.asarray(coords)))
    m = min(args.n_scipy, args.n)
    z = noisy_intensities(study.seeds[:m], clean, opt.sigma)
    x0 = np.asarray(init.to_vector())
    t0, c0 = time.perf_counter(), time.process_time()
    sp = [fit_circle_scipy(coords, zi, x0) for zi in z]
    scipy_np_ms = 1e3 * (time.perf_counter() - t0) / m
    scipy_np_cpu_ms = 1e3 * (time.process_time() - c0) / m
    est_sp = np.array([s[0] for s in sp])
    names = list(model.param_names)
    est_cmd = np.stack([study.values[nm][:m] for nm in names], axis=1)
    diff = float(np.max(np.abs(est_sp[:, :3] - est_cmd[:, :3])))
    mj = min(args.n_scipy_jax, m)
    fit(model, coords, z[0], init, ScipyLeastSquares(), throw=False)  # compile its callables first
    t0 = time.perf_counter()
    for zi in z[:mj]:
        fit(model, coords, zi, init, ScipyLeastSquares(), throw=False)
    scipy_jax_ms = 1e3 * (time.perf_counter() - t0) / mj
    per_fit = 1e3 * cmd["fit_s"] / args.n
    per_fit_cpu = 1e3 * cmd["fit_cpu_s"] / args.n
    per_wall = 1e3 * cmd["wall_s"] / args.n
    per_proc = 1e3 * cmd["process_s"] / args.n
    out = {
        "command": cmd["command"], "n": args.n, "loadavg_before": load,
        "loadavg_after": [float(v) for v in Path("/proc/loadavg").read_text().split()[:3]] if load else None,
        "runs": [{k: r[k] for k in ("fit_s", "fit_cpu_s", "compile_s", "wall_s", "process_s", "converged")} for r in runs],
        "command_ms_per_fit": per_fit, "command_wall_ms_per_fit": per_wall, "command_process_ms_per_fit": per_proc,
        "scipy_numpy_ms_per_fit": scipy_np_ms, "scipy_numpy_n": m, "scipy_numpy_converged": int(sum(s[2] for s in sp)),
        "scipy_jax_ms_per_fit": scipy_jax_ms, "scipy_jax_n": mj,
        "command_cpu_ms_per_fit": per_fit_cpu, "scipy_numpy_cpu_ms_per_fit": scipy_np_cpu_ms,
        "speedup_fit_cpu_vs_scipy_numpy": scipy_np_cpu_ms / per_fit_cpu,
        "speedup_fit_vs_scipy_numpy": scipy_np_ms / per_fit,
        "speedup_wall_vs_scipy_numpy": scipy_np_ms / per_wall,
        "speedup_process_vs_scipy_numpy": scipy_np_ms / per_proc,
        "speedup_fit_vs_scipy_jax": scipy_jax_ms / per_fit,
        "max_abs_diff_center_radius_px_vs_scipy_numpy": diff,
        "environment": environment(), "cpu_count": os.cpu_count(),
    }
    print(f"load average {load}")
    for i, r in enumerate(runs):
        print(f"run {i}: fit_s {r['fit_s']:.2f}  compile_s {r['compile_s']:.2f}  wall_s {r['wall_s']:.2f}  "
              f"process {r['process_s']:.2f} s  converged {r['converged']}/{args.n}")
    print(f"{cmd['command']}: {per_fit:.2f} ms/fit (fits), {per_wall:.2f} ms/fit (wall), {per_proc:.2f} (process)")
    print(f"SciPy lm + NumPy model/Jacobian: {scipy_np_ms:.2f} ms/fit ({m} fits) -> command {out['speedup_fit_vs_scipy_numpy']:.1f}x "
          f"(fits), {out['speedup_wall_vs_scipy_numpy']:.1f}x (wall), {out['speedup_process_vs_scipy_numpy']:.1f}x (process)")
    print(f"CPU time per fit: command {per_fit_cpu:.2f} ms, SciPy+NumPy {scipy_np_cpu_ms:.2f} ms -> "
          f"{out['speedup_fit_cpu_vs_scipy_numpy']:.1f}x")
    print(f"SciPy lm driving the JAX model (ScipyLeastSquares): {scipy_jax_ms:.2f} ms/fit -> {out['speedup_fit_vs_scipy_jax']:.1f}x")
    print(f"max |centre/radius difference| vs SciPy on the same data: {diff:.1e} px; load after {out['loadavg_after']}")
    path = save("montecarlo_cli", out)
    print(f"wrote {path}")
    return out


if __name__ == "__main__":
    main()
