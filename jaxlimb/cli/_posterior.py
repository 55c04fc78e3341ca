"""``jaxlimb posterior IMAGE``: the posterior of what ``locate`` measured in one image.

By default the fit ``locate`` ran (its model and nuisance parameters: the physical lunar-Lambert profile when the
hints give the Sun direction, with its widenings; the sigmoid otherwise; ``--profile`` another) is sampled with emcee
and the samples are mapped to the body centre, radius and range through ``locate``'s own mapping
(:func:`jaxlimb.analysis.posterior.measured_posterior`), beside ``locate``'s covariance, the Cramér--Rao bound and the
posterior adjusted for the model error ``locate``'s covariance carries.  ``--model sigmoid`` (or ``--center-rc`` with
``--radius``): the paper's study, the circular sigmoid (:mod:`jaxlimb.cli._posterior_sigmoid`).
"""

from __future__ import annotations

import argparse

from .._validate import POSITIVE, Range, arg_number
from ._posterior_sigmoid import print_sigmoid, run_sigmoid

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
        help="emcee posterior of what locate measured in an image (vs its covariance and the CRLB)",
        description="Locate the body in IMAGE and sample the posterior of the fit locate ran (its model and nuisance "
        "parameters) with emcee until the chain is longer than 50 autocorrelation times; map the samples to the body "
        "centre, radius and range through locate's mapping and report them beside locate's covariance, the "
        "Cramér-Rao bound and the posterior adjusted for the model error.  --model sigmoid: the circular sigmoid "
        "(the paper's study).  Exit 0 on success (also when the chain did not converge: see \"converged\"), 2 for "
        "unusable input, 3 when a check fails.",
    )
    p.add_argument("image", metavar="IMAGE", help="image file (PNG, TIFF, FITS) or a .npy array")
    p.add_argument("--camera", metavar="CAMERA.json", help="camera file (enables the body centre, LOS and range)")
    p.add_argument("--hints", metavar="HINTS.json", help="hints (docs/design.md); the Sun direction selects the physical "
                   "profile; --model sigmoid: expected_radius_px becomes a radius prior")
    p.add_argument("--model", choices=("locate", "sigmoid"), default="locate",
                   help="locate: the fit locate ran (default); sigmoid: the circular sigmoid (the paper's study)")
    p.add_argument("--profile", choices=("auto", "sigmoid", "lunar-lambert"), default=None,
                   help="locate's limb profile (default: locate's own default)")
    _sigmoid_args(p)
    p.add_argument("--noise", choices=("marginal", "known", "free"), default="marginal",
                   help="noise treatment: sigma marginalised (default), known (--sigma; with --model locate the fit's "
                   "residual sigma), or sampled (--model sigmoid)")
    p.add_argument("--sigma", type=arg_number(POSITIVE), help="noise sd in DN for --model sigmoid --noise known (> 0)")
    p.add_argument("--walkers", type=_even_walkers, default=32,
                   help=f"emcee walkers: an even integer {_WALKERS} and at least twice the sampled parameters "
                   "(default 32)")
    p.add_argument("--moves", choices=("stretch", "laplace"), default="stretch",
                   help="emcee moves: stretch (default) or laplace (independence proposals around the fit, mixed "
                   "with stretch moves: much shorter autocorrelation for near-Gaussian posteriors)")
    p.add_argument("--max-steps", type=arg_number(_STEPS, integer=True), default=20000,
                   help=f"stop unconverged after this many steps {_STEPS}")
    p.add_argument("--max-time", type=arg_number(_SECONDS), default=120.0,
                   help=f"stop unconverged after this many seconds {_SECONDS}")
    p.add_argument("--seed", type=arg_number(_SEED, integer=True), default=0, help=f"random seed {_SEED}")
    p.add_argument("--plot", metavar="OUT.png", help="save a figure (locate: the centre's and radius's samples; "
                   "sigmoid: a corner plot)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def _sigmoid_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("--model sigmoid")
    g.add_argument("--center-rc", nargs=2, type=arg_number(_COORD), metavar=("ROW", "COL"),
                   help=f"skip locate: circle centre, px {_COORD} (with --radius; implies --model sigmoid)")
    g.add_argument("--radius", type=arg_number(_PX), help=f"skip locate: circle radius, px {_PX} (with --center-rc)")
    g.add_argument("--annulus", type=arg_number(_PX), default=6.0,
                   help=f"half-width of the pixel band for --center-rc, px {_PX} (default 6)")
    g.add_argument("--k", type=arg_number(_K), default=2.0,
                   help=f"start (or fixed) steepness k for --center-rc, 1/px {_K} (default 2)")
    g.add_argument("--fix", default="", help="comma-separated parameters held fixed, e.g. k,ymax,ymin")


def _even_walkers(text: str) -> int:
    """``--walkers``: an even integer in ``_WALKERS`` (argparse reports the failure, exit 2)."""
    n = arg_number(_WALKERS, integer=True)(text)
    if n % 2:
        raise argparse.ArgumentTypeError(f"must be an even integer {_WALKERS}, got {text!r}")
    return n


def load_image_array(path: str):  # noqa: ANN201
    """An image file or a ``.npy`` array as a float array (``ImageReadError``: exit 2)."""
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


def read_frame(image_path: str, camera_path: str | None, hints_path: str | None):  # noqa: ANN201
    """``(image, camera or None, hints dict)`` of a frame, every file checked before any work."""
    from .._io import read_json_file
    from ..errors import LimbInputError
    from ..geometry.camera import Camera
    from ..imaging import Hints

    image = load_image_array(image_path)
    if image.ndim != 2:
        raise LimbInputError(f"IMAGE must be a 2-D grey image, got shape {image.shape}")
    camera = Camera.from_json(camera_path) if camera_path is not None else None
    hints: dict = {}
    if hints_path is not None:
        hints = read_json_file(hints_path, "hints file")
        Hints.from_dict(hints)  # every value checked (types, ranges) before any work
    return image, camera, hints


def _fixed(args: argparse.Namespace, sigmoid: bool) -> tuple[str, ...]:
    """``--fix`` (the circle's parameters; only with --model sigmoid), checked."""
    from ..errors import LimbInputError
    from ..models import CIRCLE

    fixed = tuple(s.strip() for s in args.fix.split(",") if s.strip())
    if fixed and not sigmoid:
        raise LimbInputError("--fix holds parameters of --model sigmoid (locate's fit holds its own)")
    unknown = sorted(set(fixed) - set(CIRCLE.param_names))
    if unknown:
        raise LimbInputError(f"`--fix` names unknown parameters {unknown}; the circle model has {list(CIRCLE.param_names)}")
    return fixed


def _checked(args: argparse.Namespace):  # noqa: ANN202
    """Every argument combination checked before any work: ``(sigmoid?, fixed, PosteriorOptions)``."""
    from ..analysis.posterior import PosteriorOptions
    from ..errors import LimbInputError
    from . import figure_path

    figure_path(args.plot, "--plot")
    if (args.center_rc is None) != (args.radius is None):
        raise LimbInputError("`--center-rc` and `--radius` go together (both or neither)")
    sigmoid = args.model == "sigmoid" or args.center_rc is not None
    if sigmoid and args.profile is not None:
        raise LimbInputError("--profile chooses locate's fit; --model sigmoid samples the circular sigmoid")
    if args.noise == "known" and sigmoid and args.sigma is None:
        raise LimbInputError("`--noise known` needs `--sigma`")
    if args.noise == "free" and not sigmoid:
        raise LimbInputError("--noise free samples log sigma of --model sigmoid; locate's fit: marginal or known")
    fixed = _fixed(args, sigmoid)
    opt = PosteriorOptions(n_walkers=args.walkers, max_steps=args.max_steps, max_time_s=args.max_time, seed=args.seed,
                           moves=args.moves)
    return sigmoid, fixed, opt


def _run_located(args: argparse.Namespace, opt, image, camera, hints: dict) -> dict:  # noqa: ANN001
    """Sample the posterior of ``locate``'s fit; returns the ``--json`` object."""
    from ..analysis.located import located_fit
    from ..analysis.posterior import measured_posterior, plot_measured
    from ..pipeline import LocateOptions
    from . import show_progress, try_save

    options = LocateOptions() if args.profile is None else LocateOptions(profile=args.profile)
    lf = located_fit(image, camera, hints or {"body": "moon"}, options)
    mp = measured_posterior(lf, opt, noise=args.noise, progress=show_progress(args))
    out = {"status": "ok", "n_pixels": int(lf.data.coords.shape[0]), "noise": args.noise, "sigma_hat": lf.sigma,
           "locate": {"center_rc": list(lf.measurement.center_rc), "radius_px": lf.measurement.radius_px,
                      "range_km": lf.measurement.range_km, "crlb": lf.crlb}, **mp.summary()}
    if args.plot:
        title = f"{args.image}: {lf.model.name}, {out['n_pixels']} px, {mp.posterior.n_steps} steps"
        err = try_save(lambda: plot_measured(mp, args.plot, title=title), "--plot")
        out.update(plot=args.plot if err is None else None, **({"plot_error": err} if err else {}))
    return out


def _print_located(out: dict) -> None:
    c = out["chain"]
    print(f"{out['n_pixels']} pixels; locate's {out['model']} fit, free {', '.join(out['free'])}; {c['n_steps']} steps x "
          f"{c['n_walkers']} walkers in {c['wall_s']:.1f} s; max tau {max(c['tau'].values()):.1f}; "
          f"{'converged' if c['converged'] else 'NOT converged'}")
    print(f"{'':>10} {'locate':>14} {'locate sd':>10} {'CRLB':>10} {'post mean':>14} {'post sd':>10} {'adj. sd':>10} "
          f"{'post/locate':>11}")
    for q, r in out["comparison"].items():
        crlb = "-" if r["crlb"] is None else f"{r['crlb']:.4g}"
        print(f"{q:>10} {r['locate']:14.6f} {r['locate_sd']:10.4g} {crlb:>10} {r['post_mean']:14.6f} {r['post_sd']:10.4g} "
              f"{r['adjusted_sd']:10.4g} {r['post_over_locate']:11.3f}")


def run(args: argparse.Namespace) -> int:
    from . import emit_json, report_after_result

    sigmoid, fixed, opt = _checked(args)
    image, camera, hints = read_frame(args.image, args.camera, args.hints)
    out = run_sigmoid(args, opt, image, camera, hints, fixed) if sigmoid else _run_located(args, opt, image, camera, hints)
    if args.json:
        emit_json(out)
    else:
        (print_sigmoid if sigmoid else _print_located)(out)
    return report_after_result(out.get("plot_error"))
