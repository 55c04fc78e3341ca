"""optimistix with and without the fused Jacobian / normal-equations plumbing, against NormalLM.

The nominal problem of ``benchmarks/solvers.py`` (400x400, radius 150, +-6 px band, sigma 10),
``--n`` realisations from the same start, every solver run on each in turn (round-robin, so that load
on a shared machine falls on all alike); ms per fit (median wall and CPU, after compilation), steps, and the
largest difference of the estimates from NormalLM's.  ``package default`` is ``Optimistix(solver)`` at
NormalLM's tolerances (``rtol = atol = 1e-10``), as ``--solver optx-lm`` / ``dogleg`` build it: fused Jacobian,
normal equations, coarse-to-fine start, NormalLM's stopping rule on the parameter step (``StepStop``); ``as it
comes`` is ``Optimistix(solver, fused=False, normal=False, coarse_stride=1, step_stop=False)`` (optimistix's
Cauchy test at ``OPTX_ATOL``);
the other rows remove one ingredient each (``Cauchy test, atol=1e-10``: optimistix's own test at NormalLM's
tolerances).

Run:  python benchmarks/optimistix_plumbing.py [--n 40]
Writes benchmarks/results/optimistix_plumbing.json.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optimistix as optx  # noqa: E402

from _common import environment, save  # noqa: E402
from jaxlimb.analysis.model_study import ModelStudyOptions, model_problem  # noqa: E402
from jaxlimb.fitting import NormalLM, Optimistix, fit  # noqa: E402
from jaxlimb.fitting.solvers import OPTX_ATOL, OPTX_RTOL  # noqa: E402


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=40)
    args = ap.parse_args(argv)
    model, truth, init, coords, _ = model_problem(ModelStudyOptions())
    clean = np.asarray(model.intensity(truth, jnp.asarray(coords)))
    data = clean[None] + 10.0 * np.random.default_rng(0).standard_normal((args.n, clean.size))
    tol = NormalLM.rtol, NormalLM.atol
    lm_ = lambda rtol=tol[0], atol=tol[1]: optx.LevenbergMarquardt(rtol=rtol, atol=atol)  # noqa: E731
    dl_ = lambda rtol=tol[0], atol=tol[1]: optx.Dogleg(rtol=rtol, atol=atol)  # noqa: E731
    plain = {"fused": False, "normal": False, "coarse_stride": 1, "step_stop": False}
    solvers = {"NormalLM": NormalLM(), "LevenbergMarquardt (package default)": Optimistix(lm_()),
               "LevenbergMarquardt, no coarse phase": Optimistix(lm_(), coarse_stride=1),
               "LevenbergMarquardt, Cauchy test, atol=1e-10": Optimistix(lm_(), step_stop=False),
               f"LevenbergMarquardt, Cauchy test, atol={OPTX_ATOL:g}": Optimistix(lm_(OPTX_RTOL, OPTX_ATOL), step_stop=False),
               "LevenbergMarquardt as it comes": Optimistix(lm_(OPTX_RTOL, OPTX_ATOL), **plain),
               "Dogleg (package default)": Optimistix(dl_()),
               "Dogleg, no coarse phase": Optimistix(dl_(), coarse_stride=1),
               f"Dogleg, Cauchy test, atol={OPTX_ATOL:g}": Optimistix(dl_(OPTX_RTOL, OPTX_ATOL), step_stop=False),
               "Dogleg as it comes": Optimistix(dl_(OPTX_RTOL, OPTX_ATOL), **plain)}
    load0 = Path("/proc/loadavg").read_text().split()[:3]
    for s in solvers.values():  # compile every program first
        jax.block_until_ready(fit(model, coords, data[0], init, s, throw=False).params.r0)
    rec = {name: {"wall": [], "cpu": [], "est": [], "steps": []} for name in solvers}
    for z in data:  # round-robin: a burst of load on a shared machine falls on every solver alike
        for name, s in solvers.items():
            t0, c0 = time.perf_counter(), time.process_time()
            r = fit(model, coords, z, init, s, throw=False)
            jax.block_until_ready(r.params.r0)
            rec[name]["wall"].append(time.perf_counter() - t0)
            rec[name]["cpu"].append(time.process_time() - c0)
            rec[name]["est"].append(np.asarray(r.params.to_vector()))
            rec[name]["steps"].append(int(r.n_steps))
    rows, ref = [], np.asarray(rec["NormalLM"]["est"])
    for name, v in rec.items():
        rows.append({"solver": name, "ms_per_fit": 1e3 * float(np.median(v["wall"])),
                     "cpu_ms_per_fit": 1e3 * float(np.median(v["cpu"])), "steps_mean": float(np.mean(v["steps"])),
                     "steps_max": int(np.max(v["steps"])),
                     "max_abs_diff_vs_normal_lm": float(np.abs(np.asarray(v["est"]) - ref)[:, :3].max()),
                     "median_ratio_per_fit": float(np.median(np.asarray(v["wall"]) / np.asarray(rec["NormalLM"]["wall"])))})
    for r in rows:
        r["over_normal_lm"] = r["ms_per_fit"] / rows[0]["ms_per_fit"]
        r["cpu_over_normal_lm"] = r["cpu_ms_per_fit"] / rows[0]["cpu_ms_per_fit"]
        print(f"{r['solver']:45s} {r['ms_per_fit']:8.2f} ms/fit  {r['over_normal_lm']:6.2f}x NormalLM "
              f"(CPU {r['cpu_over_normal_lm']:5.2f}x, per-fit median {r['median_ratio_per_fit']:5.2f}x)  "
              f"steps {r['steps_mean']:5.1f} (max {r['steps_max']:3d})  max|d| {r['max_abs_diff_vs_normal_lm']:.1e} px")
    out = {"rows": rows, "n": args.n, "loadavg_before": load0, "loadavg_after": Path("/proc/loadavg").read_text().split()[:3],
           "environment": environment()}
    print(f"load {out['loadavg_before']} -> {out['loadavg_after']}; wrote {save('optimistix_plumbing', out)}")
    return out


if __name__ == "__main__":
    main()
