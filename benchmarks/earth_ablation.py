"""Which component of an independent Earth scene moves the measurement: the same frame re-rendered with one
component replaced (``jaxlimb.render.independent.earth_case(..., ablate=...)``).

Usage::

    .venv/bin/python benchmarks/earth_ablation.py [--family combined] [--frames 0,1,4]
        [--ablations none,psf_core,psf_round,no_glow,no_jpeg,psf_core+no_glow,reseed_clouds] [--seed 2026]
        [--cache DIR] [--out NAME]

Every frame is the one of ``benchmarks/families.py`` (same seed, family, index: ``none`` is that benchmark's
frame bit for bit); an ablation replaces, after the same random draws, the PSF by its Gaussian core
(``psf_core``) or by a round Gaussian of the same variance (``psf_round``), removes the glow (``no_glow``) or the
JPEG step (``no_jpeg``), draws the clouds with the next seed (``reseed_clouds``) or removes them (``no_clouds``: a
uniform albedo); ``a+b`` combines them.
Reported per frame and ablation, with ``R_body_to_camera`` known: the ``locate`` centre error (px) and its NEES
(``e^T P^-1 e``, chi-square 2 expectation), and two estimators that need no pipeline choice, the known-shape
ellipse through the limb traced about the *true* limb ellipse (:func:`jaxlimb.pipeline.ellipsoid.trace.trace_limb`,
:func:`~jaxlimb.pipeline.ellipsoid.trace_fit.fit_traced`) without and with the glow's lift
(:func:`~jaxlimb.pipeline.ellipsoid.trace_fit.fit_traced_glow`): their ellipse-centre errors (px) show what the traced
limb of that scene can give at best.  Results go to ``benchmarks/results/<out>.json`` (default
``earth_ablation``).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from jaxlimb.pipeline.ellipsoid.trace_fit import fit_traced, fit_traced_glow

sys.path.insert(0, str(Path(__file__).resolve().parent))

DEFAULT_ABLATIONS = "none,psf_core,psf_round,no_glow,no_jpeg,psf_core+no_glow,reseed_clouds"


def render(family: str, idx: int, seed: int, ablate: tuple[str, ...], cache: Path | None):
    """Frame ``idx`` of ``family`` as ``benchmarks/families.py`` draws it (far when ``idx`` is odd), ablated."""
    from _common import cached

    from jaxlimb.render.independent import EARTH_FAMILIES, earth_case

    rng = np.random.default_rng([seed, 1, EARTH_FAMILIES.index(family), idx])
    if not ablate:  # the families benchmark's own frame and cache key
        return cached(cache, f"earth_{family}_{idx}_s{seed}_v1.pkl", lambda: earth_case(family, rng, far=bool(idx % 2)))
    key = f"earth_{family}_{idx}_s{seed}_abl_{'+'.join(sorted(ablate))}.pkl"
    return cached(cache, key, lambda: earth_case(family, rng, far=bool(idx % 2), ablate=ablate))


def truth_traced(case) -> dict[str, Any]:
    """Ellipse-centre errors (px) of the limb traced about the true ellipse on the lit arc less 30 deg per horn:
    the plain known-shape fit and the one with the glow's lift (its z-score too)."""
    from jaxlimb.errors import TooManyOutliersError
    from jaxlimb.imaging import sun_direction_image
    from jaxlimb.pipeline.ellipsoid.trace import trace_limb

    t = case.truth
    ell = (tuple(t.ellipse_center_rc), tuple(t.semi_axes_px), t.angle_rad)
    lit = sun_direction_image(case.hints["sun_dir_camera"], case.camera, tuple(t.ellipse_center_rc))
    try:
        tr = trace_limb(np.asarray(case.image, float), ell, lit, math.radians(60.0), 8.0)
        e0 = fit_traced(tr, ell)
        eg, _, z = fit_traced_glow(tr, ell)
    except TooManyOutliersError as e:
        return {"error": str(e)[:120]}

    def err(e):
        return float(math.dist(e[0], ell[0]))

    return {"n_rays": int(tr.ok.sum()), "plain_px": err(e0), "glow_lift_px": err(eg), "glow_lift_z": z}


def measure(case) -> dict[str, Any]:
    """``locate`` (attitude known) against the truth, and the truth-traced estimators."""
    from jaxlimb.errors import JaxlimbError
    from jaxlimb.imaging import Hints
    from jaxlimb.pipeline import locate

    rec: dict[str, Any] = {"meta": case.meta, "traced": truth_traced(case)}
    try:
        m = locate(case.image, case.camera, Hints.from_dict(case.hints))
    except JaxlimbError as e:
        rec.update(status="error", check=e.check)
        return rec
    e = np.array(m.center_rc) - np.array(case.truth.body_center_rc)
    c = m.covariance
    from jaxlimb.pipeline import covariance_block
    P = covariance_block(c)
    rec.update(status="ok", center_err_px=float(np.hypot(*e)), err_rc=e.tolist(), nees=float(e @ np.linalg.solve(P, e)))
    return rec


def _row(family: str, idx: int, name: str, rec: dict) -> str:
    tr = rec["traced"]
    loc = (f"{rec['center_err_px']:.3f} px NEES {rec['nees']:5.1f}" if rec["status"] == "ok"
           else f"{rec['check']:>24s}")
    trs = (f"{tr['plain_px']:.3f} / {tr['glow_lift_px']:.3f} (z {tr['glow_lift_z']:5.1f}, {tr['n_rays']} rays)"
           if "plain_px" in tr else tr["error"][:40])
    return f"{family:9s} {idx:2d} {name:24s} {loc:>26s}   {trs}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--family", default="combined")
    ap.add_argument("--frames", default="0,1,4")
    ap.add_argument("--ablations", default=DEFAULT_ABLATIONS, help="comma-separated; 'none' or names joined by '+'")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--cache", type=Path, default=None)
    ap.add_argument("--out", default="earth_ablation")
    a = ap.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    from _common import environment, save

    t0, records = time.perf_counter(), []
    print(f"{'family':9s} {'i':>2s} {'ablation':24s} {'locate (attitude known)':>26s}   truth-traced plain / glow lift")
    for idx in (int(v) for v in a.frames.split(",") if v):
        for name in (v for v in a.ablations.split(",") if v):
            abl = () if name == "none" else tuple(name.split("+"))
            rec = {"family": a.family, "frame": idx, "ablation": name,
                   **measure(render(a.family, idx, a.seed, abl, a.cache))}
            records.append(rec)
            print(_row(a.family, idx, name, rec), flush=True)
    out = {"args": vars(a) | {"cache": str(a.cache)}, "environment": environment(),
           "wall_s": time.perf_counter() - t0, "records": records}
    print(f"saved {save(a.out, out)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
