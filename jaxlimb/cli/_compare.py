"""``jaxlimb compare``: every registered solver on the same noise realisations, timed interleaved and repeated.

The problem is a model's standard problem (``--model``, as ``jaxlimb montecarlo``) or the fit ``locate`` runs on a
frame (``--frame IMAGE`` with ``--camera`` and ``--hints``, or ``--render FAMILY``: a Moon of the independent
renderer's family): its model, pixels, weights and held parameters at ``locate``'s answer, with noise at the
fit's residual sigma (:func:`jaxlimb.analysis.located.fit_problem`).  Table on stdout (``--json``: one object),
``--out FILE.json``, ``--plot FILE.png``.
"""

from __future__ import annotations

import argparse

from .._validate import Range, arg_number
from ._study_args import add_problem_args, host_devices, num, solver_list


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "compare",
        help="every solver on the same realisations: success, failures, iterations, ms/fit, bias, RMS/CRLB",
        description="Fit N noise realisations of one limb problem with every registered solver (the same "
        "realisations for all), timing them interleaved in chunks with the solvers taking turns, and report success "
        "rate, failures by reason, iterations, ms per fit (median wall and CPU time), bias, RMS and RMS/CRLB.  The "
        "problem: the standard problem of --model, or the fit locate runs on a frame (--frame or --render).",
    )
    add_problem_args(p)
    p.add_argument("--solvers", default="all", type=str,
                   help="comma-separated solver names, the first is the reference (default: all, lm first)")
    p.add_argument("--chunk", type=num("batch", True), default=None,
                   help="realisations per timed call (default 250; --mode single: 50)")
    p.add_argument("--repeats", type=num("repeats", True), default=1, help="timings of each chunk (default 1)")
    p.add_argument("--mode", choices=("batch", "single"), default="batch",
                   help="batch: the compiled Monte-Carlo program over the devices (default); single: one fit() "
                   "per realisation, as a pipeline fits one image")
    g = p.add_argument_group("the fit locate runs on a frame")
    g.add_argument("--frame", metavar="IMAGE", help="image file (PNG, TIFF, FITS, .npy) measured by locate")
    g.add_argument("--camera", metavar="CAMERA.json", help="camera of --frame")
    g.add_argument("--hints", metavar="HINTS.json", help="hints of --frame (body, sun_dir_camera, ...)")
    g.add_argument("--render", metavar="FAMILY", help="a Moon rendered by the independent renderer, e.g. own, hapke")
    g.add_argument("--render-seed", dest="render_seed", type=arg_number(Range(0, 2**32 - 1), integer=True), default=0)
    p.add_argument("--plot", metavar="OUT.png", help="save the figure (ms/fit and RMS/CRLB per solver)")
    p.add_argument("--out", metavar="OUT.json", help="write the JSON result to this file")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run, host_devices=host_devices)


def _problem(args: argparse.Namespace):  # noqa: ANN202
    """The standard problem of the arguments, or locate's fit on --frame / --render."""
    from ..errors import LimbInputError

    if args.frame is not None and args.render is not None:
        raise LimbInputError("--frame and --render are alternatives: give one")
    if args.frame is None and args.render is None:
        from ..analysis.problems import standard_problem
        from ._study_args import study_options

        return standard_problem(study_options(args, 250)), None
    from ..analysis.located import fit_problem, located_fit

    if args.render is not None:
        import numpy as np

        from ..render.independent import MOON_FAMILIES, moon_case

        if args.render not in MOON_FAMILIES:
            raise LimbInputError(f"--render must be one of {list(MOON_FAMILIES)}, got {args.render!r}")
        case = moon_case(args.render, np.random.default_rng(args.render_seed))
        image, camera, hints = case.image, case.camera, case.hints
    else:
        from ._posterior import read_frame

        image, camera, hints = read_frame(args.frame, args.camera, args.hints)
    return fit_problem(located_fit(image, camera, hints)), {"frame": args.frame, "render": args.render,
                                                            "render_seed": args.render_seed}


def check_outputs(args: argparse.Namespace) -> object:
    """Every output path and the solver names checked before any work; returns the ``CompareOptions``."""
    from .._validate import output_file
    from ..analysis.compare import CompareOptions
    from . import figure_path

    figure_path(args.plot, "--plot")
    if args.out is not None:
        output_file(args.out, "--out", suffixes=(".json",))
    chunk = args.chunk if args.chunk is not None else (50 if args.mode == "single" else 250)
    return CompareOptions(solvers=solver_list(args.solvers), n=args.n, seed=args.seed, chunk=chunk,
                          repeats=args.repeats, mode=args.mode)


def run_comparison(args: argparse.Namespace, opt, problem, extra: dict | None = None) -> int:  # noqa: ANN001
    """Compare the solvers of ``opt`` on ``problem``; print, write and plot as ``args`` ask."""
    from .._io import write_json_atomic
    from ..analysis.compare import compare_solvers, compare_table, plot_compare
    from . import emit_json, finite_json, report_after_result, show_progress, try_save

    res = compare_solvers(problem, opt, progress=show_progress(args))
    if extra:
        res["source"] = extra
    if args.out:
        write_json_atomic(args.out, finite_json(res))
    plot_error = try_save(lambda: plot_compare(res, args.plot), "--plot") if args.plot else None
    if args.json:
        emit_json(res if plot_error is None else {**res, "plot_error": plot_error})
    else:
        print(f"{res['problem']['label']}: {opt.n} realisations x {len(opt.solvers)} solvers ({opt.mode}, "
              f"{res['devices']} device(s), chunks of {opt.chunk} timed {opt.repeats}x, interleaved); "
              f"wall {res['wall_s']:.1f} s (compiling {res['compile_wall_s']:.1f} s); load {res['loadavg'][0]:.1f}")
        print(compare_table(res))
    return report_after_result(plot_error)


def run(args: argparse.Namespace) -> int:
    opt = check_outputs(args)
    problem, extra = _problem(args)
    return run_comparison(args, opt, problem, extra)
