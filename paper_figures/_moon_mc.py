"""Shared body of Figs. 19 and 20 of the Aerospace 2015 Moon paper (image-processing Monte Carlo).

The paper adds zero-mean Gaussian noise (sigma = 10 grey levels) to one real image 1000
times, runs its whole chain (gradient, box filter, RANSAC, Taubin, CSF least squares with
k estimated) on each and shows the histograms of the radius and centre errors, the centre
scatter and the iteration counts.  Our analogue renders one Moon frame without noise
(:func:`jaxlimb.render.render_body`, 8 bit, Lommel-Seeliger, 1 px PSF), then each trial adds
N(0, 10^2) and runs :func:`jaxlimb.pipeline.locate` (the same chain) through the Monte-Carlo
engine.  Errors are measured against the result on the noise-free frame (the paper's
"with respect to the original picture"), and the bias of that result against the exact
render truth is reported beside them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import _common
import numpy as np


def run(stem: str, title: str, phase_deg: float, paper_text: str, out_dir: Path, quick: bool) -> list[Path]:
    plt = _common.setup()
    from jaxlimb.analysis.montecarlo import MonteCarloOptions, run_monte_carlo
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.pipeline import locate
    from jaxlimb.render import RenderOptions, moon_scene, render_body

    out_dir = Path(out_dir)
    cam = Camera(rows=480, cols=640)
    r_app = 150.0
    range_km = 1737.4 * np.sqrt(1.0 + (cam.focal_px / r_app) ** 2)
    scene = moon_scene(range_km, phase_deg, center_rc=(240.4, 330.2), camera=cam, sun_angle_deg=30.0)
    img, truth = render_body(scene, cam, RenderOptions(bit_depth=8, noise=False, n_subsamples=16 if quick else 64), seed=0)
    base = img.astype(float)
    hints = {"body": "moon"}
    ref = locate(base, cam, hints)
    sigma = 10.0

    def trial(seed: int, i: int) -> dict[str, Any]:
        noisy = base + sigma * np.random.default_rng(seed).standard_normal(base.shape)
        m = locate(noisy, cam, hints)
        return {"row": m.center_rc[0] - ref.center_rc[0], "col": m.center_rc[1] - ref.center_rc[1],
                "radius": m.radius_px - ref.radius_px, "iterations": m.iterations, "k": m.k}

    n = 6 if quick else 1000
    mc = run_monte_carlo(trial, MonteCarloOptions(n_trials=n, chunk_size=min(n, 100), seed=19 if "19" in stem else 20,
                                                  progress=not quick, name=stem))
    st = mc.stats(keys=["row", "col", "radius"])
    ok = mc.ok
    e = {k: mc.values[k][ok] for k in ("row", "col", "radius")}
    it = mc.values["iterations"][ok]
    fig, axes = plt.subplots(2, 3, figsize=(8.0, 4.8))
    for ax, k in zip(axes[0], ("radius", "row", "col")):
        ax.hist(e[k], bins=30 if not quick else 5, color="0.55")
        p = st["params"][k]
        ax.set(xlabel=f"{k} error (px)", title=f"RMS {p['rms']:.4f}, bias {p['bias']:+.4f}")
    axes[1, 0].plot(e["col"], e["row"], ".", ms=2)
    axes[1, 0].set(xlabel="col error (px)", ylabel="row error (px)", title="centre error")
    axes[1, 0].set_aspect("equal", adjustable="datalim")
    vals, counts = np.unique(it.astype(int), return_counts=True)
    axes[1, 1].bar(vals, counts, color="0.55")
    axes[1, 1].set(xlabel="least-squares iterations", title=f"mean {it.mean():.1f}")
    axes[1, 2].imshow(base, cmap="gray")
    t = np.linspace(0, 2 * np.pi, 300)
    axes[1, 2].plot(ref.center_rc[1] + ref.radius_px * np.cos(t), ref.center_rc[0] + ref.radius_px * np.sin(t), "r-", lw=0.6)
    axes[1, 2].set(title=f"phase {phase_deg:.0f} deg, r = {r_app:.0f} px", xticks=[], yticks=[])
    fig.suptitle(title)
    fig.tight_layout()
    paths = [_common.save(fig, out_dir, stem)]
    bias_truth = {"row": ref.center_rc[0] - truth.center_rc[0], "col": ref.center_rc[1] - truth.center_rc[1],
                  "radius": ref.radius_px - truth.apparent_radius_px}
    maxabs = max(st["params"][k]["max_abs"] for k in ("row", "col", "radius"))
    corr = float(np.corrcoef(e["row"], e["col"])[0, 1]) if e["row"].size > 2 else float("nan")
    body = (
        f"Paper: {paper_text}\n\n"
        f"Ours: rendered Moon (480x640 crop of the 16 mm / 2.2 um camera, range {range_km:.0f} km, apparent radius "
        f"{r_app:.0f} px, phase {phase_deg:.0f} deg, 8 bit, noise-free), {n} trials of + N(0, {sigma:g}^2) grey "
        f"levels through jaxlimb.pipeline.locate (gradient front end, CSF with k estimated, body-centre "
        f"correction); {st['n_ok']}/{n} succeeded (failures: {st['failures'] or 'none'}). Errors relative to the "
        f"noise-free result: RMS radius {st['params']['radius']['rms']:.4f}, row {st['params']['row']['rms']:.4f}, "
        f"col {st['params']['col']['rms']:.4f} px; largest |error| {maxabs:.4f} px; row-col correlation {corr:+.2f}; "
        f"mean iterations {it.mean():.1f}. Noise-free result minus render truth: radius {bias_truth['radius']:+.4f}, "
        f"row {bias_truth['row']:+.4f}, col {bias_truth['col']:+.4f} px."
    )
    paths.append(_common.write_caption(out_dir, stem, title, body, quick, {
        "stats": st, "iterations_hist": {int(a): int(b) for a, b in zip(vals, counts)},
        "noise_free_minus_truth": bias_truth, "phase_deg": phase_deg, "n_trials": n, "sigma": sigma,
    }))
    return paths
