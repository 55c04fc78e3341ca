"""Where do the emcee posterior, the Laplace covariance and the Cramér--Rao bound disagree?

``python benchmarks/posterior_study.py [--quick] [--out benchmarks/results/posterior_study.json] [--corner DIR]``

Cases (circular sigmoid, Eq. 16 of Mortari et al. 2016; pixels within ``annulus`` px of the
limb on an arc; Gaussian noise sigma = 10 grey levels unless a case says otherwise, known):

* ``full_free``      -- full limb, all six parameters free (well posed);
* ``full_fixed``     -- full limb, k, ymax, ymin fixed at the truth (paper's Table 1 set-up);
* ``crescent_free``  -- the lit half of the limb (180 deg: a crescent's or gibbous limb), six free;
* ``arc60_free``     -- a 60 deg arc, six free;
* ``arc60_fixed``    -- a 60 deg arc, k, ymax, ymin fixed;
* ``blur_free``      -- a blurred edge (k = 0.4) in a narrow band (+-5 px): k, ymax, ymin trade off;
* ``blur_arc60_free``-- both;
* ``arc30_noisy_*``  -- a 30 deg arc at sigma = 30 (six free / k, ymax, ymin fixed): the radius is
  then uncertain by several px and the likelihood is visibly non-Gaussian in (c0, radius);
* ``veryblur_narrow_free`` -- k = 0.15 (a 7 px wide edge) seen through a +-4 px band: the band
  holds only the middle of the sigmoid, so k, ymax and ymin are nearly degenerate.

For each case: the posterior (emcee, vectorised, tau-converged), the Laplace covariance
sigma_hat^2 (J^T J)^-1 of :func:`jaxlimb.fitting.fit` on the same noisy frame, the CRLB at the
truth and -- the arbiter -- the RMS error of ``n_mc`` independent fits (Monte-Carlo engine +
``fit_batch``).  The JSON records the seed, git SHA, jax version and the timings, plus the
vectorize speed-up (one vmapped call per half-ensemble vs one call per walker).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jaxlimb._io import write_json_atomic  # noqa: E402
from jaxlimb.analysis.crlb import crlb  # noqa: E402
from jaxlimb.analysis.montecarlo import MonteCarloOptions, run_monte_carlo  # noqa: E402
from jaxlimb.analysis.posterior import (  # noqa: E402
    PosteriorOptions,
    compare_uncertainties,
    comparison_table,
    corner_plot,
    log_posterior,
    sample_posterior,
    synthetic_circle,
    vectorize_speedup,
)
from jaxlimb.fitting import fit, fit_batch  # noqa: E402
from jaxlimb.models import CIRCLE  # noqa: E402

FIXED3 = ("k", "ymax", "ymin")
CASES = {
    "full_free": dict(arc_deg=360.0, k=3.0, annulus=4.0, fixed=()),
    "full_fixed": dict(arc_deg=360.0, k=3.0, annulus=4.0, fixed=FIXED3),
    "crescent_free": dict(arc_deg=180.0, k=3.0, annulus=4.0, fixed=()),
    "arc60_free": dict(arc_deg=60.0, k=3.0, annulus=4.0, fixed=()),
    "arc60_fixed": dict(arc_deg=60.0, k=3.0, annulus=4.0, fixed=FIXED3),
    "blur_free": dict(arc_deg=360.0, k=0.4, annulus=5.0, fixed=()),
    "blur_arc60_free": dict(arc_deg=60.0, k=0.4, annulus=5.0, fixed=()),
    "arc30_noisy_free": dict(arc_deg=30.0, k=3.0, annulus=4.0, fixed=(), sigma=30.0),
    "arc30_noisy_fixed": dict(arc_deg=30.0, k=3.0, annulus=4.0, fixed=FIXED3, sigma=30.0),
    "veryblur_narrow_free": dict(arc_deg=360.0, k=0.15, annulus=4.0, fixed=()),
}


def _git_sha() -> str:
    from _common import environment

    return environment()["git_sha"]


def run_case(name: str, radius: float, sigma_default: float, n_mc: int, seed: int, max_time: float,
             corner_dir: Path | None) -> dict:
    c = CASES[name]
    sigma = float(c.get("sigma", sigma_default))
    s = synthetic_circle(radius=radius, k=c["k"], sigma=sigma, arc_deg=c["arc_deg"], annulus=c["annulus"], seed=seed)
    fixed = c["fixed"]
    init = s.truth.replace(r0=s.truth.r0 + 0.2, radius=s.truth.radius - 0.2)
    f = fit(CIRCLE, s.coords, s.z, init, fixed=fixed, throw=False)
    lp = log_posterior(CIRCLE, s.coords, s.z, f.params, fixed=fixed, noise="known", sigma=sigma)
    post = sample_posterior(lp, f, options=PosteriorOptions(seed=seed, max_time_s=max_time, max_steps=40_000))
    bound = crlb(CIRCLE, s.coords, s.truth, sigma, fixed=fixed)
    cmp = compare_uncertainties(post, f, bound, s.truth)
    # the arbiter: RMS of independent fits (same pixels, new noise)
    clean = np.asarray(CIRCLE.intensity(s.truth, jnp.asarray(s.coords)))
    v0 = np.asarray(init.to_vector())

    def batch(seeds: np.ndarray, idx: np.ndarray) -> dict[str, np.ndarray]:
        z = np.stack([clean + sigma * np.random.default_rng(int(sd)).standard_normal(clean.size) for sd in seeds])
        res = fit_batch(CIRCLE, np.broadcast_to(s.coords, (len(seeds), *s.coords.shape)), z,
                        CIRCLE.params_type.from_vector(jnp.asarray(np.repeat(v0[None], len(seeds), 0))), fixed=fixed)
        return {n: np.asarray(getattr(res.params, n)) for n in f.free} | {"ok": np.asarray(res.converged)}

    mc = run_monte_carlo(batch, MonteCarloOptions(n_trials=n_mc, chunk_size=min(n_mc, 100), seed=seed + 1000,
                                                  batched=True, progress=False, name=name))
    st = mc.stats(truth=s.truth.as_dict(), crlb=bound.std, keys=list(f.free))
    for n in f.free:
        p = st["params"][n]
        cmp[n]["mc_rms"] = p.get("rms")
        cmp[n]["mc_bias"] = p.get("bias")
        pc = p.get("percentiles", {})
        cmp[n]["mc_half_68"] = 0.5 * (pc["84"] - pc["16"]) if pc else None  # robust sd of the fits
        cmp[n]["post_over_mc"] = cmp[n]["post_std"] / p["rms"] if p.get("rms") else None
        cmp[n]["crlb_over_mc"] = cmp[n]["crlb"] / p["rms"] if p.get("rms") else None
    if corner_dir is not None:
        corner_plot(post, corner_dir / f"posterior_study_{name}.png", truths=s.truth.as_dict(), laplace=f, title=name)
    print(f"\n== {name}: {s.z.size} px, fit {'ok' if bool(f.converged) else 'FAILED'}, "
          f"{post.n_steps} steps, max tau {np.max(post.tau):.1f}, {'converged' if post.converged else 'NOT converged'}, "
          f"{post.wall_s:.1f} s; MC {st['n_ok']}/{n_mc}")
    print(comparison_table(cmp))
    print("   MC RMS: " + ", ".join(f"{n} {cmp[n]['mc_rms']:.4g}" for n in f.free))
    return {
        "case": name, **{k: (list(v) if isinstance(v, tuple) else v) for k, v in c.items()},
        "radius": radius, "sigma": sigma, "n_pixels": int(s.z.size), "fit_converged": bool(f.converged),
        "posterior": post.summary(), "comparison": cmp, "mc": {"n": n_mc, "n_ok": st["n_ok"]},
    }


def main(out: Path, quick: bool = False, corner_dir: Path | None = None, seed: int = 0) -> dict:
    radius = 40.0 if quick else 60.0
    n_mc = 100 if quick else 500
    max_time = 60.0 if quick else 300.0
    t0 = time.perf_counter()
    # vectorize speed-up on the well-posed 6-parameter problem
    s = synthetic_circle(radius=radius, sigma=10.0, annulus=4.0, seed=seed)
    f = fit(CIRCLE, s.coords, s.z, s.truth.replace(r0=s.truth.r0 + 0.2))
    lp = log_posterior(CIRCLE, s.coords, s.z, f.params, noise="marginal")
    speed = vectorize_speedup(lp, f, n_steps=100 if quick else 300)
    print(f"vectorize speed-up: {speed}")
    cases = [run_case(n, radius, 10.0, n_mc, seed, max_time, corner_dir) for n in CASES]
    result = {
        "benchmark": "posterior_study", "seed": seed, "quick": quick, "git_sha": _git_sha(), "jax": jax.__version__,
        "devices": [str(d) for d in jax.devices()], "vectorize_speedup": speed, "cases": cases,
        "wall_s": time.perf_counter() - t0,
    }
    write_json_atomic(out, json.loads(json.dumps(result, default=float)))
    print(f"\nwrote {out} in {result['wall_s']:.0f} s")
    return result


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "posterior_study.json")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--corner", type=Path, default=None, help="directory for one corner plot per case")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    main(a.out, a.quick, a.corner, a.seed)
