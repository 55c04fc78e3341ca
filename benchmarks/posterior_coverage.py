"""Coverage of the posterior of what ``locate`` measured, on renders of a family its model does not assume.

Usage::

    .venv/bin/python benchmarks/posterior_coverage.py [--families hapke] [--n 100] [--seed 7] [--out-dir DIR]
                                                      [--walkers 16] [--plot FILE.png] [--shard P/N]

    # on N cores: N processes, each a shard of the chunks, into one --out-dir; then once more without --shard to
    # gather them (every chunk is on disk: nothing is recomputed) and write the summary
    for p in 0 1; do .venv/bin/python benchmarks/posterior_coverage.py --out-dir DIR --shard $p/2 & done; wait
    .venv/bin/python benchmarks/posterior_coverage.py --out-dir DIR

Each trial renders a Moon of the family with the independent renderer (:mod:`jaxlimb.render.independent`, drawn
from the trial's seed: range 60 000-384 400 km, phase 0-150 deg, 8 or 12 bits), runs ``locate`` with the hints a
filter has, samples the posterior of its final fit (:func:`jaxlimb.analysis.posterior.measured_posterior`, the
physical profile and its nuisance parameters, noise marginalised; emcee with the Laplace independence moves, 16
walkers, converged when longer than 50 autocorrelation times with ``tau`` stable to 10 % between checks 50 steps
apart: ``tau`` ~ 3 steps is estimated to a few % only, and 1 % ran chains of 850 steps for nothing) and
records where the truth falls: the credible level of the true body centre (2-D) and apparent radius in the
posterior, in the model-error-adjusted posterior (Shaby's open-faced sandwich to ``locate``'s covariance) and in
``locate``'s Gaussian.  Coverage of the 68.27 % / 95.45 % regions = the fraction of levels below them (calibrated:
68 +- 7 % / 95 +- 4 % over >= 100 renders: two binomial standard errors).  Trials run through the Monte-Carlo engine into
``--out-dir`` (resumable); the summary goes to ``benchmarks/results/posterior_coverage.json`` (``wall_s`` is that
process's own: a gathering run's ``chunks_resumed`` counts what the shards computed).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

LEVELS = {"68": 0.6827, "95": 0.9545}
KEYS = ("center", "center_adjusted", "center_locate", "radius", "radius_adjusted")


@dataclass(frozen=True)
class CoverageTrial:
    """One render of ``families[i % len]`` through ``locate`` and the posterior of its fit."""

    families: tuple[str, ...]
    walkers: int = 16
    max_time_s: float = 300.0

    def __call__(self, seed: int, i: int) -> dict[str, float]:
        from jaxlimb._jaxcache import start_jax

        start_jax()
        from jaxlimb.analysis.located import located_fit
        from jaxlimb.analysis.posterior import PosteriorOptions, measured_posterior, truth_levels
        from jaxlimb.render.independent import moon_case

        case = moon_case(self.families[i % len(self.families)], np.random.default_rng(seed))
        lf = located_fit(case.image, case.camera, case.hints)
        opt = PosteriorOptions(n_walkers=self.walkers, moves="laplace", chunk=50, tau_rtol=0.1, seed=seed % 2**31,
                               max_time_s=self.max_time_s)
        mp = measured_posterior(lf, opt)
        lv = truth_levels(mp, case.truth.body_center_rc, case.truth.apparent_radius_px)
        cmp = mp.compare()
        return {**lv, "family": float(i % len(self.families)), "tau_max": float(np.max(mp.posterior.tau)),
                "n_steps": float(mp.posterior.n_steps), "converged": float(mp.posterior.converged),
                "post_over_locate_r": cmp["center_r"]["post_over_locate"],
                "adjusted_over_locate_r": cmp["center_r"]["adjusted_over_locate"],
                "n_pixels": float(lf.data.coords.shape[0]), "model": float(len(lf.free))}


def coverage(res, keys=KEYS) -> dict:  # noqa: ANN001
    """Coverage of the 68 % / 95 % regions per key over the finished trials (module docstring)."""
    out = {}
    for k in keys:
        v = res.values.get(k, np.full(res.n, np.nan))[res.ok]
        v = v[np.isfinite(v)]
        if v.size:
            out[k] = {"n": int(v.size), **{q: float(np.mean(v <= lev)) for q, lev in LEVELS.items()}}
    return out


def plot(res, summary: dict, path: Path) -> None:  # noqa: ANN001
    """Sorted credible levels of the truth (a calibrated posterior: the diagonal) for each region."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxlimb.analysis.figures import save_figure

    fig, ax = plt.subplots(figsize=(4.4, 4.0))
    for k, label in (("center", "posterior"), ("center_adjusted", "adjusted (model error)"), ("center_locate", "locate")):
        v = np.sort(res.values[k][res.ok & np.isfinite(res.values[k])])
        ax.plot(v, np.arange(1, v.size + 1) / v.size, label=f"{label}: {100 * summary[k]['68']:.0f} / "
                f"{100 * summary[k]['95']:.0f} %")
    ax.plot([0, 1], [0, 1], "k--", lw=0.8)
    for lev in LEVELS.values():
        ax.axvline(lev, color="0.7", lw=0.6)
    ax.set(xlabel="credible level of the true centre", ylabel="fraction of renders", xlim=(0, 1), ylim=(0, 1))
    ax.legend(fontsize=7, title="inside 68 / 95 %", title_fontsize=7)
    save_figure(fig, path)


