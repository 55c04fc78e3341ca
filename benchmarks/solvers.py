"""Solver x scenario table for the circular-sigmoid fit.

Problem: 400x400 image, circular sigmoid, radius 150 px, k = 3, ymax 200, ymin 20,
pixels within +-6 px of the limb (~11 000), Gaussian noise sigma = 10, float64.

Scenarios
---------
nominal  start 0.5 px off in the centre and radius, k/ymax/ymin 10-25 % off.
far      start 2 px off in the centre and 5 % off in the radius (7.5 px); the pixel band
         is widened to +-12 px so that it still contains the true limb.
table1   k, ymax, ymin held fixed at the truth (the paper's Table 1: an n x 3 Jacobian).

For every solver: success rate, mean iterations, ms per single fit (after
compilation), compile time, agreement with SciPy's MINPACK LM (analytic
Jacobian) on the same data, and the time for ``--n-batch`` realisations
(SciPy in a Python loop vs our batched ``fit_batch`` path), with the ratios to
SciPy measured in the same run.

Run:  python benchmarks/solvers.py [--quick] [--n-batch 1000]
Writes benchmarks/results/solvers.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time

# SciPy at its best here: single-threaded BLAS (OpenBLAS threads slow MINPACK's small QRs 2-3x on
# this shared 2-core machine); JAX's CPU backend does not use these variables.
for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jaxlimb.analysis.model_study import ModelStudyOptions, model_problem  # noqa: E402
from jaxlimb.fitting import SOLVERS, fit, fit_batch, solver_from_name  # noqa: E402

from _common import environment, save  # noqa: E402
from _scipy_numpy import fit_circle_scipy  # noqa: E402

SOLVER_ORDER = ["lm", "optx-normal-lm", "optx-lm", "dogleg", "gauss-newton", "bfgs", "paper", "scipy", "scipy-numpy"]
NUMPY_BASELINE = "scipy-numpy"  # SciPy lm + the model and its Jacobian in NumPy (_scipy_numpy.py): the strongest baseline
# batch timings: every strategy for the default, the fast "map" path for the others (vmap of the
# slow solvers takes minutes for 1000 realisations and is measured in --quick mode only)
BATCH_STRATEGIES = {"lm": ("map", "vmap"), "optx-normal-lm": ("map",), "optx-lm": ("map",), "dogleg": ("map",),
                    "paper": ("map", "vmap")}


def _scenario_inits(name: str, truth, rng: np.random.Generator, n: int):  # noqa: ANN001, ANN202
    tv = np.asarray(truth.to_vector())
    out = np.repeat(tv[None], n, 0)
    ang = rng.uniform(0, 2 * np.pi, n)
    if name == "far":
        out[:, 0] += 2.0 * np.sin(ang)
        out[:, 1] += 2.0 * np.cos(ang)
        out[:, 2] *= 1.0 + 0.05 * rng.choice([-1.0, 1.0], n)
    else:
        out[:, 0] += 0.5 * np.sin(ang)
        out[:, 1] += 0.5 * np.cos(ang)
        out[:, 2] += 0.5 * rng.choice([-1.0, 1.0], n)
    if name != "table1":
        out[:, 3] *= rng.uniform(0.75, 1.25, n)
        out[:, 4] *= rng.uniform(0.9, 1.1, n)
        out[:, 5] *= rng.uniform(0.8, 1.2, n)
    return out


def _numpy_row(scen: str, coords, data, inits, fixed, truth, model) -> dict:  # noqa: ANN001
    """The strongest SciPy baseline on one scenario (no JAX in its loop)."""
    free = np.array([i for i, n in enumerate(model.param_names) if n not in fixed])
    ok, steps, est, times = [], [], [], []
    for i in range(len(data)):
        t0 = time.perf_counter()
        x, nj, conv = fit_circle_scipy(coords, data[i], inits[i], free)
        times.append(time.perf_counter() - t0)
        ok.append(conv and abs(x[0] - float(truth.r0)) < 0.1 and abs(x[2] - float(truth.radius)) < 0.1)
        steps.append(nj)
        est.append(x[:3])
    row = {"scenario": scen, "solver": NUMPY_BASELINE, "success_rate": float(np.mean(ok)),
           "iterations_mean": float(np.mean(steps)), "ms_per_fit_median": 1e3 * float(np.median(times)),
           "compile_s": 0.0, "n": len(data), "_est": np.asarray(est)}
    print(f"{scen:8s} {NUMPY_BASELINE:15s} ok {row['success_rate']:6.1%}  it {row['iterations_mean']:6.1f}  "
          f"{row['ms_per_fit_median']:8.2f} ms/fit", flush=True)
    return row


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer realisations (for CI / a first look)")
    ap.add_argument("--n-batch", type=int, default=1000, help="realisations for the batch timing (default 1000)")
    ap.add_argument("--n-success", type=int, default=200, help="realisations per scenario for success rates")
    ap.add_argument("--solvers", default=",".join(SOLVER_ORDER))
    args = ap.parse_args(argv)
    n_batch = 50 if args.quick else args.n_batch
    n_succ = 20 if args.quick else args.n_success
    solvers = [s for s in args.solvers.split(",") if s]
    for s in solvers:
        if s not in SOLVERS and s != NUMPY_BASELINE:
            ap.error(f"unknown solver {s!r}")

    opt = ModelStudyOptions()
    model, truth, _, coords_nominal, _ = model_problem(opt)
    coords_far = model_problem(dataclasses.replace(opt, annulus=12.0))[3]
    rng = np.random.default_rng(2026)
    rows = []
    scipy_ref: dict[str, np.ndarray] = {}
    for scen in ("nominal", "far", "table1"):
        coords = coords_far if scen == "far" else coords_nominal
        clean = np.asarray(model.intensity(truth, jnp.asarray(coords)))
        data = clean[None] + opt.sigma * rng.standard_normal((n_succ, clean.size))
        fixed = ("k", "ymax", "ymin") if scen == "table1" else ()
        inits = _scenario_inits(scen, truth, np.random.default_rng(7), n_succ)
        for name in solvers:
            if name == NUMPY_BASELINE:
                rows.append(_numpy_row(scen, coords, data, inits, fixed, truth, model))
                continue
            solver = solver_from_name(name)
            p0 = model.params_type.from_vector(jnp.asarray(inits[0]))
            t0 = time.perf_counter()
            fit(model, coords, data[0], p0, solver, fixed=fixed, throw=False)
            compile_s = time.perf_counter() - t0
            ok, steps, est, times = [], [], [], []
            for i in range(n_succ):
                p0 = model.params_type.from_vector(jnp.asarray(inits[i]))
                t0 = time.perf_counter()
                r = fit(model, coords, data[i], p0, solver, fixed=fixed, throw=False)
                jax.block_until_ready(r.params.r0)
                times.append(time.perf_counter() - t0)
                conv = bool(r.converged)
                good = conv and abs(float(r.params.r0) - float(truth.r0)) < 0.1 and abs(float(r.params.radius) - float(truth.radius)) < 0.1
                ok.append(good)
                steps.append(int(r.n_steps))
                est.append(np.asarray(r.params.to_vector())[:3])
            est = np.asarray(est)
            if name == "scipy":
                scipy_ref[scen] = est
            row = {
                "scenario": scen, "solver": name, "success_rate": float(np.mean(ok)),
                "iterations_mean": float(np.mean(steps)), "ms_per_fit_median": 1e3 * float(np.median(times)),
                "compile_s": compile_s, "n": n_succ,
            }
            rows.append(row)
            print(f"{scen:8s} {name:15s} ok {row['success_rate']:6.1%}  it {row['iterations_mean']:6.1f}  "
                  f"{row['ms_per_fit_median']:8.2f} ms/fit  first call {compile_s:5.2f} s", flush=True)
            rows[-1]["_est"] = est
    # agreement with scipy (same data, same start)
    for row in rows:
        ref = scipy_ref.get(row["scenario"])
        est = row.pop("_est")
        if ref is not None:
            row["max_abs_diff_vs_scipy_px"] = float(np.max(np.abs(est - ref)))
    # ratios to the strongest SciPy (NumPy model) and to SciPy driving the JAX model, per scenario
    for row in rows:
        for base, key in ((NUMPY_BASELINE, "speedup_vs_scipy_numpy_single"), ("scipy", "speedup_vs_scipy_single")):
            ref = next((r for r in rows if r["scenario"] == row["scenario"] and r["solver"] == base), None)
            if ref is not None:
                row[key] = ref["ms_per_fit_median"] / row["ms_per_fit_median"]
        lm = next((r for r in rows if r["scenario"] == row["scenario"] and r["solver"] == "lm"), None)
        if lm is not None:
            row["ms_over_lm"] = row["ms_per_fit_median"] / lm["ms_per_fit_median"]

    # batch: n_batch realisations, nominal scenario
    coords = coords_nominal
    clean = np.asarray(model.intensity(truth, jnp.asarray(coords)))
    data = clean[None] + opt.sigma * rng.standard_normal((n_batch, clean.size))
    inits = _scenario_inits("nominal", truth, np.random.default_rng(8), n_batch)
    batch = {}
    for name in solvers:
        if name not in BATCH_STRATEGIES and name != "scipy":
            continue
        solver = solver_from_name(name)
        if solver.jittable:
            for strategy in BATCH_STRATEGIES[name]:
                cb = np.broadcast_to(coords, (n_batch, *coords.shape))
                p0 = model.params_type.from_vector(jnp.asarray(inits))
                t0 = time.perf_counter()
                r = fit_batch(model, cb, data[:n_batch], p0, solver, strategy=strategy)
                jax.block_until_ready(r.params.r0)
                first = time.perf_counter() - t0
                t0 = time.perf_counter()
                r = fit_batch(model, cb, data[:n_batch] + 0.0, p0, solver, strategy=strategy)
                jax.block_until_ready(r.params.r0)
                secs = time.perf_counter() - t0
                batch[f"{name}/{strategy}"] = {"seconds": secs, "first_call_s": first,
                                               "converged": int(np.sum(np.asarray(r.converged)))}
                print(f"batch {n_batch:5d} {name:15s} {strategy:5s} {secs:8.2f} s (first call {first:.2f} s), "
                      f"converged {batch[f'{name}/{strategy}']['converged']}", flush=True)
        elif name == "scipy":
            t0 = time.perf_counter()
            conv = 0
            for i in range(n_batch):
                r = fit(model, coords, data[i], model.params_type.from_vector(jnp.asarray(inits[i])), solver, throw=False)
                conv += bool(r.converged)
            secs = time.perf_counter() - t0
            batch["scipy/loop"] = {"seconds": secs, "converged": conv}
            print(f"batch {n_batch:5d} scipy           loop  {secs:8.2f} s, converged {conv}", flush=True)
    if NUMPY_BASELINE in solvers:
        t0 = time.perf_counter()
        free = np.arange(6)
        conv = sum(fit_circle_scipy(coords, data[i], inits[i], free)[2] for i in range(n_batch))
        batch["scipy-numpy/loop"] = {"seconds": time.perf_counter() - t0, "converged": int(conv)}
        print(f"batch {n_batch:5d} scipy-numpy     loop  {batch['scipy-numpy/loop']['seconds']:8.2f} s, converged {conv}",
              flush=True)
    for base, key in (("scipy-numpy/loop", "speedup_vs_scipy_numpy_loop"), ("scipy/loop", "speedup_vs_scipy_loop")):
        if base in batch:
            for v in batch.values():
                v[key] = batch[base]["seconds"] / v["seconds"]

    nan = float("nan")
    table = ["| scenario | solver | success | iterations | ms/fit | / lm | vs SciPy+NumPy | vs SciPy+JAX | "
             "max |Δ| vs SciPy (px) | first call (s) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        table.append(f"| {r['scenario']} | {r['solver']} | {r['success_rate']:.1%} | {r['iterations_mean']:.1f} | "
                     f"{r['ms_per_fit_median']:.2f} | {r.get('ms_over_lm', nan):.2f} | "
                     f"{r.get('speedup_vs_scipy_numpy_single', nan):.1f}x | {r.get('speedup_vs_scipy_single', nan):.1f}x | "
                     f"{r.get('max_abs_diff_vs_scipy_px', nan):.1e} | {r['compile_s']:.2f} |")
    table.append("")
    table.append(f"| batch of {n_batch} | seconds | vs SciPy+NumPy loop | vs SciPy+JAX loop |")
    table.append("|---|---|---|---|")
    for k, v in batch.items():
        table.append(f"| {k} | {v['seconds']:.2f} | {v.get('speedup_vs_scipy_numpy_loop', nan):.1f}x | "
                     f"{v.get('speedup_vs_scipy_loop', nan):.1f}x |")
    print("\n".join(table))
    out = {"problem": {"shape": list(opt.shape), "radius": opt.radius, "k": opt.k, "ymax": opt.ymax, "ymin": opt.ymin,
                       "sigma": opt.sigma, "n_pixels": int(coords.shape[0])},
           "rows": rows, "batch": batch, "n_batch": n_batch, "quick": args.quick, "table_md": "\n".join(table),
           "loadavg": open("/proc/loadavg").read().split()[:3] if os.path.exists("/proc/loadavg") else None,
           "environment": environment()}
    path = save("solvers_quick" if args.quick else "solvers", out)
    print(f"wrote {path}")
    return out


if __name__ == "__main__":
    main()
