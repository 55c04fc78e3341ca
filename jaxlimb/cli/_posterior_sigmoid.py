"""``jaxlimb posterior IMAGE --model sigmoid``: the paper's study, the posterior of the circular sigmoid.

Pixels and start: :func:`jaxlimb.pipeline.locate` (circle model, no body-centre correction, ``keep_pixels``) selects
the annulus on the lit side and fits it; or, with ``--center-rc`` and ``--radius``, the pixels within ``--annulus``
px of that circle are used (the quick path for synthetic images or when the front end fails).  The circular sigmoid
is refitted on the raw intensities (:func:`jaxlimb.fitting.fit`), then the posterior is sampled
(:func:`jaxlimb.analysis.posterior.sample_posterior`) and compared with the fit's Laplace covariance and the
Cramér--Rao bound at the estimate (noise = the residual sigma).  With a camera and a body radius (hints), the LOS
and range and their delta-method sigmas are reported too.
"""

from __future__ import annotations

import argparse


def _pixels_from_circle(image, center_rc, radius: float, annulus: float):  # noqa: ANN001, ANN202
    import numpy as np

    from ..errors import LimbInputError

    if not (radius > 0 and annulus > 0):
        raise LimbInputError(f"`--radius` and `--annulus` must be > 0, got {radius!r}, {annulus!r}")
    rows, cols = image.shape
    r0, c0 = center_rc
    lo_r, hi_r = max(0, int(r0 - radius - annulus - 1)), min(rows, int(r0 + radius + annulus + 2))
    lo_c, hi_c = max(0, int(c0 - radius - annulus - 1)), min(cols, int(c0 + radius + annulus + 2))
    if lo_r >= hi_r or lo_c >= hi_c:
        raise LimbInputError(f"the circle {tuple(center_rc)}, radius {radius} does not overlap the {rows}x{cols} image")
    rr, cc = np.mgrid[lo_r:hi_r, lo_c:hi_c]
    d = np.hypot(rr - r0, cc - c0)
    sel = np.abs(d - radius) <= annulus
    rc = np.stack([rr[sel], cc[sel]], -1).astype(float)
    if rc.shape[0] < 20:
        raise LimbInputError(f"only {rc.shape[0]} pixels within {annulus} px of the circle: check --center-rc/--radius")
    win = image[lo_r:hi_r, lo_c:hi_c].astype(float)
    z = win[sel]
    inner = win[np.abs(d - (radius - annulus)) < 0.7]
    outer = win[np.abs(d - (radius + annulus)) < 0.7]
    ymax = float(np.mean(inner)) if inner.size else float(np.percentile(z, 95))
    ymin = float(np.mean(outer)) if outer.size else float(np.percentile(z, 5))
    return rc, z, ymax, ymin


def _pixels(args: argparse.Namespace, image, camera, hints: dict):  # noqa: ANN001, ANN202
    """The pixels and the start of the fit: ``(rc, z, init, source)`` (``--center-rc`` or ``locate``)."""
    import numpy as np

    from ..models import CircleParams

    if args.center_rc is not None:
        rc, z, ymax, ymin = _pixels_from_circle(image, args.center_rc, args.radius, args.annulus)
        return rc, z, CircleParams(args.center_rc[0], args.center_rc[1], args.radius, args.k, ymax, ymin), "center-rc"
    from ..pipeline import LocateOptions, locate

    m = locate(image, camera, hints or {"body": "moon"},
               LocateOptions(model="circle", body_center_correction=False, keep_pixels=True))
    rc = np.asarray(m.selected_pixels_rc, dtype=float)
    z = image[np.rint(rc[:, 0]).astype(int), np.rint(rc[:, 1]).astype(int)].astype(float)
    c = m.extras["circle_fit"]
    return rc, z, CircleParams(c["center_rc"][0], c["center_rc"][1], c["radius_px"], m.k, m.ymax, m.ymin), "locate"