def _median_ok(res, key: str) -> float | None:  # noqa: ANN001
    """The median of ``key`` over the trials that succeeded (``None`` when none did)."""
    v = res.values.get(key)
    return None if v is None or not res.ok.any() else float(np.nanmedian(v[res.ok]))


def main(argv: list[str] | None = None) -> dict:
    from _common import environment, save

    from jaxlimb.analysis.montecarlo import MonteCarloOptions, run_monte_carlo

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", default="hapke")
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--walkers", type=int, default=16)
    ap.add_argument("--out-dir", type=Path, default=Path("/tmp/posterior_coverage"))
    ap.add_argument("--plot", type=Path, default=None)
    ap.add_argument("--name", default="posterior_coverage")
    ap.add_argument("--shard", default="0/1", help="P/N: run only chunk c with c %% N == P (module docstring)")
    args = ap.parse_args(argv)
    shard = tuple(int(v) for v in args.shard.split("/"))
    fams = tuple(f.strip() for f in args.families.split(","))
    t0 = time.perf_counter()
    opt = MonteCarloOptions(n_trials=args.n, chunk_size=5, seed=args.seed, out_dir=str(args.out_dir),
                            name=f"coverage-{'-'.join(fams)}-w{args.walkers}", shard=shard)
    res = run_monte_carlo(CoverageTrial(fams, args.walkers), opt)
    if shard[1] > 1:
        print(f"shard {args.shard}: {res.n} trials in {args.out_dir}; gather them with a run without --shard")
        return {"shard": args.shard, "n": res.n}
    summary = coverage(res)
    fails = res.failure_counts()
    out = {"families": list(fams), "n": res.n, "n_ok": int(res.ok.sum()), "failures": fails, "coverage": summary,
           "median_tau_max": _median_ok(res, "tau_max"),
           "median_post_over_locate_r": _median_ok(res, "post_over_locate_r"),
           "converged": int(np.nansum(res.values.get("converged", np.zeros(res.n))[res.ok])), "seed": args.seed,
           "walkers": args.walkers,
           "wall_s": time.perf_counter() - t0, "chunks_run": res.chunks_run, "chunks_resumed": res.chunks_skipped,
           "environment": environment(),
           "command": "python benchmarks/posterior_coverage.py " + " ".join(argv if argv is not None else sys.argv[1:])}
    save(args.name, out)
    if args.plot is not None:
        plot(res, summary, args.plot)
    for k, v in summary.items():
        print(f"{k:>16}: {v['n']} renders, inside 68 %: {100 * v['68']:.1f} %, inside 95 %: {100 * v['95']:.1f} %")
    print(f"failures {fails}; median post/locate sd {out['median_post_over_locate_r']}")
    return out


if __name__ == "__main__":
    main()
