"""``jaxlimb locate IMAGE``: the body centre, radius, line of sight and range from one image (``docs/design.md``).

The pipeline is imported when the command runs (``jaxlimb --help`` does not import JAX)."""

from __future__ import annotations

import argparse
import time

from .._image_bounds import check_file
from .._jaxcache import CompileTimer
from .._solver_names import SOLVER_NAMES
from .._validate import Range, arg_number
from ..errors import ConfigError, SaturationWarning
from ..geometry.camera import Camera
from . import _batch, emit_json, figure_path, report_after_result, try_save, warnings_to_stderr
from ._inputs import (add_center_tolerance, locate_options_given, read_frame_file, read_hints, spice_prediction,
                      spice_report)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "locate",
        help="locate a body (Moon, Earth, Sun, any sphere or spheroid) in an image: centre, radius, LOS, range",
        description="Find the limb of the body in IMAGE, fit its limb model (the physical lunar-Lambert profile "
        "when the Sun direction is known, else the sigmoid; the limb-darkened disc for the Sun; the limb ellipse "
        "of a spheroid such as the Earth) and report the image of the body centre, the apparent radius, the "
        "covariance, the checks and, with a camera, the line of sight and the range.  Exit 0 on success, 2 for "
        "unusable input, 3 when a check fails.",
    )
    p.add_argument("image", metavar="IMAGE", nargs="+",
                   help="image file: VICAR, PDS3 (.IMG/.LBL), PDS4 (.xml), FITS, PNG, TIFF, JPEG, JPEG 2000; "
                   "several files, a directory, a quoted glob or @LIST.txt: one JSON line per frame (see --out)")
    p.add_argument("--camera", metavar="CAMERA.json",
                   help="camera file: focal length, pixel pitch, size, principal point, optional distortion "
                   "(docs/formats.md)")
    p.add_argument("--hints", metavar="HINTS.json", help="navigation prior (docs/design.md hints; every key optional)")
    p.add_argument("--body", metavar="NAME", default=None,
                   help="the body: moon, earth, sun (limb-darkened disc) or any body with known radii (e.g. enceladus; "
                   "SPICE PCK with --kernels, else the IAU 2015 table; hints body_radii_km override); default: the "
                   "hints' body, the label's TARGET_NAME with --kernels, else moon")
    p.add_argument("--kernels", metavar="KERNEL", nargs="+", default=None,
                   help="SPICE meta-kernel or kernel files (never downloaded): camera, predicted limb, Sun direction, "
                   "range and orientation from the label's image time; reports measured - predicted")
    p.add_argument("--instrument", metavar="NAME", default=None,
                   help="SPICE instrument (e.g. CASSINI_ISS_NAC); default: the label's INSTRUMENT_ID")
    p.add_argument("--front-end", choices=("gradient", "scanline"), default="gradient", dest="front_end",
                   help="candidate-limb front end (default gradient; when it finds no limb the other one is tried and "
                   "the answer's front_end says which answered)")
    p.add_argument("--no-front-end-fallback", action="store_false", dest="front_end_fallback",
                   help="only the chosen front end: its failure is the answer")
    p.add_argument("--model", choices=("circle", "ellipse"), default="circle", help="limb model (default circle)")
    p.add_argument("--solver", choices=sorted(SOLVER_NAMES), default="lm", help="least-squares solver (default lm)")
    p.add_argument("--fixed-k", action="store_true",
                   help="hold k = 3 and ymax/ymin at the annulus edge means (illuminated-ellipsoid paper, Table 1)")
    p.add_argument("--profile", choices=("auto", "sigmoid", "lunar-lambert", "albedo-field", "limb-darkened", "corona"),
                   default="auto",
                   help="limb profile.  auto (default): the physical lunar-Lambert limb when the hints give "
                   "sun_dir_camera (it removes the sigmoid's 0.1-0.6 px limb bias), for --body sun the limb-darkened disc "
                   "or, when the disc is brightest at its limb (the EUV), the corona over an opaque disc, else the "
                   "sigmoid; sigmoid: the papers' model; lunar-lambert; albedo-field: lunar-lambert with the surface "
                   "albedo an unknown field, marginalised; limb-darkened; corona")
    p.add_argument("--sun-declination-max", type=arg_number(Range(0.0, 90.0)), metavar="DEG", default=None,
                   help="Earth (or spheroid) without R_body_to_camera, Sun known: the largest angle (0-90 deg) of the "
                   "Sun from the body's equator (the Earth: 23.44); the centre is marginalised over the poles it "
                   "allows, which often signs the centre offset the limb leaves open (default: not used)")
    p.add_argument("--unresolved-glow", type=_unresolved_glow, metavar="G_MAX,H_LO_KM,H_HI_KM|none",
                   default=argparse.SUPPRESS,
                   help="Earth (or spheroid): the glow above the edge carried in the covariance when the fit has none: "
                   "brightness up to G_MAX of the disc's radiance, scale height H_LO_KM to H_HI_KM (default: "
                   "EllipsoidOptions', 0.4,6,25; none for a body without an atmosphere)")
    add_center_tolerance(p)
    p.add_argument("--figure", metavar="PATH", help="also save a picture of the fit (PNG/PDF)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    _batch.add_batch_arguments(p)
    p.set_defaults(func=run, precheck=_precheck)


def _precheck(args: argparse.Namespace) -> None:
    """One frame: the size its header declares, checked before JAX starts (a bomb is refused in milliseconds)."""
    if len(args.image) == 1 and not args.image[0].startswith("@") and args.out is None:
        check_file(args.image[0])


def _unresolved_glow(text: str):
    """``--unresolved-glow``: ``none`` or ``G_MAX,H_LO_KM,H_HI_KM``, checked by ``EllipsoidOptions`` itself."""
    from ..pipeline import EllipsoidOptions

    if text.strip().lower() == "none":
        return None
    try:
        g, lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected G_MAX,H_LO_KM,H_HI_KM or none, got {text!r}") from None
    try:
        return EllipsoidOptions(unresolved_glow=(g, lo, hi)).unresolved_glow
    except ConfigError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _json(meas, spice, timing: dict | None = None) -> dict:
    out = meas.to_json()
    if spice is not None:
        out["spice"] = spice
    if timing is not None:  # compile_s: tracing + compiling (or loading from the persistent cache)
        out["timing"] = timing
    return out


def run(args: argparse.Namespace) -> int:
    images = list(args.image)
    if _batch.is_many(images, args):  # many frames: JSON Lines, one per frame (cli/_batch.py)
        if args.figure:
                    raise ConfigError("--figure saves one frame's picture: not with many frames")
        return _batch.run_frames(images, args, read_frame_file, _frame_json(args))
    args.image = images[0]
    figure_path(args.figure, "--figure")  # before any work
    meas, spice, image, timing = _measure(args, read_frame_file(args.image))
    figure_error = None
    if args.figure:  # after the work: a failing writer must not lose the measurement
        from ..pipeline import save_locate_figure

        figure_error = try_save(lambda: save_locate_figure(image, meas, args.figure), "--figure")
    _print(args, meas, spice, figure_error, timing)
    return report_after_result(figure_error)


def _frame_json(args: argparse.Namespace):  # noqa: ANN202
    """The per-frame measure of the many-frame runner: ``(path, frame) -> --json object``."""
    def measure(path: str, frame) -> dict:  # noqa: ANN001
        meas, spice, _, timing = _measure(args, frame)
        return _json(meas, spice, timing)

    return measure


def _measure(args: argparse.Namespace, frame):
    """``(measurement, SPICE report or None, image, timing)`` of one frame; ``timing`` holds the
    seconds of the measurement and ``compile_s``, the part spent compiling (0 once compiled)."""


    t0 = time.perf_counter()
    with CompileTimer() as ct:
        meas, spice, image = _measure_frame(args, frame)
    return meas, spice, image, {"seconds": time.perf_counter() - t0, "compile_s": ct.seconds}


def _measure_frame(args: argparse.Namespace, frame):
    """The CLI chooses nothing but options: :func:`jaxlimb.pipeline.locate` picks the body strategy
    from the hints' body."""
    from ..pipeline import EllipsoidOptions, LocateOptions, locate

    image = frame.data
    geom = spice_prediction(args, frame.meta)
    camera = Camera.from_json(args.camera) if args.camera is not None else (geom.camera if geom else None)
    hints = read_hints(args.hints, args.body.lower() if args.body else (geom.target.lower() if geom else None),
                        base=geom.hints() if geom else None)
    glow = {"unresolved_glow": args.unresolved_glow} if "unresolved_glow" in vars(args) else {}  # else the library's
    ellipsoid = EllipsoidOptions(sun_declination_max_deg=args.sun_declination_max, **glow)
    options = LocateOptions(front_end=args.front_end, front_end_fallback=args.front_end_fallback, model=args.model,
                            solver=args.solver, estimate_k=not args.fixed_k, profile=args.profile, ellipsoid=ellipsoid,
                            **locate_options_given(args))
    with warnings_to_stderr(SaturationWarning):
        meas = locate(image, camera, hints, options, mask=frame.mask_or_none)
    return meas, (spice_report(geom, meas) if geom is not None else None), image


def _print(args: argparse.Namespace, meas, spice, figure_error: str | None = None, timing: dict | None = None) -> None:
    if args.json:
        emit_json({**_json(meas, spice, timing), **({"figure_error": figure_error} if figure_error else {})})
    else:
        print(f"centre (row, col): {meas.center_rc[0]:.4f} {meas.center_rc[1]:.4f} px")
        if meas.radius_px is not None:
            print(f"radius:            {meas.radius_px:.4f} px")
        if meas.ellipse is not None:
            e = meas.ellipse
            print(f"ellipse:           centre {e.center_rc[0]:.4f} {e.center_rc[1]:.4f}, semi-axes "
                  f"{e.semi_axes_px[0]:.4f} {e.semi_axes_px[1]:.4f} px, angle {e.angle_rad:.6f} rad")
        cov = meas.covariance
        if "center_r" in cov and "center_c" in cov:
            print(f"1-sigma centre:    {cov['center_r']['center_r'] ** 0.5:.4f} {cov['center_c']['center_c'] ** 0.5:.4f} px")
        if meas.los_camera is not None:
            print("LOS (camera):      " + " ".join(f"{v:.9f}" for v in meas.los_camera))
        if meas.range_km is not None:
            print(f"range:             {meas.range_km:.3f} km")
        if spice is not None:
            d = spice["measured_minus_predicted"]
            print(f"measured - SPICE:  {d['delta_rc_px'][0]:.3f} {d['delta_rc_px'][1]:.3f} px "
                  f"({d['angle_urad']:.1f} urad)")
        print(f"k {meas.k:.4f}, ymax {meas.ymax:.2f}, ymin {meas.ymin:.2f}; {meas.n_pixels} px, "
              f"{meas.iterations} iterations ({meas.solver}, {meas.front_end} front end)")
