"""``jaxlimb montecarlo``: noise study of a limb-model fit on a rendered limb (``--solvers``: every solver on the
same realisations, as ``jaxlimb compare``; ``--pipeline``: the whole ``locate`` pipeline on rendered frames)."""

from __future__ import annotations

import argparse

from ._mc_pipeline import add_pipeline_args, run_pipeline
from ._study_args import add_problem_args, check_out, host_devices, num, study_options


def register(sub: argparse._SubParsersAction) -> None:
    from .._solver_names import SOLVER_NAMES

    p = sub.add_parser(
        "montecarlo",
        help="Monte-Carlo noise study of the model fit (RMS, bias, CRLB) or of the whole pipeline (NEES, coverage)",
        description="Render a limb with a limb model (--model), select the pixels around it, fit N noise "
        "realisations and compare the RMS error with the Cramér-Rao bound.  The realisations run in compiled "
        "batches split over the CPU devices; with --out DIR every finished batch is written to DIR and --resume "
        "continues an interrupted study there.  --solvers a,b,...: every solver on the same realisations "
        "(jaxlimb compare).  --pipeline: rendered frames through locate (its defaults), on Dask workers.",
    )
    add_problem_args(p)
    p.add_argument("--solver", choices=sorted(SOLVER_NAMES), default="lm", help="least-squares solver (default lm)")
    p.add_argument("--solvers", default=None, help="compare these solvers (comma-separated, or all) on the same "
                   "realisations: the table of jaxlimb compare")
    p.add_argument("--batch", type=num("batch", True), default=None,
                   help="realisations per compiled batch / per task (default 250; --pipeline: about 16 tasks per "
                   "worker; --resume: the study's own)")
    p.add_argument("--out", metavar="DIR", help="write every finished batch to DIR (chunk files + manifest)")
    p.add_argument("--resume", action="store_true", help="continue the study already in --out DIR")
    p.add_argument("--plot", metavar="OUT.png", help="save a figure of the study")
    add_pipeline_args(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run, host_devices=_host_devices, needs_jax=_needs_jax)


def _needs_jax(args: argparse.Namespace) -> bool:
    """Whether this process computes (and so starts JAX first).  A ``--pipeline`` study on Dask workers
    (``--workers`` / ``--scheduler``) does not: the workers start JAX themselves
    (:mod:`jaxlimb.analysis.pipeline_study`), and this process only starts the cluster, submits the chunks and
    assembles their files -- so the cluster starts ~1 s sooner."""
    return not (args.pipeline and (args.workers is not None or args.scheduler is not None))


def _host_devices(args: argparse.Namespace) -> int:
    """CPU devices (read before JAX starts): the model study's (:func:`._study_args.host_devices`); the
    full-pipeline study scales with Dask worker processes instead: one device there."""
    return 1 if args.pipeline else host_devices(args)


def _compare(args: argparse.Namespace) -> int:
    """``--solvers``: the comparison of ``jaxlimb compare`` on the standard problem of the arguments."""
    from ..analysis.problems import standard_problem
    from ..errors import ConfigError
    from ._compare import check_outputs, run_comparison

    if args.out is not None or args.resume:
        raise ConfigError("--solvers compares solvers in this process: --out DIR / --resume are for one solver's study")
    args.chunk, args.repeats, args.mode = args.batch, 1, "batch"
    opt = check_outputs(argparse.Namespace(**{**vars(args), "out": None}))
    return run_comparison(args, opt, standard_problem(study_options(args, 250)))


def _batch_size(args: argparse.Namespace) -> int:
    """``--batch`` (default 250), at most ``--n`` for a new study: a batch is compiled for its full width, so a
    wider one only fits padding (``--n 2 --batch 100000`` would fit 100 000 members); a resumed study keeps its own."""
    batch = 250 if args.batch is None else int(args.batch)
    return batch if args.resume else min(batch, int(args.n))


def run(args: argparse.Namespace) -> int:
    if args.pipeline:
        return run_pipeline(args)
    if args.workers is not None or args.scheduler is not None or args.families is not None:
        from ..errors import ConfigError

        raise ConfigError("--workers/--scheduler/--families run the full-pipeline study: add --pipeline (the model "
                          "study runs as compiled batches in one process)")
    if args.solvers is not None:
        return _compare(args)
    from ..analysis.model_study import run_model_study, study_table
    from ..analysis.montecarlo import ChunkRecomputedWarning
    from ..fitting import solver_from_name
    from . import emit_json, figure_path, report_after_result, show_progress, warnings_to_stderr

    figure_path(args.plot, "--plot")
    check_out(args)
    opt = study_options(args, _batch_size(args))
    with warnings_to_stderr(ChunkRecomputedWarning):
        res = run_model_study(opt, solver_from_name(args.solver), progress=show_progress(args), out_dir=args.out)
    import jax

    res["devices"] = jax.local_device_count()
    plot_error = _plot_model_study(args, res, opt)
    if args.json:
        emit_json({"status": "ok", **res, **({"plot_error": plot_error} if plot_error else {})})
    else:
        resumed = f", {res['chunks_resumed']} batches resumed from {args.out}" if res["chunks_resumed"] else ""
        print(f"{res['converged']}/{res['n']} converged, {res['n_pixels']} pixels, solver {res['solver']}, "
              f"wall {res['wall_s']:.2f} s (fits {res['fit_s']:.2f} s on {res['devices']} device(s), "
              f"compile {res['compile_s']:.2f} s){resumed}")
        print(study_table(res))
    return report_after_result(plot_error)


def _plot_model_study(args: argparse.Namespace, res: dict, opt) -> str | None:  # noqa: ANN001
    """``--plot``: RMS against the CRLB of every free parameter (after the result: a failing writer loses nothing)."""
    if not args.plot:
        return None
    from ..analysis.figures import plot_rms_vs_crlb
    from . import try_save

    pts = [{"crlb": res["crlb"][k], "rms": res["rms"][k], "label": k} for k in res["rms"]]
    return try_save(lambda: plot_rms_vs_crlb(pts, args.plot, title=f"{opt.model}, {res['converged']} fits, "
                                             f"{res['solver']}"), "--plot")
