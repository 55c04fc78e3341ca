"""``jaxlimb posterior IMAGE``: emcee posterior of the circular-sigmoid limb fit of one image.

Pixels and start: :func:`jaxlimb.pipeline.locate` (circle model, no body-centre correction,
``keep_pixels``) selects the annulus on the lit side and fits it; or, with ``--center-rc``
and ``--radius``, the pixels within ``--annulus`` px of that circle are used (the quick
path for synthetic images or when the front end fails).  The circular sigmoid is refitted
on the raw intensities (:func:`jaxlimb.fitting.fit`), then the posterior is sampled
(:func:`jaxlimb.analysis.posterior.sample_posterior`) and compared with the fit's Laplace
covariance and the Cramér--Rao bound at the estimate (noise = the residual sigma).  With a
camera and a body radius (hints), the LOS and range and their delta-method sigmas are
reported too.
"""

from __future__ import annotations

import argparse

from .._validate import POSITIVE, Range, arg_number

_PX = Range(0.0, 1e5, lo_open=True)  # a length in pixels (no image is 100 000 px wide)
_COORD = Range(-1e5, 1e5)  # a pixel coordinate (may lie off the frame)
_K = Range(0.0, 1e3, lo_open=True)  # sigmoid steepness, 1/px (analysis.posterior.MAX_K)
_WALKERS = Range(4, 10_000)
_STEPS = Range(1, 10_000_000)
_SECONDS = Range(0.0, 86_400.0, lo_open=True)
_SEED = Range(0, 2**32 - 1)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "posterior",
        help="emcee posterior of the limb fit of an image (vs Laplace covariance and CRLB)",
        description="Locate the limb in IMAGE (or take --center-rc/--radius), fit the circular sigmoid and "
        "sample its posterior with emcee until the chain is longer than 50 autocorrelation times; report "
        "posterior mean and sd beside the Laplace covariance and the Cramér-Rao bound.  Exit 0 on success "
        "(also when the chain did not converge: see \"converged\"), 2 for unusable input, 3 when a check fails.",
    )
    p.add_argument("image", metavar="IMAGE", help="image file (PNG, TIFF, FITS) or a .npy array")
    p.add_argument("--camera", metavar="CAMERA.json", help="camera file (enables LOS and range)")
    p.add_argument("--hints", metavar="HINTS.json", help="hints (docs/design.md); expected_radius_px becomes a radius prior")
    p.add_argument("--center-rc", nargs=2, type=arg_number(_COORD), metavar=("ROW", "COL"),
                   help=f"skip locate: circle centre, px {_COORD} (with --radius)")
    p.add_argument("--radius", type=arg_number(_PX), help=f"skip locate: circle radius, px {_PX} (with --center-rc)")
    p.add_argument("--annulus", type=arg_number(_PX), default=6.0,
                   help=f"half-width of the pixel band for --center-rc, px {_PX} (default 6)")
    p.add_argument("--k", type=arg_number(_K), default=2.0,
                   help=f"start (or fixed) steepness k for --center-rc, 1/px {_K} (default 2)")
    p.add_argument("--fix", default="", help="comma-separated parameters held fixed, e.g. k,ymax,ymin")
    p.add_argument("--noise", choices=("marginal", "known", "free"), default="marginal",
                   help="noise treatment: sigma marginalised (default), known (--sigma), or sampled")
    p.add_argument("--sigma", type=arg_number(POSITIVE), help="noise sd in DN for --noise known (> 0)")
    p.add_argument("--walkers", type=_even_walkers, default=32,
                   help=f"emcee walkers: an even integer {_WALKERS} and at least twice the sampled parameters "
                   "(the circle samples 6 with --noise marginal: 12; fewer with --fix); default 32")
    p.add_argument("--max-steps", type=arg_number(_STEPS, integer=True), default=20000,
                   help=f"stop unconverged after this many steps {_STEPS}")
    p.add_argument("--max-time", type=arg_number(_SECONDS), default=120.0,
                   help=f"stop unconverged after this many seconds {_SECONDS}")
    p.add_argument("--seed", type=arg_number(_SEED, integer=True), default=0, help=f"random seed {_SEED}")
    p.add_argument("--plot", metavar="OUT.png", help="save a corner plot")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def _even_walkers(text: str) -> int:
    """``--walkers``: an even integer in ``_WALKERS`` (argparse reports the failure, exit 2)."""
    n = arg_number(_WALKERS, integer=True)(text)
    if n % 2:
        raise argparse.ArgumentTypeError(f"must be an even integer {_WALKERS}, got {text!r}")
    return n


