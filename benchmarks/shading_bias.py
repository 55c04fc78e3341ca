"""The traced limb's shading bias on ``benchmarks/families.py`` Earth frames, with and without the shading model.

Usage::

    .venv/bin/python benchmarks/shading_bias.py [--families lambert,own,clouds] [--n 6] [--seed 2026] [--cache DIR]
                                                [--L 0] [--out NAME]

For each frame the limb is traced about its *true* ellipse (:func:`jaxlimb.pipeline.ellipsoid.trace.trace_limb`, the
Sun's side, 80 deg each way, +-6 px), and the known-shape ellipse is fitted through the crossings as traced
(``plain``) and after :func:`~jaxlimb.pipeline.ellipsoid.trace.shading_offsets` with the PSF sigma of
:func:`~jaxlimb.pipeline.ellipsoid.trace.shading_sigma` and lunar-Lambert ``--L`` (``corrected``).  Reported: the centre
error along and across the Sun's image direction (px) and the chosen sigma.  ``--L-grid`` also reports the ``L``
(0, 0.25, ..., 1) whose model best matches the rays.  Writes ``benchmarks/results/<out>.json`` (default
``shading_bias``).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from jaxlimb.pipeline.ellipsoid import shading, trace as lt
from jaxlimb.pipeline.ellipsoid.trace_fit import fit_traced

sys.path.insert(0, str(Path(__file__).resolve().parent))


def _best_L(img, tr, ell, cam, sun) -> float:
    """The ``L`` (0-1 by 0.25) of the best-matching shading model, sigma chosen for each."""

    ok = tr.ok
    v, rad, _ = lt._sample_rays(img, ell, tr.angles[ok], 6.0, 0.5)
    r_obs = np.linalg.norm(tr.points[ok] - np.asarray(ell[0], float)[None, :], axis=1)
    y, rel = (v - tr.sky) / (tr.inside[ok] - tr.sky)[:, None], rad - r_obs[:, None]
    xs = np.arange(-10.0, 10.25, 0.25)
    normals = shading.limb_normals(cam, ell, tr.angles[ok])
    costs = {(L, sg): lt._shape_misfit(y, rel, lt._scaled_rows(tr, ok, ell, normals, sun, sg, L, xs), xs, tr.noise)
             for L in (0.0, 0.25, 0.5, 0.75, 1.0) for sg in lt.SHADE_SIGMAS}
    return float(min(costs, key=costs.get)[0])


def measure(case, L: float, grid: bool) -> dict:
    """Plain and shading-corrected centre errors of one frame traced about its true ellipse."""
    from jaxlimb.imaging.prior import sun_direction_image
    from jaxlimb.pipeline.ellipsoid.trace import shading_corrected, shading_offsets, shading_sigma, trace_limb

    t, cam, sun = case.truth, case.camera, case.hints["sun_dir_camera"]
    ell = (tuple(t.ellipse_center_rc), tuple(t.semi_axes_px), t.angle_rad)
    sd = np.asarray(sun_direction_image(sun, cam, ell[0]), float)
    img = np.asarray(case.image, float)
    tr = trace_limb(img, ell, tuple(sd), math.radians(80.0), 6.0)

    def along_across(e) -> list[float]:
        d = np.subtract(e[0], ell[0])
        return [float(d @ sd), float(d @ np.array([-sd[1], sd[0]]))]

    sig = shading_sigma(img, tr, ell, cam, sun, L)
    fixed = fit_traced(shading_corrected(tr, shading_offsets(tr, ell, cam, sun, sig, L)), ell)
    rec = {"rays": int(tr.ok.sum()), "plain": along_across(fit_traced(tr, ell)), "corrected": along_across(fixed),
           "sigma_px": sig, "meta": case.meta}
    if grid:
        rec["best_L"] = _best_L(img, tr, ell, cam, sun)
    return rec


def main(argv=None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    from _common import environment, save
    from families import family_case

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--families", default="lambert,own,clouds")
    ap.add_argument("--n", type=int, default=6)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--cache", type=Path, default=None)
    ap.add_argument("--L", type=float, default=0.0)
    ap.add_argument("--L-grid", action="store_true", help="also report the best-matching L")
    ap.add_argument("--out", default="shading_bias")
    a = ap.parse_args(argv)
    rows = []
    for fam in a.families.split(","):
        for i in range(a.n):
            r = {"family": fam, "frame": i, **measure(family_case("earth", fam, i, a.seed, a.cache), a.L, a.L_grid)}
            rows.append(r)
            print(f"{fam:8s} {i}: rays {r['rays']:4d}  plain along/across {r['plain'][0]:+.3f} / {r['plain'][1]:+.3f}  "
                  f"corrected {r['corrected'][0]:+.3f} / {r['corrected'][1]:+.3f}  sigma {r['sigma_px']:.1f}"
                  + (f"  best L {r['best_L']:.2f}" if "best_L" in r else ""))
    args = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(a).items()}
    print("saved", save(a.out, {"args": args, "environment": environment(), "rows": rows}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