def _los_range(post, f, camera, hints: dict) -> dict | None:  # noqa: ANN001
    """LOS and range with their delta-method sigmas, from the posterior and the Laplace covariance."""
    import numpy as np

    from ..analysis.crlb import los_range_bound
    from ..imaging import Hints

    names = ("r0", "c0", "radius")
    body_radius = Hints.from_dict(hints).radius_km() if camera is not None and hints else None
    if body_radius is None or not set(names) <= set(post.names):
        return None
    idx = [post.names.index(n) for n in names]
    fidx = [f.free.index(n) for n in names]
    mean = post.mean[idx]
    covs = {"posterior": post.covariance[np.ix_(idx, idx)], "laplace": np.asarray(f.covariance)[np.ix_(fidx, fidx)]}
    return {label: los_range_bound(camera, mean[:2], mean[2], cov, body_radius).as_dict() for label, cov in covs.items()}


def run_sigmoid(args: argparse.Namespace, opt, image, camera, hints: dict, fixed: tuple) -> dict:  # noqa: ANN001
    """Fit the circular sigmoid, sample its posterior with ``opt``; returns the ``--json`` object (and the plot's
    error, if any, under ``plot_error``)."""
    import math

    from ..analysis.crlb import crlb
    from ..analysis.posterior import (Priors, compare_uncertainties, corner_plot, log_posterior, priors_from_hints,
                                      sample_posterior)
    from ..fitting import fit
    from ..models import CIRCLE
    from . import show_progress, try_save

    rc, z, init, source = _pixels(args, image, camera, hints)
    f = fit(CIRCLE, rc, z, init, fixed=fixed)
    priors = priors_from_hints(hints, CIRCLE) if hints else Priors()
    lp = log_posterior(CIRCLE, rc, z, f.params, fixed=fixed, noise=args.noise, sigma=args.sigma, priors=priors)
    post = sample_posterior(lp, f, options=opt, progress=show_progress(args))  # quality-checked (exit 3 on pure noise)
    sigma_hat = math.sqrt(float(f.sigma2))
    bound = crlb(CIRCLE, rc, f.params, args.sigma if args.noise == "known" else sigma_hat, fixed=fixed)
    out: dict = {"status": "ok", "model": "circle", "source": source, "n_pixels": int(z.size), "fixed": list(fixed),
                 "noise": args.noise, "sigma_hat": sigma_hat, "fit": {**f.params.as_dict(), "iterations": int(f.n_steps)},
                 "posterior": post.summary(), "comparison": compare_uncertainties(post, f, bound),
                 "priors": {"gaussian": {k: list(v) for k, v in priors.gaussian.items()}}}
    lr = _los_range(post, f, camera, hints)
    if lr is not None:
        out["los_range"] = lr
    if args.plot:  # after the work: a failing writer must not lose the result
        title = f"{args.image}: {z.size} px, {post.n_steps} steps{'' if post.converged else ' (NOT converged)'}"
        err = try_save(lambda: corner_plot(post, args.plot, laplace=f, title=title), "--plot")
        out.update(plot=args.plot if err is None else None, **({"plot_error": err} if err else {}))
    return out


def print_sigmoid(out: dict) -> None:
    """The text output of :func:`run_sigmoid`'s result."""
    from ..analysis.posterior import comparison_table

    s = out["posterior"]
    print(f"{out['n_pixels']} pixels ({out['source']}); circular sigmoid; {s['n_steps']} steps x {s['n_walkers']} "
          f"walkers in {s['wall_s']:.1f} s; max tau {max(s['tau'].values()):.1f}; "
          f"{'converged' if s['converged'] else 'NOT converged'}")
    print(comparison_table(out["comparison"]))
    if "los_range" in out:
        p = out["los_range"]["posterior"]
        print(f"range {p['range_km']:.2f} +- {p['sigma_range_km']:.2f} km, LOS sigma {p['sigma_los_arcsec']:.3f} arcsec")
