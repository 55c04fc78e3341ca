r"""Christian--Robinson horizon navigation vs the sigmoid limb fit, on identical inputs.

For rendered Moon and Earth frames (full, gibbous and crescent phases; whole lit limb and a
short +-30 deg arc) the gradient front end (:func:`jaxlimb.imaging.gradient_front_end`) finds the
limb points once per noisy frame; the *same* points are given to

* ``CR``: :func:`jaxlimb.geometry.horizon.horizon_from_pixels` (non-iterative, Cholesky
  whitening, LS; Christian & Robinson 2016), known radii and ``R_body_to_camera``;

and the same frame + front end to the sigmoid routes:

* ``ESF``: the paper's elliptical sigmoid (flat top, ``interior_ramp=False``, logistic kernel)
  with ``rho, theta`` fixed from the prior geometry, then the centre offset and range iteration
  (:func:`jaxlimb.pipeline.locate`, the ellipsoid strategy);
* ``ESF+ramp``: the same with the edge model of
  :func:`jaxlimb.models.ellipse_ramp.ellipse_ramp_intensity` (Gaussian kernel, interior ramp, level
  varying along the limb);
* ``profile`` (the default of ``locate``): ``ESF+ramp``, then the same pixels refitted with the
  physical lunar-Lambert limb profile (:data:`jaxlimb.models.lunar_lambert.LIMB_PROFILE`, ``L``
  estimated; ``LocateOptions(profile="auto")``), Earth only;
* ``CSF`` (Moon only, whole limb): the Moon pipeline, :func:`jaxlimb.pipeline.locate.locate` with
  its defaults (the circular sigmoid, then the physical limb profile; it runs its own front end,
  so it has no short-arc row).

The short-arc rows keep only the front-end points within 30 deg of the lit direction for CR
(``arc_margin_deg = 60`` for the sigmoid routes, the same +-30 deg of limb).  Reported per
(frame, arc, method): centre-of-body image error (bias = |mean error| and RMS, px), range error
(mean and RMS, %), the number of failures and the median time per frame (ms) of the estimator
alone (the shared front end is timed separately).  Noise: the renderer's 12-bit sensor
(photon + read noise), seeded per realisation; truth from the renderer (exact geometry).

Run::

    .venv/bin/python benchmarks/horizon_vs_sigmoid.py --quick   # 3 noise realisations per frame
    .venv/bin/python benchmarks/horizon_vs_sigmoid.py           # 20

Writes ``benchmarks/results/horizon_vs_sigmoid.json`` (git SHA, versions, seeds, all numbers).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Frame:
    """A rendered geometry (camera frame construction of :mod:`jaxlimb.render.scene`)."""

    name: str
    body: str
    range_km: float
    phase_deg: float
    focal_mm: float
    size_px: int
    latitude_deg: float = 30.0


FRAMES = (
    Frame("moon-full", "moon", 60000.0, 8.0, 16.0, 520),
    Frame("moon-gibbous", "moon", 60000.0, 45.0, 16.0, 520),
    Frame("moon-crescent", "moon", 60000.0, 120.0, 16.0, 520),
    Frame("earth-380k-full", "earth", 380000.0, 8.0, 16.0, 300),
    Frame("earth-380k-gibbous", "earth", 380000.0, 45.0, 16.0, 300),
    Frame("earth-380k-crescent", "earth", 380000.0, 120.0, 16.0, 300),
    Frame("earth-40k-gibbous", "earth", 40000.0, 45.0, 8.0, 1300),
)


def _noisy():
    """``noisy(frame_e, seed, sensor)`` of ``benchmarks/navigate_e2e.py`` (one sensor model for both)."""
    name = "jaxlimb_bench_navigate_e2e"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name("navigate_e2e.py"))
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return sys.modules[name].noisy


def render(fr: Frame, reflectance: str = "lommel-seeliger"):
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.render import RenderOptions, earth_scene, moon_scene, render_body

    cam = Camera(focal_length_mm=fr.focal_mm, rows=fr.size_px, cols=fr.size_px)
    c = (cam.rows / 2 - 7.3, cam.cols / 2 + 11.9)
    if fr.body == "moon":
        sc = moon_scene(fr.range_km, fr.phase_deg, center_rc=c, camera=cam, sun_angle_deg=30.0)
    else:
        sc = earth_scene(fr.range_km, fr.latitude_deg, fr.phase_deg, center_rc=c, camera=cam, sun_angle_deg=30.0,
                         north_angle_deg=80.0)
    frame, truth = render_body(sc, cam, RenderOptions(reflectance=reflectance, noise=False, bit_depth=None), seed=0)
    return cam, sc, frame, truth


def _hints(fr: Frame, sc, truth) -> dict[str, Any]:
    h = {"body": fr.body, "range_prior_km": 1.01 * truth.range_km, "sun_dir_camera": list(truth.sun_dir_cam),
         "R_body_to_camera": np.asarray(sc.R_body_to_camera).tolist()}
    if fr.body == "moon":
        h["body_radii_km"] = list(sc.radii)
    return h


def _short(points: np.ndarray, center, lit_dir, half_deg: float) -> np.ndarray:
    if lit_dir is None:
        return points
    v = points - np.asarray(center)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return points[v @ np.asarray(lit_dir) >= math.cos(math.radians(half_deg))]


def run_frame(fr: Frame, n_noise: int, seed: int, reflectance: str = "lommel-seeliger",
              only: tuple[str, ...] = ()) -> list[dict[str, Any]]:
    from jaxlimb.geometry.horizon import horizon_from_pixels
    from jaxlimb.imaging import Hints, gradient_front_end
    from jaxlimb.pipeline import LocateOptions, locate as locate_any
    from jaxlimb.pipeline import EllipsoidOptions

    noisy = _noisy()
    cam, sc, frame, truth = render(fr, reflectance)
    hints = Hints.from_dict(_hints(fr, sc, truth))
    methods = ["CR", "ESF", "ESF+ramp"] + (["CSF"] if fr.body == "moon" else ["profile"])
    if only:
        methods = [m for m in methods if m in only]
    rows: dict[tuple[str, str], dict[str, list]] = {}
    t_fe = []
    for k in range(n_noise):
        img = noisy(frame, seed + k, "12bit")
        t0 = time.perf_counter()
        cand = gradient_front_end(img, hints=hints, camera=cam)
        t_fe.append(time.perf_counter() - t0)
        for arc in ("full", "short"):
            for m in methods:
                if m == "CSF" and arc == "short":
                    continue  # the Moon pipeline has no arc option
                rec = rows.setdefault((arc, m), {"dc": [], "dr": [], "t": [], "fail": []})
                try:
                    t1 = time.perf_counter()
                    if m == "CR":
                        pts = cand.points_rc if arc == "full" else _short(cand.points_rc, cand.center_rc, cand.lit_direction, 30.0)
                        sol = horizon_from_pixels(cam, pts, sc.radii, sc.R_body_to_camera)
                        t_est = time.perf_counter() - t1
                        c_rc = cam.project(sol.body_center_camera_km)
                        rng = sol.range_km
                    elif m == "CSF":
                        from jaxlimb.pipeline.locate import locate

                        meas = locate(img, cam, hints, None)
                        t_est = time.perf_counter() - t1 - meas.extras.get("timings_s", {}).get("front_end", 0.0)
                        c_rc, rng = meas.center_rc, meas.range_km
                    else:
                        eo = EllipsoidOptions(interior_ramp=(m != "ESF"), arc_margin_deg=60.0 if arc == "short" else 30.0,
                                              band_px=6.0 if m == "ESF" else 4.0)
                        opt = LocateOptions(ellipsoid=eo, profile="auto" if m == "profile" else "sigmoid")
                        meas = locate_any(img, cam, hints, opt)
                        t_est = time.perf_counter() - t1 - t_fe[-1]  # locate reruns the same front end
                        c_rc, rng = meas.center_rc, meas.range_km
                    rec["dc"].append(np.subtract(c_rc, truth.center_rc).tolist())
                    rec["dr"].append(100.0 * (rng / truth.range_km - 1.0))
                    rec["t"].append(max(t_est, 0.0))
                except Exception as e:  # counted in the table, never hidden
                    rec["fail"].append(f"{type(e).__name__}: {e}")
    out = []
    for (arc, m), rec in rows.items():
        dc = np.asarray(rec["dc"])
        dr = np.asarray(rec["dr"])
        n = len(dr)
        out.append({
            "frame": fr.name, "reflectance": reflectance, "body": fr.body, "phase_deg": fr.phase_deg, "range_km": fr.range_km, "arc": arc,
            "method": m, "n_ok": n, "n_fail": len(rec["fail"]), "failures": rec["fail"][:3],
            "center_bias_px": float(np.linalg.norm(dc.mean(0))) if n else None,
            "center_rms_px": float(np.sqrt((dc**2).sum(1).mean())) if n else None,
            "range_bias_pct": float(dr.mean()) if n else None,
            "range_rms_pct": float(np.sqrt((dr**2).mean())) if n else None,
            "median_ms": 1e3 * float(np.median(rec["t"])) if n else None,
            "front_end_median_ms": 1e3 * float(np.median(t_fe)),
            "n_limb_points": int(cand.n_points),
        })
    return out


def table(rows: list[dict[str, Any]]) -> str:
    hdr = (f"{'frame':20s} {'arc':5s} {'method':9s} {'ok':>3s} {'fail':>4s} {'c bias px':>9s} {'c rms px':>8s} "
           f"{'R bias %':>9s} {'R rms %':>8s} {'ms':>7s}")
    lines = [hdr, "-" * len(hdr)]
    f = lambda v, w, p: f"{v:{w}.{p}f}" if v is not None else " " * (w - 3) + "n/a"  # noqa: E731
    for r in rows:
        lines.append(
            f"{r['frame']:20s} {r['arc']:5s} {r['method']:9s} {r['n_ok']:3d} {r['n_fail']:4d} {f(r['center_bias_px'], 9, 3)} "
            f"{f(r['center_rms_px'], 8, 3)} {f(r['range_bias_pct'], 9, 4)} {f(r['range_rms_pct'], 8, 4)} {f(r['median_ms'], 7, 1)}"
        )
    return "\n".join(lines)


def _meta(seed: int) -> dict[str, Any]:
    from _common import environment

    return {**environment(), "seed": seed, "sensor": "12bit (photon + read noise)"}


def main(argv: list[str] | None = None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 noise realisations per frame")
    ap.add_argument("--runs", type=int, default=20, help="noise realisations per frame (default 20)")
    ap.add_argument("--seed", type=int, default=4242)
    ap.add_argument("--frames", default=None, help="comma-separated frame names (default all)")
    ap.add_argument("--reflectance", default="lommel-seeliger",
                    help="renderer photometric model (default lommel-seeliger; lambert is closer to the Earth)")
    ap.add_argument("--out", default=None, help="default results/horizon_vs_sigmoid[_REFLECTANCE].json")
    ap.add_argument("--methods", default=None, help="comma-separated subset of CR,ESF,ESF+ramp,profile,CSF (default all)")
    args = ap.parse_args(argv)
    only = tuple(args.methods.split(",")) if args.methods else ()
    n = 3 if args.quick else args.runs
    frames = [f for f in FRAMES if args.frames is None or f.name in args.frames.split(",")]
    rows: list[dict[str, Any]] = []
    for i, fr in enumerate(frames):
        rows += run_frame(fr, n, args.seed + 100 * i, args.reflectance, only)
        print(f"done {fr.name}", file=sys.stderr)
    print(table(rows))
    suffix = "" if args.reflectance == "lommel-seeliger" else "_" + args.reflectance
    p = Path(args.out) if args.out else Path(__file__).parent / "results" / f"horizon_vs_sigmoid{suffix}.json"
    p.parent.mkdir(parents=True, exist_ok=True)
    meta = _meta(args.seed) | {"reflectance": args.reflectance}
    p.write_text(json.dumps({"meta": meta, "runs_per_frame": n, "rows": rows}, indent=1))
    print(f"wrote {p}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
