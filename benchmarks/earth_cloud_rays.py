"""Per-ray limb estimators on cloudy Earths, measured against the true limb (attitude known).

Usage::

    .venv/bin/python benchmarks/earth_cloud_rays.py [--frames clouds:0,clouds:1,...] [--cache DIR] [--out NAME]

Frames: :mod:`jaxlimb.render.independent` (``benchmarks/families.py``'s Earth frames, same seed and cache keys).
Rays are sampled every pixel of arc across the lit limb (30 deg off each horn) from 8 px inside to 8 px outside
the *true* limb ellipse (0.25 px steps, bilinear), so that every ray's edge error is its estimator's own.  Per ray:

* ``current``: :mod:`jaxlimb.pipeline.ellipsoid.trace`'s edge (50 % between the sky and the median level 2-5 px
  inside the 5-sigma foot; rays with a non-flat inside left out);
* ``step_wN``: a blurred step ``sky + A Phi(-(r - e) / sigma)`` fitted to the samples from ``N`` px inside to
  3 px outside the edge (variable projection over ``e``, ``A`` linear; ``sigma`` the one that minimises the
  summed residual of the ``current`` rays over 0.7-1.45 px), i.e. the 50 % point of the ray's own outermost level;
* ``sqrt_w4``: the same with a blurred ``A1 sqrt(d)`` interior term (Lambert albedo linear in the surface angle
  from the limb, ``delta = sqrt(2 d / R)``).

Each set of edges is turned into a centre with the known-shape ellipse fit of
:func:`jaxlimb.pipeline.ellipsoid.trace_fit.fit_traced` (soft-L1); reported: the ellipse-centre error (px) with the rays
``current`` keeps and with every ray whose step is > 8 noise sigma, and the per-10-deg-sector median edge error
(the albedo bias along the limb).  Results: ``benchmarks/results/<out>.json``.
"""

from __future__ import annotations

import argparse
import functools
import math
import sys
from pathlib import Path

import numpy as np

from jaxlimb.pipeline.ellipsoid.trace_fit import fit_traced

sys.path.insert(0, str(Path(__file__).resolve().parent))

DEFAULT_FRAMES = "clouds:0,clouds:1,clouds:2,combined:0,combined:1,combined:2"


def _rays(img, ell, lit_dir, half, search=8.0, step=0.25):
    """Samples ``(n_rays, n)`` along rays through the true limb, their angles, directions, offsets, true radii."""
    from scipy.ndimage import map_coordinates

    from jaxlimb.pipeline.ellipsoid.trace import _ray_radius

    t0 = math.atan2(lit_dir[0], lit_dir[1])
    ang = t0 + np.linspace(-half, half, max(16, int(2 * half * ell[1][0])))
    u = np.column_stack([np.sin(ang), np.cos(ang)])
    s = np.arange(-search, search + 0.5 * step, step)
    r_true = _ray_radius(ell, u)
    rad = r_true[:, None] + s[None, :]
    c = np.asarray(ell[0], float)
    rr, cc = c[0] + rad * u[:, 0:1], c[1] + rad * u[:, 1:2]
    v = map_coordinates(np.asarray(img, float), [rr.ravel(), cc.ravel()], order=1, mode="nearest").reshape(rr.shape)
    return ang, u, s, v, r_true


@functools.lru_cache(maxsize=16)
def _sqrt_table(sig: float) -> tuple[np.ndarray, np.ndarray]:
    xs, dd = np.linspace(-15, 8, 4601), np.linspace(0, 16, 3201)
    g = np.exp(-0.5 * ((xs[:, None] + dd[None]) / sig) ** 2) / (sig * math.sqrt(2 * math.pi))
    return xs, np.trapezoid(np.sqrt(dd)[None] * g, dd, axis=1)


def _blurred_sqrt(x: np.ndarray, sig: float) -> np.ndarray:
    """``int_0^inf sqrt(d) g(x + d) dd`` for a Gaussian ``g`` of ``sig`` (tabulated)."""
    xs, tab = _sqrt_table(sig)
    return np.interp(x.ravel(), xs, tab).reshape(x.shape)


