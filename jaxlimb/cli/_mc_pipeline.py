"""``jaxlimb montecarlo --pipeline``: Monte Carlo of the whole ``locate`` pipeline, in process or on Dask.

Rendered 1944x2592 (or ``--camera``) lunar-Lambert Moons with Gaussian noise through ``locate``
(:class:`jaxlimb.analysis.distributed.LocateTrial`); chunks of trials are written to ``--out DIR``
as they finish (the Monte-Carlo engine's files), ``--resume`` continues, ``--workers N`` runs the
chunks on a Dask ``LocalCluster`` and ``--scheduler ADDRESS`` on a running Dask cluster.  The
statistics are written to ``DIR/result.json`` (no timings in it: an interrupted and resumed run
writes the same file as an uninterrupted one) and printed with the timings.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import time
from pathlib import Path
from typing import Any

_KEYS = ("row", "col", "radius")


def _study(args: argparse.Namespace, camera: Any) -> tuple[Any, Any]:
    from ..analysis.distributed import LocateTrial, default_chunk
    from ..analysis.montecarlo import MonteCarloOptions, study_chunk_size

    trial = LocateTrial(camera=camera, range_km=args.range_km, phase_deg=args.phase_deg, sigma_dn=args.sigma)
    ident = json.dumps({"camera": camera.to_dict(), "range_km": args.range_km, "phase_deg": args.phase_deg,
                        "sigma_dn": args.sigma, "profile": trial.profile}, sort_keys=True)
    chunk = args.batch
    if chunk is None and args.resume:  # the study's own chunks, whatever the number of workers now
        chunk = study_chunk_size(args.out)
    if chunk is None:
        chunk = default_chunk(args.n, args.workers or 1)
    opt = MonteCarloOptions(n_trials=args.n, chunk_size=chunk, seed=args.seed, out_dir=args.out,
                            name=f"pipeline-{hashlib.sha1(ident.encode()).hexdigest()[:12]}", progress=not args.json)
    return trial, opt


def _summary(res: Any, opt: Any, args: argparse.Namespace, camera: Any) -> dict[str, Any]:
    st = res.stats(keys=_KEYS)
    it = res.values["iterations"][res.ok]
    return {"status": "ok", "n": st["n"], "n_ok": st["n_ok"], "failures": st["failures"],
            "error_px": {k: {m: st["params"][k].get(m) for m in ("rms", "bias", "std", "max_abs", "n")} for k in _KEYS},
            "iterations_mean": float(it.mean()) if it.size else None,
            "study": {"frame": [camera.rows, camera.cols], "range_km": args.range_km, "phase_deg": args.phase_deg,
                      "sigma_dn": args.sigma, "seed": args.seed}}


def run_pipeline(args: argparse.Namespace) -> int:
    from .._io import write_json_atomic
    from ..analysis.montecarlo import ChunkRecomputedWarning, run_monte_carlo
    from ..errors import ConfigError
    from ..geometry.camera import Camera
    from . import emit_json, warnings_to_stderr
    from ._montecarlo import _check_out

    if args.out is None:
        raise ConfigError("--pipeline needs --out DIR (the finished chunks are its results; --resume continues them)")
    _check_out(args)
    camera = Camera.from_json(args.camera) if args.camera else Camera.default()
    trial, opt = _study(args, camera)
    t0 = time.perf_counter()
    with warnings_to_stderr(ChunkRecomputedWarning):
        if args.workers is None and args.scheduler is None:
            res = run_monte_carlo(trial, opt)
        else:
            from ..analysis.distributed import close_client, make_client, run_monte_carlo_distributed

            client = make_client(args.scheduler, args.workers or 2)
            try:
                res = run_monte_carlo_distributed(trial, opt, client, progress=not args.json)
            finally:
                close_client(client)
    out = _summary(res, opt, args, camera)
    write_json_atomic(Path(args.out) / "result.json", out)
    out.update(wall_s=time.perf_counter() - t0, chunks_run=res.chunks_run, chunks_resumed=res.chunks_skipped,
               workers=args.workers, scheduler=args.scheduler, result_file=str(Path(args.out) / "result.json"))
    if args.json:
        emit_json(out)
    else:
        e = out["error_px"]
        print(f"{out['n_ok']}/{out['n']} frames ok in {out['wall_s']:.1f} s ({res.chunks_run} chunks run, "
              f"{res.chunks_skipped} resumed); error RMS row {e['row']['rms']:.4f} col {e['col']['rms']:.4f} "
              f"radius {e['radius']['rms']:.4f} px; {out['result_file']}")
    return 0
