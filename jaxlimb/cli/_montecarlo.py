"""``jaxlimb montecarlo``: noise study of a sigmoid-model fit on a rendered disk."""

from __future__ import annotations

import argparse

from .._validate import Range, arg_number

#: Argument ranges (exit 2 outside them); memory is estimated before allocating too.
RANGES = {"radius": Range(5.0, 5000.0), "sigma": Range(0.0, 1e6, lo_open=True), "n": Range(2, 10_000_000),
          "seed": Range(0, 2**32 - 1), "k": Range(0.0, 1e3, lo_open=True), "annulus": Range(0.5, 1000.0),
          "batch": Range(1, 100_000), "range_km": Range(2000.0, 1e9), "phase_deg": Range(0.0, 170.0),
          "workers": Range(1, 1024), "devices": Range(1, 256)}


def _num(name: str, integer: bool = False):  # noqa: ANN202
    return arg_number(RANGES[name], integer=integer)


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
    p.add_argument("--radius", type=_num("radius"), default=150.0, help="radius / semi-axis a in px (default 150)")
    p.add_argument("--sigma", type=_num("sigma"), default=10.0, help="Gaussian noise in DN (default 10)")
    p.add_argument("--n", type=_num("n", True), default=1000, help="realisations (default 1000)")
    p.add_argument("--solver", choices=sorted(SOLVER_NAMES), default="lm")
    p.add_argument("--seed", type=_num("seed", True), default=0)
    p.add_argument("--k", type=_num("k"), default=3.0, help="sigmoid steepness (default 3)")
    p.add_argument("--annulus", type=_num("annulus"), default=6.0,
                   help=f"half-width of the pixel band, px {RANGES['annulus']} (default 6; a narrower band holds no pixel "
                   "of some rows)")
    p.add_argument("--fix", default="", help="comma-separated parameters held at truth, e.g. k,ymax,ymin")
    p.add_argument("--batch", type=_num("batch", True), default=None,
                   help="realisations per compiled batch / per task (default 250; --pipeline: about 16 tasks per worker; --resume: the study's own)")
    p.add_argument("--out", metavar="DIR", help="write every finished batch to DIR (chunk files + manifest)")
    p.add_argument("--resume", action="store_true", help="continue the study already in --out DIR")
    g = p.add_argument_group("full pipeline (--pipeline): rendered Moon frames through `locate`, on Dask workers")
    g.add_argument("--pipeline", action="store_true",
                   help="Monte Carlo of the whole locate pipeline on a rendered lunar-Lambert Moon (needs --out)")
    g.add_argument("--camera", metavar="CAMERA.json", help="camera of the rendered frames (default: 1944x2592, 16 mm)")
    g.add_argument("--range-km", type=_num("range_km"), default=150_000.0, dest="range_km", help="Moon range, km (default 150000)")
    g.add_argument("--phase-deg", type=_num("phase_deg"), default=45.0, dest="phase_deg", help="phase angle, deg (default 45)")
    g.add_argument("--workers", type=_num("workers", True), default=None,
                   help="Dask LocalCluster with this many worker processes (default: in this process)")
    g.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler, e.g. tcp://node:8786")
    p.add_argument("--devices", type=_num("devices", True), default=None,
                   help="XLA CPU devices the batches are split over (default: one per usable core; "
                   "ignored when XLA_FLAGS already sets xla_force_host_platform_device_count)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run, host_devices=_host_devices, needs_jax=_needs_jax)


def _needs_jax(args: argparse.Namespace) -> bool:
    """Whether this process computes (and so starts JAX first).  A ``--pipeline`` study on Dask workers
    (``--workers`` / ``--scheduler``) does not: the workers start JAX themselves
    (:class:`~jaxlimb.analysis.distributed.LocateTrial`), and this process only starts the cluster, submits
    the chunks and assembles their files -- so the cluster starts ~1 s sooner."""
    return not (args.pipeline and (args.workers is not None or args.scheduler is not None))


def _host_devices(args: argparse.Namespace) -> int:
    """CPU devices for the model study (read before JAX starts): ``--devices`` or one per usable core.

    The study's compiled program splits its seeds over the local devices (``shard_map``, each
    device on its own thread; :func:`jaxlimb.analysis.model_study._program`), so on a 2-core CPU
    two devices halve the wall time of the fits.  The full-pipeline study (``--pipeline``)
    scales with Dask worker processes instead: one device there.
    """
    from .._jaxcache import usable_cores

    if args.pipeline:
        return 1
    if args.devices is not None:
        return int(args.devices)
    return usable_cores()


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


def _batch_size(args: argparse.Namespace) -> int:
    """``--batch`` (default 250), at most ``--n`` for a new study: a batch is compiled for its full width, so a
    wider one only fits padding (``--n 2 --batch 100000`` would fit 100 000 members); a resumed study keeps its own."""
    batch = 250 if args.batch is None else int(args.batch)
    return batch if args.resume else min(batch, int(args.n))


def run(args: argparse.Namespace) -> int:
    if args.pipeline:
        from ._mc_pipeline import run_pipeline

        return run_pipeline(args)
    if args.workers is not None or args.scheduler is not None:
        from ..errors import ConfigError

        raise ConfigError("--workers/--scheduler run the full-pipeline study: add --pipeline (the model study "
                          "runs as compiled batches in one process)")
    from ..analysis.montecarlo import ChunkRecomputedWarning
    from ..analysis.model_study import ModelStudyOptions, run_model_study, study_table
    from ..fitting import solver_from_name
    from . import emit_json, warnings_to_stderr

    _check_out(args)
    size = int(max(400, 2 * args.radius + 100))
    opt = ModelStudyOptions(
        model=args.model, shape=(size, size), radius=args.radius, sigma=args.sigma, n=args.n, seed=args.seed,
        k=args.k, annulus=args.annulus, batch=_batch_size(args),
        fixed=tuple(s.strip() for s in args.fix.split(",") if s.strip()),
    )
    with warnings_to_stderr(ChunkRecomputedWarning):
        res = run_model_study(opt, solver_from_name(args.solver), progress=not args.json, out_dir=args.out)
    import jax

    res["devices"] = jax.local_device_count()
    if args.json:
        emit_json({"status": "ok", **res})
    else:
        resumed = f", {res['chunks_resumed']} batches resumed from {args.out}" if res["chunks_resumed"] else ""
        print(f"{res['converged']}/{res['n']} converged, {res['n_pixels']} pixels, solver {res['solver']}, "
              f"wall {res['wall_s']:.2f} s (fits {res['fit_s']:.2f} s on {res['devices']} device(s), "
              f"compile {res['compile_s']:.2f} s){resumed}")
        print(study_table(res))
    return 0
