"""Fig. 18 of the Aerospace 2015 Moon paper: Moon-distance error vs radius error (Eq. 38).

Lines: Eq. 38, ``sigma_D = (D^2 - R^2)^{3/2} / (f_px D R) sigma_r``, for D = 50 000, 150 000,
250 000 and 350 000 km (:func:`jaxlimb.analysis.error_propagation.figure18_data`; the paper's
"35 000" is read as 350 000 km, see that module).  Open markers: Monte Carlo of the exact
inversion of Eq. 36 with Gaussian radius errors (:func:`monte_carlo_range_sigma`).  Filled
markers: a whole measurement chain -- a full Moon drawn with the circular sigmoid (k = 3),
sigma = 10 grey levels of noise, fitted with (r0, c0, radius) free by
:func:`jaxlimb.fitting.fit_batch` inside the Monte-Carlo engine
(:func:`jaxlimb.analysis.montecarlo.run_monte_carlo`), the fitted radius inverted to a range
-- placed at (RMS radius error, RMS range error).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import _common

STEM = "fig18_range_sigma"


def _csf_chain(D: float, n: int, seed: int) -> dict[str, float]:
    """Monte Carlo of CSF fits of a full Moon at range D; returns RMS radius and range errors."""
    import jax.numpy as jnp

    from jaxlimb.analysis.crlb import crlb
    from jaxlimb.analysis.error_propagation import radius_px, range_from_radius
    from jaxlimb.analysis.montecarlo import MonteCarloOptions, run_monte_carlo
    from jaxlimb.analysis.posterior import synthetic_circle
    from jaxlimb.fitting import fit_batch
    from jaxlimb.models import CIRCLE

    r = float(radius_px(D))
    s = synthetic_circle(radius=r, k=3.0, ymax=200.0, ymin=20.0, sigma=10.0, annulus=4.0, seed=0)
    clean = np.asarray(CIRCLE.intensity(s.truth, jnp.asarray(s.coords)))
    fixed = ("k", "ymax", "ymin")
    v0 = np.asarray(s.truth.to_vector())

    def batch(seeds: np.ndarray, idx: np.ndarray) -> dict[str, np.ndarray]:
        z = np.stack([clean + 10.0 * np.random.default_rng(int(sd)).standard_normal(clean.size) for sd in seeds])
        init = CIRCLE.params_type.from_vector(jnp.asarray(np.repeat(v0[None], len(seeds), 0)))
        res = fit_batch(CIRCLE, np.broadcast_to(s.coords, (len(seeds), *s.coords.shape)), z, init, fixed=fixed)
        rad = np.asarray(res.params.radius)
        return {"radius": rad, "range": range_from_radius(rad), "n_steps": np.asarray(res.n_steps),
                "ok": np.asarray(res.converged)}

    mc = run_monte_carlo(batch, MonteCarloOptions(n_trials=n, chunk_size=min(n, 100), seed=seed, batched=True,
                                                  progress=False, name=f"fig18 D={D:.0f}"))
    st = mc.stats(truth={"radius": r, "range": D}, keys=["radius", "range"])
    bound = crlb(CIRCLE, s.coords, s.truth, 10.0, fixed=fixed)
    return {"D_km": D, "radius_px": r, "rms_radius_px": st["params"]["radius"]["rms"],
            "rms_range_km": st["params"]["range"]["rms"], "crlb_radius_px": bound.std["radius"],
            "n_ok": st["n_ok"], "n": n, "n_pixels": int(s.z.size)}


def main(out_dir: Path | str = _common.DEFAULT_OUT, quick: bool = False) -> list[Path]:
    """Plot Fig. 18 with Monte-Carlo points and write its caption."""
    plt = _common.setup()
    from jaxlimb.analysis.error_propagation import FIG18_DISTANCES_KM, figure18_data, monte_carlo_range_sigma

    out_dir = Path(out_dir)
    f18 = figure18_data(np.geomspace(1e-3, 1.0, 31))
    fig, ax = plt.subplots()
    mc_pts, chain = [], []
    n_chain = 16 if quick else 400
    for i, D in enumerate(f18.distances_km):
        ax.plot(f18.sigma_r_px, f18.sigma_D_km[i], color=f"C{i}", label=f"D = {D:,.0f} km (r = {f18.radius_px[i]:.0f} px)")
        for sr in (0.25, 0.5, 1.0):
            m = monte_carlo_range_sigma(float(D), sr, n_trials=2000 if quick else 20_000, seed=i)
            mc_pts.append({"D_km": float(D), "sigma_r_px": sr, "std_km": m.std_km, "bias_km": m.bias_km,
                           "eq38_km": m.linear_sigma_km})
            ax.plot(sr, m.std_km, "o", mfc="none", color=f"C{i}")
        if quick and i % 2 == 0:  # quick: the chain at 150 000 and 350 000 km only
            continue
        c = _csf_chain(float(D), n_chain, seed=100 + i)
        chain.append(c)
        ax.plot(c["rms_radius_px"], c["rms_range_km"], "s", color=f"C{i}")
    ax.plot([], [], "ko", mfc="none", label="MC, exact Eq. 36 inversion")
    ax.plot([], [], "ks", label=r"MC, CSF fit ($\sigma$ = 10 DN) $\to$ range")
    ax.set(xlabel=r"$\sigma_r$ (px)", ylabel=r"$\sigma_D$ (km)", title="Fig. 18 (2015): Moon distance error, Eq. 38",
           xscale="log", yscale="log", xlim=(8e-4, 1.3))
    ax.legend(loc="lower right")
    paths = [_common.save(fig, out_dir, STEM)]
    s1 = {f"{D:.0f}": float(f18.sigma_D_km[i, -1]) for i, D in enumerate(f18.distances_km)}
    worst = max(abs(p["std_km"] / p["eq38_km"] - 1) for p in mc_pts)
    chain_txt = "; ".join(
        f"D = {c['D_km']:,.0f} km: RMS radius {c['rms_radius_px']:.4f} px (CRLB {c['crlb_radius_px']:.4f}), "
        f"RMS range {c['rms_range_km']:.2f} km ({c['n_ok']}/{c['n']} fits)" for c in chain)
    body = (
        "Eq. 38 of the Aerospace 2015 paper for D = " + ", ".join(f"{D:,.0f}" for D in FIG18_DISTANCES_KM) +
        " km on the papers' 16 mm / 2.2 um camera (the paper prints no values; its text lists \"35 000\" km, read as "
        "350 000). At sigma_r = 1 px: " + ", ".join(f"{k} km -> {v:,.1f} km" for k, v in s1.items()) + ". "
        f"Open circles: Monte Carlo of the exact inversion of Eq. 36 ({mc_pts[0]['sigma_r_px']}-1 px); largest "
        f"departure from Eq. 38 {100 * worst:.1f} % (the first-order formula underestimates when sigma_r/r is not small). "
        f"Squares: CSF fits of a full Moon with sigma = 10 DN, k = 3 (annulus +-4 px), {n_chain} trials per distance: "
        + chain_txt + "."
    )
    paths.append(_common.write_caption(out_dir, STEM, "Fig. 18 (2015): range error vs radius error", body, quick, {
        "sigma_r_px": f18.sigma_r_px.tolist(), "distances_km": f18.distances_km.tolist(),
        "sigma_D_km": f18.sigma_D_km.tolist(), "mc_exact_inversion": mc_pts, "csf_chain": chain,
    }))
    return paths


if __name__ == "__main__":
    _common.cli(main, STEM)
