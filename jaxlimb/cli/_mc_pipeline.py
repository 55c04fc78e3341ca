"""``jaxlimb montecarlo --pipeline``: Monte Carlo of the whole ``locate`` pipeline, in process or on Dask.

Frames through ``locate`` with its defaults (``--profile``: another limb profile):

* ``--families own,hapke,...`` (``--body moon|earth``): a new frame per trial from the independent renderer's scene
  families, cycling through them (:class:`jaxlimb.analysis.pipeline_study.FamilyTrial`);
* otherwise one rendered 1944x2592 (or ``--camera``) lunar-Lambert Moon with new Gaussian noise per trial
  (:class:`jaxlimb.analysis.pipeline_study.LocateTrial`).

Chunks of trials are written to ``--out DIR`` as they finish (the Monte-Carlo engine's files), ``--resume``
continues, ``--workers N`` runs the chunks on a Dask ``LocalCluster`` and ``--scheduler ADDRESS`` on a running Dask
cluster.  Reported per family and for all: bias and RMS of the centre, radius and range errors, the mean reported
sigma and Cramér--Rao sigma, the mean NEES of the centre and the coverage of its reported 68 % / 95 % ellipses
(:func:`jaxlimb.analysis.pipeline_study.pipeline_summary`).  The statistics are written to ``DIR/result.json`` (no
timings in it: an interrupted and resumed run writes the same file as an uninterrupted one) and printed with the
timings; ``--plot`` draws the normalised errors and the coverage.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import time
from pathlib import Path
from typing import Any

from ._study_args import check_out, num


def add_pipeline_args(p: argparse.ArgumentParser) -> None:
    """The ``--pipeline`` argument group of ``jaxlimb montecarlo``."""
    g = p.add_argument_group("full pipeline (--pipeline): rendered frames through `locate`, on Dask workers")
    g.add_argument("--pipeline", action="store_true", help="Monte Carlo of the whole locate pipeline (needs --out)")
    g.add_argument("--families", default=None,
                   help="independent scene families, comma-separated (e.g. own,hapke,maria; all: every family of the "
                   "body): a new frame per trial; default: one rendered lunar-Lambert Moon with new noise per trial")
    g.add_argument("--body", choices=("moon", "earth"), default="moon", help="body of --families (default moon)")
    g.add_argument("--profile", choices=("auto", "sigmoid", "lunar-lambert"), default=None,
                   help="locate's limb profile (default: locate's own default)")
    g.add_argument("--camera", metavar="CAMERA.json", help="camera of the one-scene study (default: 1944x2592, 16 mm)")
    g.add_argument("--range-km", type=num("range_km"), default=150_000.0, dest="range_km",
                   help="Moon range of the one-scene study, km (default 150000)")
    g.add_argument("--phase-deg", type=num("phase_deg"), default=45.0, dest="phase_deg",
                   help="phase angle of the one-scene study, deg (default 45)")
    g.add_argument("--workers", type=num("workers", True), default=None,
                   help="Dask LocalCluster with this many worker processes (default: in this process)")
    g.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler, e.g. tcp://node:8786")


def _families(args: argparse.Namespace) -> tuple[str, ...] | None:
    if args.families is None:
        return None
    from ..render.independent import EARTH_FAMILIES, MOON_FAMILIES

    every = MOON_FAMILIES if args.body == "moon" else EARTH_FAMILIES
    return tuple(every) if args.families.strip() == "all" else tuple(f.strip() for f in args.families.split(",") if f.strip())


def study(args: argparse.Namespace, camera: Any) -> tuple[Any, Any, tuple[str, ...] | None]:
    """The trial, the Monte-Carlo options (the study's identity in its manifest) and the families."""
    from ..analysis.distributed import default_chunk
    from ..analysis.montecarlo import MonteCarloOptions, study_chunk_size
    from ..analysis.pipeline_study import FamilyTrial, LocateTrial
    from . import show_progress

    families = _families(args)
    profile = getattr(args, "profile", None)
    if families is not None:
        trial: Any = FamilyTrial(families=families, body=args.body, profile=profile)
        ident = {"families": list(families), "body": args.body, "profile": profile}
    else:
        trial = LocateTrial(camera=camera, range_km=args.range_km, phase_deg=args.phase_deg, sigma_dn=args.sigma,
                            profile=profile)
        ident = {"camera": camera.to_dict(), "range_km": args.range_km, "phase_deg": args.phase_deg,
                 "sigma_dn": args.sigma, "profile": profile}
    chunk = args.batch
    if chunk is None and args.resume:  # the study's own chunks, whatever the number of workers now
        chunk = study_chunk_size(args.out)
    if chunk is None:
        chunk = default_chunk(args.n, args.workers or 1)
    key = hashlib.sha1(json.dumps(ident, sort_keys=True).encode()).hexdigest()[:12]
    opt = MonteCarloOptions(n_trials=args.n, chunk_size=chunk, seed=args.seed, out_dir=args.out,
                            name=f"pipeline-{key}", progress=show_progress(args))
    return trial, opt, families


def _summary(res: Any, args: argparse.Namespace, camera: Any, families: tuple[str, ...] | None) -> dict[str, Any]:
    from ..analysis.pipeline_study import pipeline_summary

    st = pipeline_summary(res, families)
    scene = ({"families": list(families), "body": args.body} if families is not None else
             {"frame": [camera.rows, camera.cols], "range_km": args.range_km, "phase_deg": args.phase_deg,
              "sigma_dn": args.sigma})
    return {"status": "ok", "n": res.n, "n_ok": int(res.ok.sum()), "failures": res.failure_counts(), "summary": st,
            "study": {**scene, "profile": args.profile or "locate default", "seed": args.seed}}


def _run(trial: Any, opt: Any, args: argparse.Namespace) -> Any:
    from ..analysis.montecarlo import ChunkRecomputedWarning, run_monte_carlo
    from . import show_progress, warnings_to_stderr

    with warnings_to_stderr(ChunkRecomputedWarning):
        if args.workers is None and args.scheduler is None:
            return run_monte_carlo(trial, opt)
        from ..analysis.distributed import close_client, make_client, run_monte_carlo_distributed

        client = make_client(args.scheduler, args.workers or 2)
        try:
            return run_monte_carlo_distributed(trial, opt, client, progress=show_progress(args))
        finally:
            close_client(client)


def _print(out: dict[str, Any], res: Any) -> None:
    print(f"{out['n_ok']}/{out['n']} frames ok in {out['wall_s']:.1f} s ({res.chunks_run} chunks run, "
          f"{res.chunks_skipped} resumed); {out['result_file']}")
    print(f"{'family':>10} {'ok':>5} {'bias r':>8} {'bias c':>8} {'RMS r':>8} {'RMS c':>8} {'sigma r':>8} "
          f"{'CRLB r':>8} {'NEES':>6} {'in 68%':>7} {'in 95%':>7}")
    for name, s in out["summary"].items():
        if "nees_mean" not in s:
            print(f"{name:>10} {s['n_ok']:>5}  (no answer with a covariance)")
            continue
        print(f"{name:>10} {s['n_ok']:>5} {s['row']['bias']:8.4f} {s['col']['bias']:8.4f} {s['row']['rms']:8.4f} "
              f"{s['col']['rms']:8.4f} {s.get('sigma_row_mean', float('nan')):8.4f} "
              f"{s.get('crlb_row_mean', float('nan')):8.4f} {s['nees_mean']:6.2f} {s['coverage']['68']:7.1%} "
              f"{s['coverage']['95']:7.1%}")


def run_pipeline(args: argparse.Namespace) -> int:
    from .._io import write_json_atomic
    from ..errors import ConfigError
    from ..geometry.camera import Camera
    from . import emit_json, figure_path, report_after_result, try_save

    if args.out is None:
        raise ConfigError("--pipeline needs --out DIR (the finished chunks are its results; --resume continues them)")
    figure_path(args.plot, "--plot")
    check_out(args)
    camera = Camera.from_json(args.camera) if args.camera else Camera.default()
    trial, opt, families = study(args, camera)
    t0 = time.perf_counter()
    res = _run(trial, opt, args)
    out = _summary(res, args, camera, families)
    write_json_atomic(Path(args.out) / "result.json", out)
    out.update(wall_s=time.perf_counter() - t0, chunks_run=res.chunks_run, chunks_resumed=res.chunks_skipped,
               workers=args.workers, scheduler=args.scheduler, result_file=str(Path(args.out) / "result.json"))
    plot_error = None
    if args.plot:
        from ..analysis.pipeline_study import plot_pipeline

        title = f"locate on {', '.join(families) if families else 'one rendered Moon'}: {out['n_ok']}/{out['n']} frames"
        plot_error = try_save(lambda: plot_pipeline(res, out["summary"], args.plot, title), "--plot")
    if args.json:
        emit_json(out if plot_error is None else {**out, "plot_error": plot_error})
    else:
        _print(out, res)
    return report_after_result(plot_error)
