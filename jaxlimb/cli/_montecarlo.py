"""``jaxlimb montecarlo``: noise study of a sigmoid-model fit on a rendered disk."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    from .._solver_names import SOLVER_NAMES

    p = sub.add_parser(
        "montecarlo",
        help="Monte-Carlo noise study of the model fit (RMS, bias, CRLB)",
        description="Render a disk with the circular (or elliptical) sigmoid model, select the pixels "
        "around the limb, fit N noise realisations and compare the RMS error with the Cramér-Rao bound.  "
        "The realisations run in compiled batches; with --out DIR every finished batch is written to DIR "
        "and --resume continues an interrupted study there.",
    )
    p.add_argument("--model", choices=["circle", "ellipse"], default="circle")
    p.add_argument("--radius", type=float, default=150.0, help="radius / semi-axis a in px (default 150)")
    p.add_argument("--sigma", type=float, default=10.0, help="Gaussian noise in DN (default 10)")
    p.add_argument("--n", type=int, default=1000, help="realisations (default 1000)")
    p.add_argument("--solver", choices=sorted(SOLVER_NAMES), default="lm")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--k", type=float, default=3.0, help="sigmoid steepness (default 3)")
    p.add_argument("--annulus", type=float, default=6.0, help="half-width of the pixel band, px (default 6)")
    p.add_argument("--fix", default="", help="comma-separated parameters held at truth, e.g. k,ymax,ymin")
    p.add_argument("--batch", type=int, default=250, help="realisations per compiled batch (default 250)")
    p.add_argument("--out", metavar="DIR", help="write every finished batch to DIR (chunk files + manifest)")
    p.add_argument("--resume", action="store_true", help="continue the study already in --out DIR")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _check_out(args: argparse.Namespace) -> None:
    """--out DIR must be new (or an existing study with --resume); checked before any work."""
    from pathlib import Path

    from ..errors import ConfigError

    if args.out is None:
        if args.resume:
            raise ConfigError("--resume needs --out DIR (the directory of the study to continue)")
        return
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {args.out!r} exists and is not a directory")
    has_study = (out / "manifest.json").exists()
    if has_study and not args.resume:
        raise ConfigError(f"--out {args.out!r} already holds a study: pass --resume to continue it, or choose a new directory")
    if out.is_dir() and not has_study and any(out.iterdir()):
        raise ConfigError(f"--out {args.out!r} is a non-empty directory without a study; choose a new or empty directory")


def run(args: argparse.Namespace) -> int:
    from ..analysis.montecarlo import ChunkRecomputedWarning
    from ..analysis.model_study import ModelStudyOptions, run_model_study, study_table
    from ..fitting import solver_from_name
    from . import emit_json, warnings_to_stderr

    _check_out(args)
    size = int(max(400, 2 * args.radius + 100))
    opt = ModelStudyOptions(
        model=args.model, shape=(size, size), radius=args.radius, sigma=args.sigma, n=args.n, seed=args.seed,
        k=args.k, annulus=args.annulus, batch=args.batch,
        fixed=tuple(s.strip() for s in args.fix.split(",") if s.strip()),
    )
    with warnings_to_stderr(ChunkRecomputedWarning):
        res = run_model_study(opt, solver_from_name(args.solver), progress=not args.json, out_dir=args.out)
    if args.json:
        emit_json(res)
    else:
        resumed = f", {res['chunks_resumed']} batches resumed from {args.out}" if res["chunks_resumed"] else ""
        print(f"{res['converged']}/{res['n']} converged, {res['n_pixels']} pixels, solver {res['solver']}, "
              f"wall {res['wall_s']:.2f} s (fits {res['fit_s']:.2f} s, compile {res['compile_s']:.2f} s){resumed}")
        print(study_table(res))
    return 0