def _load(path: str):  # noqa: ANN202
    import numpy as np

    from ..errors import ImageReadError
    from ..imaging import load_image

    if path.endswith(".npy"):
        try:
            a = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as e:
            raise ImageReadError(f"cannot read IMAGE {path!r}: {e}") from None
        if not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating) or a.dtype == np.bool_):
            raise ImageReadError(f"IMAGE {path!r} must hold real numbers, got dtype {a.dtype}")
        return np.asarray(a, dtype=float)
    image, _ = load_image(path, reject_constant=False)
    return image


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


def _inputs(args: argparse.Namespace):  # noqa: ANN202
    """Every input checked and read before any work: ``(image, camera, hints dict, fixed names)``."""
    from .._io import read_json_file
    from ..errors import LimbInputError
    from ..geometry.camera import Camera
    from ..imaging import Hints
    from ..models import CIRCLE
    from . import figure_path

    figure_path(args.plot, "--plot")
    if (args.center_rc is None) != (args.radius is None):
        raise LimbInputError("`--center-rc` and `--radius` go together (both or neither)")
    if args.noise == "known" and args.sigma is None:
        raise LimbInputError("`--noise known` needs `--sigma`")
    fixed = tuple(s.strip() for s in args.fix.split(",") if s.strip())
    unknown = sorted(set(fixed) - set(CIRCLE.param_names))
    if unknown:
        raise LimbInputError(f"`--fix` names unknown parameters {unknown}; the circle model has {list(CIRCLE.param_names)}")
    image = _load(args.image)
    if image.ndim != 2:
        raise LimbInputError(f"IMAGE must be a 2-D grey image, got shape {image.shape}")
    camera = Camera.from_json(args.camera) if args.camera is not None else None
    hints: dict = {}
    if args.hints is not None:
        hints = read_json_file(args.hints, "hints file")
        Hints.from_dict(hints)  # every value checked (types, ranges) before any work
    return image, camera, hints, fixed


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


def run(args: argparse.Namespace) -> int:
    import math

    from ..analysis.crlb import crlb
    from ..analysis.posterior import (
        PosteriorOptions,
        Priors,
        compare_uncertainties,
        comparison_table,
        corner_plot,
        log_posterior,
        priors_from_hints,
        sample_posterior,
    )
    from ..fitting import fit
    from ..models import CIRCLE
    from . import emit_json, report_after_result, try_save

    image, camera, hints, fixed = _inputs(args)
    rc, z, init, source = _pixels(args, image, camera, hints)
    f = fit(CIRCLE, rc, z, init, fixed=fixed)
    priors = priors_from_hints(hints, CIRCLE) if hints else Priors()
    lp = log_posterior(CIRCLE, rc, z, f.params, fixed=fixed, noise=args.noise, sigma=args.sigma, priors=priors)
    opt = PosteriorOptions(n_walkers=args.walkers, max_steps=args.max_steps, max_time_s=args.max_time, seed=args.seed)
    post = sample_posterior(lp, f, options=opt, progress=not args.json)  # quality-checked (exit 3 on pure noise)
    sigma_hat = math.sqrt(float(f.sigma2))
    bound = crlb(CIRCLE, rc, f.params, args.sigma if args.noise == "known" else sigma_hat, fixed=fixed)
    cmp = compare_uncertainties(post, f, bound)
    out: dict = {
        "status": "ok",
        "source": source,
        "n_pixels": int(z.size),
        "fixed": list(fixed),
        "noise": args.noise,
        "sigma_hat": sigma_hat,
        "fit": {**f.params.as_dict(), "iterations": int(f.n_steps)},
        "posterior": post.summary(),
        "comparison": cmp,
        "priors": {"gaussian": {k: list(v) for k, v in priors.gaussian.items()}},
    }
    lr = _los_range(post, f, camera, hints)
    if lr is not None:
        out["los_range"] = lr
    plot_error = None
    if args.plot:  # after the work: a failing writer must not lose the result
        plot_error = try_save(lambda: corner_plot(post, args.plot, laplace=f, title=f"{args.image}: {z.size} px, "
                                                  f"{post.n_steps} steps{'' if post.converged else ' (NOT converged)'}"),
                              "--plot")
        out["plot"] = args.plot if plot_error is None else None
        if plot_error:
            out["plot_error"] = plot_error
    if args.json:
        emit_json(out)
    else:
        s = post.summary()
        print(f"{z.size} pixels ({source}); {s['n_steps']} steps x {s['n_walkers']} walkers in {s['wall_s']:.1f} s; "
              f"max tau {max(s['tau'].values()):.1f}; {'converged' if post.converged else 'NOT converged'}")
        print(comparison_table(cmp))
        if lr is not None:
            p = lr["posterior"]
            print(f"range {p['range_km']:.2f} +- {p['sigma_range_km']:.2f} km, LOS sigma {p['sigma_los_arcsec']:.3f} arcsec")
    return report_after_result(plot_error)