def _step_edges(v, s, sky, e0, sig, w_in, sqrt_term, w_out=3.0):
    """Per ray: the edge offset ``e`` (grid of 0.02 px about ``e0``) minimising the linear least-squares residual of
    the blurred step (and ``sqrt`` term) over ``[e - w_in, e + w_out]``; returns ``e``, amplitude, residual."""
    from scipy.special import ndtr

    n = v.shape[0]
    best, be, bA = np.full(n, np.inf), np.full(n, np.nan), np.full(n, np.nan)
    for g in np.arange(-1.5, 1.5001, 0.02):
        x = s[None, :] - (e0 + g)[:, None]
        win = (x >= -w_in) & (x <= w_out)
        y = (v - sky) * win
        F = [ndtr(-x / sig) * win] + ([_blurred_sqrt(x, sig) * win] if sqrt_term else [])
        F = np.stack(F, -1)
        G = np.einsum("nmk,nml->nkl", F, F) + 1e-9 * np.eye(F.shape[-1])
        A = np.linalg.solve(G, np.einsum("nmk,nm->nk", F, y)[..., None])[..., 0]
        rss = ((y - np.einsum("nmk,nk->nm", F, A)) ** 2).sum(1)
        bt = rss < best
        best[bt], be[bt], bA[bt] = rss[bt], (e0 + g)[bt], A[bt, 0]
    return be, bA, best


def _center_error(ell, u, r_true, e, ok) -> float:
    """Ellipse-centre error (px) of the known-shape fit to the points ``r_true + e`` of the rays ``ok``."""
    from jaxlimb.pipeline.ellipsoid.trace import TracedLimb

    c = np.asarray(ell[0], float)
    pts = c[None] + (r_true + np.nan_to_num(e))[:, None] * u
    tr = TracedLimb((float(c[0]), float(c[1])), np.zeros(len(u)), pts, np.where(ok, 1.0, np.nan), 0.0, 1.0)
    fitted = fit_traced(tr, ell)
    return float(math.dist(fitted[0], ell[0]))


def measure(case) -> dict:
    """Every estimator of the module docstring on one frame."""
    from jaxlimb.imaging import sun_direction_image
    from jaxlimb.pipeline.ellipsoid.trace import _ray_edges, _sky

    t = case.truth
    ell = (tuple(t.ellipse_center_rc), tuple(t.semi_axes_px), float(t.angle_rad))
    sd = sun_direction_image(np.array(case.hints["sun_dir_camera"]), case.camera, ell[0])
    ang, u, s, v, r_true = _rays(case.image, ell, sd, math.pi / 2 - math.radians(30))
    sky, noise = _sky(v)
    r_e, _ = _ray_edges(v, r_true[:, None] + s[None, :], sky, noise, s[1] - s[0], 0.35)
    kept, e_cur = np.isfinite(r_e), np.nan_to_num(r_e - r_true)
    sector = np.floor(np.degrees(ang - ang.min()) / 10.0).astype(int)
    out = {"R_px": float(t.semi_axes_px[0]), "psf": case.meta["psf"], "n_rays": int(len(ang)), "n_kept": int(kept.sum()),
           "current": {"center_err_px": _center_error(ell, u, r_true, e_cur, kept),
                       "sector_median_px": [float(np.median(e_cur[kept & (sector == k)])) if (kept & (sector == k)).any()
                                            else None for k in range(sector.max() + 1)]}}
    for name, w_in, sq in (("step_w1", 1.0, False), ("step_w3", 3.0, False), ("sqrt_w4", 4.0, True)):
        rss = {sig: _step_edges(v[kept], s, sky, e_cur[kept], sig, w_in, sq)[2].sum() for sig in (0.7, 0.85, 1.0, 1.15, 1.3, 1.45)}
        sig = min(rss, key=rss.get)
        e, A, _ = _step_edges(v, s, sky, e_cur, sig, w_in, sq)
        good = np.isfinite(e) & (A > 8 * noise)
        out[name] = {"sigma": sig, "center_err_kept_px": _center_error(ell, u, r_true, e, good & kept),
                     "center_err_all_px": _center_error(ell, u, r_true, e, good), "n_all": int(good.sum())}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", default=DEFAULT_FRAMES, help="family:index, comma-separated")
    ap.add_argument("--cache", type=Path, default=None)
    ap.add_argument("--out", default="earth_cloud_rays")
    a = ap.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    from _common import environment, save
    from families import family_case

    res = {}
    for fr in a.frames.split(","):
        fam, i = fr.split(":")
        r = res[fr] = measure(family_case("earth", fam, int(i), 2026, a.cache))
        print(f"{fr:11s} R {r['R_px']:5.0f} rays {r['n_rays']:4d} kept {r['n_kept']:4d}  current {r['current']['center_err_px']:.3f}  "
              + "  ".join(f"{k} {r[k]['center_err_kept_px']:.3f}/{r[k]['center_err_all_px']:.3f}" for k in ("step_w1", "step_w3", "sqrt_w4")),
              flush=True)
    print(f"saved {save(a.out, {'frames': res, 'environment': environment()})}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
