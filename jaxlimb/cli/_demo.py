"""``jaxlimb demo``: the main job on built-in examples.

1. A circular-sigmoid fit on a rendered disk with known truth: estimate, 1-sigma,
   Cramér--Rao bound, and a small solver comparison (each solver's fit timed several times, the solvers taking
   turns: the median; every solver on many realisations is ``jaxlimb compare``).
2. ``locate`` on a rendered Moon frame (default 1944x2592 camera) and on the real
   SDO/HMI image shipped in ``shared/data/sun`` (if present), with pictures of the
   selected pixels and the fitted limb written to ``--out``.
"""

from __future__ import annotations

import argparse
import os


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the main job on built-in examples",
                       description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="demo_out", help="directory for the pictures (default demo_out/)")
    p.add_argument("--sdo", default=None, help="path of the SDO/HMI PNG (default: ../shared/data/sun/...)")
    p.add_argument("--json", action="store_true", help="print one JSON object with every number")
    p.set_defaults(func=run)


#: Timings of each solver's fit in the demo's table, the solvers taking turns (median reported).
DEMO_REPEATS = 7


def _fit_demo() -> dict[str, object]:
    import jax.numpy as jnp
    import numpy as np

    from ..analysis.compare import interleaved_timings
    from ..analysis.crlb import crlb
    from ..analysis.problems import ModelStudyOptions, model_problem
    from ..fitting import fit, solver_from_name

    opt = ModelStudyOptions()
    model, truth, init, coords, _ = model_problem(opt)
    z = np.asarray(model.intensity(truth, jnp.asarray(coords)))
    z = z + opt.sigma * np.random.default_rng(0).standard_normal(z.shape)
    bound = crlb(model, coords, truth, opt.sigma).std
    names = ("lm", "optx-lm", "dogleg", "paper", "scipy")
    solvers = {n: solver_from_name(n) for n in names}
    fits = {n: fit(model, coords, z, init, s) for n, s in solvers.items()}  # compiled before any timing
    calls = {n: (lambda b, s=s: fit(model, coords, z, init, s)) for n, s in solvers.items()}
    times, _ = interleaved_timings(calls, n_blocks=DEMO_REPEATS, repeats=1)
    rows = []
    for n in names:
        res = fits[n]
        rows.append({"solver": n, "ms": 1e3 * float(np.median([t[0] for t in times[n]])),
                     "cpu_ms": 1e3 * float(np.median([t[1] for t in times[n]])), "iterations": int(res.n_steps),
                     "r0": float(res.params.r0), "c0": float(res.params.c0), "radius": float(res.params.radius),
                     "std": {k: float(v) for k, v in res.std.items()}})
    return {"truth": truth.as_dict(), "n_pixels": int(coords.shape[0]), "sigma": opt.sigma, "crlb": bound,
            "timing": f"median of {DEMO_REPEATS} fits, the solvers taking turns", "fits": rows}


def run(args: argparse.Namespace) -> int:
    from . import emit_json

    from .._validate import input_file, output_dir

    out_dir = output_dir(args.out, "--out")  # before any work; relative to the current directory
    if args.sdo is not None:
        input_file(args.sdo, "--sdo")
    report: dict[str, object] = {"status": "ok", "model_fit": _fit_demo()}
    try:
        from ._demo_locate import locate_demos
    except ImportError:  # pragma: no cover - the pipeline is optional while it is being built
        locate_demos = None
    if locate_demos is not None:
        report["locate"] = locate_demos(out_dir, args.sdo)
    if args.json:
        emit_json(report)
        return 0
    fd = report["model_fit"]
    t = fd["truth"]  # type: ignore[index]
    print(f"1) circular-sigmoid fit, {fd['n_pixels']} pixels, noise sigma {fd['sigma']} DN")  # type: ignore[index]
    print(f"   truth  r0 {t['r0']:.4f}  c0 {t['c0']:.4f}  radius {t['radius']:.4f}")
    b = fd["crlb"]  # type: ignore[index]
    print(f"   CRLB   r0 {b['r0']:.4f}  c0 {b['c0']:.4f}  radius {b['radius']:.4f} px")
    print(f"   {'solver':8} {'ms/fit':>7} {'CPU ms':>7} {'iter':>4} {'r0':>10} {'c0':>10} {'radius':>10} {'1-sigma r0':>10}"
          f"   ({fd['timing']})")  # type: ignore[index]
    for r in fd["fits"]:  # type: ignore[index]
        print(f"   {r['solver']:8} {r['ms']:7.2f} {r['cpu_ms']:7.2f} {r['iterations']:4d} {r['r0']:10.4f} {r['c0']:10.4f} "
              f"{r['radius']:10.4f} {r['std']['r0']:10.4f}")
    if "locate" in report:
        for case in report["locate"]:  # type: ignore[union-attr]
            print(f"2) locate: {case['name']}")
            for line in case["lines"]:
                print(f"   {line}")
    print(f"(every solver on 1000 realisations: jaxlimb compare; pictures in {os.fspath(out_dir)}/)")
    return 0
