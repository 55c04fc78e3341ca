"""Solver x front end x phase x noise grid of ``jaxlimb.pipeline.locate``, with k estimated vs fixed.

Usage::

    .venv/bin/python benchmarks/grid_study.py [--quick] [--n N] [--solvers lm,dogleg] [--phases 0,90] [--seed S]

Grid: solver in {lm, optx-lm, dogleg, paper} x front end in {gradient, scanline} x phase in
{0, 45, 90, 120} deg x noise in {2 DN read noise, + 10 DN extra (the 2015 paper's sigma = 10
grey levels)} x k in {estimated, fixed = 3 (the 2016 paper)}.  ``--n`` scenes per cell (5 by
default, 1 with ``--quick``).  Each scene is rendered once per (phase, noise, seed) on a
400x500 camera (the default field of view scaled down, as ``tests/pipeline/_scenes.py``'s
``SMALL_CAMERA``): 8-bit, 2 DN read noise + photon noise, lunar-Lambert reflectance, Gaussian
PSF 1 px, Moon of ~80 px apparent radius, centre uniform in the frame with the limb inside,
Sun angle uniform -- and reused by every solver / front end / k setting, so the grid is cheap.

``locate`` gets the camera and the Sun direction (as ``sun_hints`` of the tests).  Per cell:
centre error (distance to the projection of the body centre) and |radius error|
(``radius_px - apparent_radius_px``) p50, p90 and RMS; RMS / CRLB, with the CRLB of the
measurement's ``crlb`` field (centre: sqrt(crlb_r^2 + crlb_c^2); ratio = RMS error / RMS
bound over the successful frames); success rate (a raised ``CheckFailed`` -- including
``ConvergenceError`` -- is a failure, counted by its ``check`` name); mean iterations and
median and mean ms per frame (after a warm-up call per configuration; the gradient front
end still recompiles on frames whose pixel counts are new, which shows in the mean, not the
median).  ``rad std/CRLB`` (n > 1) separates the scatter from the sigmoid's radius bias.
Results go to ``benchmarks/results/grid_study.json`` (``grid_study_quick.json`` with ``--quick``).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

SOLVERS = ("lm", "optx-lm", "dogleg", "paper")
FRONT_ENDS = ("gradient", "scanline")
PHASES = (0.0, 45.0, 90.0, 120.0)
NOISES = {"read2": 0.0, "read2+10dn": 10.0}  # name -> extra_noise_dn
K_MODES = ("est", "fix3")
_READ_2DN = 2.0 * 20000.0 / 255.0
_RADIUS_PX = 80.0


def _setup() -> None:
    import jax

    jax.config.update("jax_enable_x64", True)


def small_camera():
    from jaxlimb.geometry.camera import Camera

    # = tests/pipeline/_scenes.py SMALL_CAMERA (f = 1403 px)
    return Camera(focal_length_mm=16.0 * 500 / 2592, rows=400, cols=500)


def render(cam, phase: float, noise: str, idx: int, seed: int):
    """(image, truth, meta) of scene ``idx`` at ``phase`` with ``noise`` (geometry shared across noises)."""
    from jaxlimb.render import RenderOptions, moon_scene, render_body

    rng = np.random.default_rng([seed, int(phase), idx])  # same geometry for both noise levels
    rng_km = math.sqrt((cam.focal_px * 1737.4 / _RADIUS_PX) ** 2 + 1737.4**2)
    m = _RADIUS_PX * 1.1 + 10
    rc = (float(rng.uniform(m, cam.rows - m)), float(rng.uniform(m, cam.cols - m)))
    sun_angle = float(rng.uniform(0, 360))
    render_seed = int(rng.integers(2**31)) + (7919 if noise != "read2" else 0)
    opts = RenderOptions(reflectance="lunar-lambert", psf_sigma_px=1.0, bit_depth=8, read_noise_e=_READ_2DN,
                         extra_noise_dn=NOISES[noise])
    img, truth = render_body(moon_scene(rng_km, phase, center_rc=rc, camera=cam, sun_angle_deg=sun_angle), cam,
                             opts, seed=render_seed)
    meta = {"phase_deg": phase, "noise": noise, "index": idx, "range_km": rng_km, "sun_angle_deg": sun_angle,
            "center_rc": [float(v) for v in truth.center_rc], "radius_px": float(truth.apparent_radius_px)}
    return img, truth, meta


def sun_hints(truth):
    from jaxlimb.imaging import Hints

    return Hints(body="moon", sun_dir_camera=tuple(float(v) for v in truth.sun_dir_cam))


def measure(img, cam, truth, hints, options) -> dict[str, Any]:
    from jaxlimb.errors import CheckFailed
    from jaxlimb.pipeline import locate

    t0 = time.perf_counter()
    try:
        m = locate(img, cam, hints, options)
    except CheckFailed as e:  # ConvergenceError is a CheckFailed
        return {"ok": False, "check": e.check, "message": str(e)[:200], "ms": 1000 * (time.perf_counter() - t0)}
    ms = 1000 * (time.perf_counter() - t0)
    rec = {"ok": True, "ms": ms, "iterations": int(m.iterations), "k": float(m.k),
           "center_err_px": float(np.hypot(*np.subtract(m.center_rc, truth.center_rc))),
           "radius_err_px": float(m.radius_px - truth.apparent_radius_px)}
    cr = m.crlb or {}
    if "center_r" in cr and "center_c" in cr:
        rec["crlb_center_px"] = float(math.hypot(cr["center_r"], cr["center_c"]))
    if "radius" in cr:
        rec["crlb_radius_px"] = float(cr["radius"])
    return rec


def _p(v: list[float], q: float) -> float:
    return float(np.percentile(v, q)) if v else float("nan")


def _rms(v: list[float]) -> float:
    return float(np.sqrt(np.mean(np.square(v)))) if v else float("nan")


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    ok = [r for r in rows if r["ok"]]
    ce = [r["center_err_px"] for r in ok]
    re_ = [abs(r["radius_err_px"]) for r in ok]
    fails: dict[str, int] = {}
    for r in rows:
        if not r["ok"]:
            fails[r["check"]] = fails.get(r["check"], 0) + 1
    cc = [r for r in ok if "crlb_center_px" in r]
    cr = [r for r in ok if "crlb_radius_px" in r]
    nan = float("nan")
    return {
        "n": len(rows), "n_ok": len(ok), "success_rate": len(ok) / len(rows) if rows else nan, "failures": fails,
        "center_p50": _p(ce, 50), "center_p90": _p(ce, 90), "center_rms": _rms(ce),
        "radius_p50": _p(re_, 50), "radius_p90": _p(re_, 90), "radius_rms": _rms(re_),
        "radius_mean_signed": float(np.mean([r["radius_err_px"] for r in ok])) if ok else nan,
        "center_rms_over_crlb": (_rms([r["center_err_px"] for r in cc]) / _rms([r["crlb_center_px"] for r in cc])
                                 if cc else nan),
        "radius_rms_over_crlb": (_rms([r["radius_err_px"] for r in cr]) / _rms([r["crlb_radius_px"] for r in cr])
                                 if cr else nan),
        "crlb_center_rms_px": _rms([r["crlb_center_px"] for r in cc]),
        "crlb_radius_rms_px": _rms([r["crlb_radius_px"] for r in cr]),
        "iterations_mean": float(np.mean([r["iterations"] for r in ok])) if ok else nan,
        "ms_mean": float(np.mean([r["ms"] for r in rows])) if rows else nan,
        "ms_median": _p([r["ms"] for r in rows], 50),
        "radius_std_over_crlb": (float(np.std([r["radius_err_px"] for r in cr])) / _rms([r["crlb_radius_px"] for r in cr])
                                 if len(cr) > 1 else nan),
    }


def _key(solver: str, fe: str, phase: float, noise: str, k: str) -> str:
    return f"{solver}|{fe}|{phase:g}|{noise}|{k}"


def _fmt_table(summary: dict[str, Any], phase: float, solvers, noises) -> list[str]:
    lines = [f"\n### phase {phase:g} deg",
             "| solver | front end | noise | k | ok | ctr p50 | ctr p90 | ctr RMS | ctr RMS/CRLB | rad p50 | rad p90 "
             "| rad RMS | rad RMS/CRLB | rad std/CRLB | iters | ms med | ms mean | failures |",
             "|" + "---|" * 18]
    for noise in noises:
        for s in solvers:
            for fe in FRONT_ENDS:
                for k in K_MODES:
                    c = summary.get(_key(s, fe, phase, noise, k))
                    if c is None:
                        continue
                    f = ",".join(f"{n}:{v}" for n, v in sorted(c["failures"].items())) or "-"
                    lines.append(
                        f"| {s} | {fe} | {noise} | {k} | {c['n_ok']}/{c['n']} | {c['center_p50']:.3f} | "
                        f"{c['center_p90']:.3f} | {c['center_rms']:.3f} | {c['center_rms_over_crlb']:.2f} | "
                        f"{c['radius_p50']:.3f} | {c['radius_p90']:.3f} | {c['radius_rms']:.3f} | "
                        f"{c['radius_rms_over_crlb']:.2f} | {c['radius_std_over_crlb']:.2f} | {c['iterations_mean']:.1f} | "
                        f"{c['ms_median']:.0f} | {c['ms_mean']:.0f} | {f} |")
    return lines


def best_per_phase(summary: dict[str, Any], phases, noises) -> dict[str, Any]:
    """Per (phase, noise): the lowest centre RMS among fully successful configurations, and every
    configuration within 1 % (+ 1e-4 px) of it (``tied``: the solvers usually reach the same minimum)."""
    out = {}
    for ph in phases:
        for noise in noises:
            cands = sorted((c["center_rms"], key) for key, c in summary.items()
                           if key.split("|")[2] == f"{ph:g}" and key.split("|")[3] == noise
                           and c["n_ok"] == c["n"] and math.isfinite(c["center_rms"]))
            if cands:
                rms, key = cands[0]
                tied = [k for r, k in cands if r <= 1.01 * rms + 1e-4]
                out[f"{ph:g}|{noise}"] = {"config": key, "center_rms": rms, "radius_rms": summary[key]["radius_rms"],
                                          "tied": tied}
    return out


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1 scene per cell")
    ap.add_argument("--n", type=int, default=None, help="scenes per cell (default 5, 1 with --quick)")
    ap.add_argument("--solvers", default=",".join(SOLVERS), help="comma-separated solver names")
    ap.add_argument("--phases", default=",".join(f"{p:g}" for p in PHASES), help="comma-separated phases (deg)")
    ap.add_argument("--noises", default=",".join(NOISES), help=f"comma-separated subset of {list(NOISES)}")
    ap.add_argument("--seed", type=int, default=2026)
    args = ap.parse_args(argv)
    _setup()
    from _common import environment, save

    from jaxlimb.pipeline import LocateOptions

    n = args.n if args.n is not None else (1 if args.quick else 5)
    solvers = [s.strip() for s in args.solvers.split(",") if s.strip()]
    phases = [float(p) for p in args.phases.split(",") if p.strip()]
    noises = [s.strip() for s in args.noises.split(",") if s.strip()]
    for nz in noises:
        if nz not in NOISES:
            ap.error(f"unknown noise {nz!r}; choose from {list(NOISES)}")
    cam = small_camera()
    configs = [(s, fe, k) for s in solvers for fe in FRONT_ENDS for k in K_MODES]
    options = {c: LocateOptions(solver=c[0], front_end=c[1], estimate_k=(c[2] == "est"))
               for c in configs}

    t_all = time.perf_counter()
    # warm-up (JAX compilation) per configuration on one frame, excluded from ms per frame
    img0, tr0, _ = render(cam, 45.0, "read2", 10_000, args.seed)
    warm = {}
    for c in configs:
        t0 = time.perf_counter()
        measure(img0, cam, tr0, sun_hints(tr0), options[c])
        warm["|".join(c)] = time.perf_counter() - t0
    print(f"warm-up (compilation) {sum(warm.values()):.1f} s over {len(configs)} configurations")

    rows: dict[str, list[dict[str, Any]]] = {}
    for ph in phases:
        for noise in noises:
            for i in range(n):
                img, truth, meta = render(cam, ph, noise, i, args.seed)
                h = sun_hints(truth)
                for c in configs:
                    rec = dict(meta, solver=c[0], front_end=c[1], k_mode=c[2])
                    rec.update(measure(img, cam, truth, h, options[c]))
                    rows.setdefault(_key(c[0], c[1], ph, noise, c[2]), []).append(rec)
        print(f"  phase {ph:g} done ({time.perf_counter() - t_all:.0f} s)", flush=True)
    summary = {key: summarise(r) for key, r in rows.items()}
    for ph in phases:
        print("\n".join(_fmt_table(summary, ph, solvers, noises)))
    best = best_per_phase(summary, phases, noises)
    print("\nbest (lowest centre RMS, all frames successful) per phase / noise:")
    for k, v in best.items():
        tied = sorted({"|".join(t.split("|")[i] for i in (0, 1, 4)) for t in v["tied"]})
        print(f"  {k}: centre RMS {v['center_rms']:.3f} px, radius RMS {v['radius_rms']:.3f} px -- "
              f"{len(tied)} tied (solver|front end|k): {', '.join(tied)}")
    out = {"environment": environment(), "quick": bool(args.quick), "n_per_cell": n, "seed": args.seed,
           "grid": {"solvers": solvers, "front_ends": list(FRONT_ENDS), "phases_deg": phases, "noises": noises,
                    "noise_extra_dn": {k: NOISES[k] for k in noises}, "k_modes": list(K_MODES), "k_fixed": 3.0,
                    "camera": "400x500, f=16*500/2592 mm (tests SMALL_CAMERA)", "radius_px": _RADIUS_PX,
                    "psf_sigma_px": 1.0, "reflectance": "lunar-lambert"},
           "warmup_s": warm, "summary": summary, "best": best, "frames": rows,
           "wall_time_s": time.perf_counter() - t_all}
    path = save("grid_study_quick" if args.quick else "grid_study", out)
    print(f"\nwrote {path}  ({out['wall_time_s']:.0f} s)")
    return out


if __name__ == "__main__":
    main()
