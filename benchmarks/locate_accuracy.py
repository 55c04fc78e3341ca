"""Accuracy and speed of ``jaxlimb.pipeline.locate`` on rendered Moons, against a naive OpenCV baseline.

Usage::

    .venv/bin/python benchmarks/locate_accuracy.py [--quick] [--n N] [--seed S]

Scenes (default 1944x2592 camera, 16 mm / 2.2 um; 8-bit, 2 DN read noise + photon noise;
lunar-Lambert reflectance; Gaussian PSF sigma uniform in [0.6, 1.2] px; Moon at 60 000 -
380 000 km, log-uniform; seeded): five categories of ``--n`` scenes each (20 by default, 5 with
``--quick``):

* ``gibbous``  -- phase uniform in [0, 90] deg, centre anywhere with the limb in the frame;
* ``crescent120`` -- phase 120 deg;
* ``thin``     -- phase 150 deg (lit width 13 % of the radius), 60 000 - 150 000 km;
* ``cropped``  -- phase in [0, 60] deg, centre beyond a frame edge by up to half a radius;
* ``stars``    -- as ``gibbous`` plus 50 stars and 100 hot pixels.

``locate`` gets the camera and the hints a navigation filter has (body, Sun direction, a range
prior 5 % off).  Errors: centre = distance between ``center_rc`` and the projection of the body
centre (truth); radius = ``radius_px - apparent_radius_px`` (``f tan(alpha)``); a raised check
counts as a failure.  The baseline (Otsu threshold -> largest external contour ->
``cv2.fitEllipse``; centre = ellipse centre, radius = mean semi-axis) runs on the same frames.

Limb-bias study: at zero phase (centred Moon, 5 ranges x 3 PSF sigmas) the radius bias of the
sigmoid is measured and a correction ``b = c0 + c1 s + c2 R + c3 s R`` is fitted by least
squares, with ``s = 1.7 / k`` the edge sigma the fit itself estimates and ``R`` the fitted
radius -- both known at run time, so the correction needs no outside knowledge of the PSF.
The table reports the radius error of every category with and without it.

Timing: the first ``locate`` call on a 1944x2592 frame (includes JAX compilation) and the
median of 10 calls after warm-up, for the sigmoid and the default (physical profile), with the
Moon at 150 000 km (R 84 px) and 60 000 km (R 211 px, the largest: the most pixels).  Results
go to ``benchmarks/results/locate_accuracy.json`` with the git SHA and versions.
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

CATEGORIES = ("gibbous", "crescent120", "thin", "cropped", "stars")
_READ_2DN = 2.0 * 20000.0 / 255.0


def _setup() -> None:
    import jax

    jax.config.update("jax_enable_x64", True)


def _render(rng: np.random.Generator, category: str, idx: int):
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.render import RenderOptions, moon_scene, render_body

    cam = Camera.default()
    lo, hi = (60000.0, 150000.0) if category == "thin" else (60000.0, 380000.0)
    rng_km = float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
    R = cam.focal_px * 1737.4 / math.sqrt(rng_km**2 - 1737.4**2)
    phase = {"gibbous": rng.uniform(0, 90), "stars": rng.uniform(0, 90), "crescent120": 120.0, "thin": 150.0,
             "cropped": rng.uniform(0, 60)}[category]
    m = R * 1.1 + 10
    if category == "cropped":
        side = int(rng.integers(4))
        out = rng.uniform(0.0, 0.5) * R
        along = (rng.uniform(m, cam.rows - m), rng.uniform(m, cam.cols - m))
        rc = [(-out, along[1]), (cam.rows - 1 + out, along[1]), (along[0], -out), (along[0], cam.cols - 1 + out)][side]
        # the lit side faces into the frame half of the time
        sun_angle = float(rng.uniform(0, 360))
    else:
        rc = (rng.uniform(m, cam.rows - m), rng.uniform(m, cam.cols - m))
        sun_angle = float(rng.uniform(0, 360))
    psf = float(rng.uniform(0.6, 1.2))
    n_stars, n_hot = (50, 100) if category == "stars" else (0, 0)
    opts = RenderOptions(reflectance="lunar-lambert", psf_sigma_px=psf, bit_depth=8, read_noise_e=_READ_2DN,
                         n_stars=n_stars, n_hot_pixels=n_hot)
    sc = moon_scene(rng_km, phase, center_rc=rc, camera=cam, sun_angle_deg=sun_angle)
    img, truth = render_body(sc, cam, opts, seed=int(rng.integers(2**31)))
    meta = {"category": category, "index": idx, "range_km": rng_km, "phase_deg": float(phase), "psf_sigma_px": psf,
            "center_rc": [float(v) for v in truth.center_rc], "radius_px": float(truth.apparent_radius_px),
            "sun_angle_deg": sun_angle, "crop": truth.crop}
    return cam, img, truth, meta


def opencv_baseline(image: np.ndarray) -> tuple[tuple[float, float], float] | None:
    """Otsu threshold -> largest external contour -> ``cv2.fitEllipse``: (centre (row, col), mean semi-axis)."""
    import cv2

    a = np.asarray(image)
    if a.dtype != np.uint8:
        a = cv2.normalize(a.astype(np.float64), None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    _, bw = cv2.threshold(a, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    cs, _ = cv2.findContours(bw, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not cs:
        return None
    c = max(cs, key=cv2.contourArea)
    if len(c) < 5:
        return None
    (x, y), (w, h), _ = cv2.fitEllipse(c)
    return (float(y), float(x)), 0.25 * float(w + h)


def _hints(truth, rng: np.random.Generator):
    from jaxlimb.imaging import Hints

    return Hints(body="moon", sun_dir_camera=tuple(float(v) for v in truth.sun_dir_cam),
                 range_prior_km=float(truth.range_km * (1.0 + 0.05 * rng.standard_normal())))


def _measure(img, cam, truth, hints, options, prefix: str, rec: dict[str, Any]) -> None:
    from jaxlimb.errors import JaxlimbError
    from jaxlimb.pipeline import locate

    t0 = time.perf_counter()
    try:
        m = locate(img, cam, hints, options)
        rec.update({f"{prefix}ok": True,
                    f"{prefix}center_err_px": float(np.hypot(*np.subtract(m.center_rc, truth.center_rc))),
                    f"{prefix}radius_err_px": float(m.radius_px - truth.apparent_radius_px), f"{prefix}k": float(m.k),
                    f"{prefix}fitted_radius_px": float(m.radius_px),
                    f"{prefix}range_err_frac": float(m.range_km / truth.range_km - 1),
                    f"{prefix}sigma_center_px": float(math.sqrt(m.covariance["center_r"]["center_r"]))})
    except JaxlimbError as e:
        rec.update({f"{prefix}ok": False, f"{prefix}error": e.check, f"{prefix}message": str(e)})
    rec[f"{prefix}time_s"] = time.perf_counter() - t0


def run_category(category: str, n: int, seed: int) -> list[dict[str, Any]]:
    from jaxlimb.pipeline import LocateOptions

    rng = np.random.default_rng([seed, CATEGORIES.index(category)])
    rows = []
    for i in range(n):
        cam, img, truth, meta = _render(rng, category, i)
        rec = dict(meta)
        h = _hints(truth, rng)
        _measure(img, cam, truth, h, LocateOptions(profile="sigmoid"), "", rec)
        _measure(img, cam, truth, h, LocateOptions(), "phys_", rec)  # default: profile="auto"
        b = opencv_baseline(img)
        if b is None:
            rec.update(cv_ok=False)
        else:
            rec.update(cv_ok=True, cv_center_err_px=float(np.hypot(*np.subtract(b[0], truth.center_rc))),
                       cv_radius_err_px=float(b[1] - truth.apparent_radius_px))
        rows.append(rec)
    return rows


# ----------------------------------------------------------------------------- limb bias
def bias_study(seed: int, quick: bool) -> dict[str, Any]:
    """Radius bias at zero phase vs range and PSF, and the fitted correction (module docstring)."""
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.pipeline import LocateOptions, locate
    from jaxlimb.render import RenderOptions, moon_scene, render_body

    cam = Camera.default()
    ranges = (60000.0, 150000.0, 380000.0) if quick else (60000.0, 100000.0, 150000.0, 250000.0, 380000.0)
    psfs = (0.6, 0.9, 1.2)
    pts = []
    rng = np.random.default_rng([seed, 99])
    for D in ranges:
        for s in psfs:
            opts = RenderOptions(reflectance="lunar-lambert", psf_sigma_px=s, bit_depth=8, read_noise_e=_READ_2DN)
            img, tr = render_body(moon_scene(D, 0.0, camera=cam), cam, opts, seed=int(rng.integers(2**31)))
            h = _hints(tr, rng)
            m = locate(img, cam, h, LocateOptions(profile="sigmoid"))
            mp = locate(img, cam, h)  # default: the physical profile (the Sun direction is in the hints)
            pts.append({"range_km": D, "psf_sigma_px": s, "radius_px": float(m.radius_px), "k": float(m.k),
                        "bias_px": float(m.radius_px - tr.apparent_radius_px),
                        "phys_bias_px": float(mp.radius_px - tr.apparent_radius_px),
                        "phys_psf_sigma_px": float(mp.extras["profile"]["psf_sigma_px"])})
    coef = fit_bias_model(pts)
    res = [p["bias_px"] - bias_correction(coef, p["radius_px"], p["k"]) for p in pts]
    return {"points": pts, "coefficients": coef, "residual_rms_px": float(np.sqrt(np.mean(np.square(res))))}


def _features(radius: float, k: float) -> np.ndarray:
    s = 1.7 / k
    return np.array([1.0, s, radius, s * radius])


def fit_bias_model(points: list[dict[str, Any]]) -> list[float]:
    A = np.stack([_features(p["radius_px"], p["k"]) for p in points])
    b = np.array([p["bias_px"] for p in points])
    coef, *_ = np.linalg.lstsq(A, b, rcond=None)
    return [float(c) for c in coef]


def bias_correction(coef: list[float], radius: float, k: float) -> float:
    return float(_features(radius, k) @ np.asarray(coef))


# ----------------------------------------------------------------------------- timing
def timing(seed: int, n_warm: int = 10, profile: str = "sigmoid", range_km: float = 150000.0) -> dict[str, Any]:
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.pipeline import LocateOptions, locate
    from jaxlimb.render import RenderOptions, moon_scene, render_body

    cam = Camera.default()
    opts = RenderOptions(reflectance="lunar-lambert", psf_sigma_px=1.0, bit_depth=8, read_noise_e=_READ_2DN)
    img, tr = render_body(moon_scene(range_km, 30.0, center_rc=(700.0, 1500.0), camera=cam, sun_angle_deg=40),
                          cam, opts, seed=seed)
    rng = np.random.default_rng(seed)
    h = _hints(tr, rng)
    lo = LocateOptions(profile=profile)
    t0 = time.perf_counter()
    locate(img, cam, h, lo)
    first = time.perf_counter() - t0
    ts = []
    parts = []
    for _ in range(n_warm):
        t0 = time.perf_counter()
        m = locate(img, cam, h, lo)
        ts.append(time.perf_counter() - t0)
        parts.append(m.extras["timings_s"])
    med = {k: float(np.median([p[k] for p in parts])) for k in parts[0]}
    return {"profile": profile, "range_km": range_km, "radius_px": float(tr.apparent_radius_px), "n_pixels": m.n_pixels,
            "first_call_s": first, "median_s": float(np.median(ts)), "min_s": float(np.min(ts)), "parts_median_s": med}


# ----------------------------------------------------------------------------- report
def _p(v: list[float], q: float) -> float:
    return float(np.percentile(v, q)) if v else float("nan")


def summarise(rows: list[dict[str, Any]], coef: list[float] | None) -> dict[str, Any]:
    ok = [r for r in rows if r.get("ok")]
    ce = [r["center_err_px"] for r in ok]
    re_ = [abs(r["radius_err_px"]) for r in ok]
    out = {"n": len(rows), "n_ok": len(ok), "failures": sorted({r.get("error", "") for r in rows if not r.get("ok")} - {""}),
           "center_p50": _p(ce, 50), "center_p90": _p(ce, 90), "center_max": max(ce) if ce else float("nan"),
           "radius_p50": _p(re_, 50), "radius_p90": _p(re_, 90), "radius_mean_signed": float(np.mean([r["radius_err_px"] for r in ok])) if ok else float("nan"),
           "time_median_s": _p([r["time_s"] for r in rows], 50)}
    if coef is not None and ok:
        rc = [abs(r["radius_err_px"] - bias_correction(coef, r["fitted_radius_px"], r["k"])) for r in ok]
        out.update(radius_corr_p50=_p(rc, 50), radius_corr_p90=_p(rc, 90))
    okp = [r for r in rows if r.get("phys_ok")]
    pc = [r["phys_center_err_px"] for r in okp]
    pr = [abs(r["phys_radius_err_px"]) for r in okp]
    out.update(phys_n_ok=len(okp), phys_center_p50=_p(pc, 50), phys_center_p90=_p(pc, 90),
               phys_center_max=max(pc) if pc else float("nan"), phys_radius_p90=_p(pr, 90),
               phys_radius_mean_signed=float(np.mean([r["phys_radius_err_px"] for r in okp])) if okp else float("nan"),
               phys_time_median_s=_p([r["phys_time_s"] for r in rows], 50))
    cv = [r for r in rows if r.get("cv_ok")]
    cvc = [r["cv_center_err_px"] for r in cv]
    out.update(cv_n_ok=len(cv), cv_center_p50=_p(cvc, 50), cv_center_p90=_p(cvc, 90),
               cv_center_max=max(cvc) if cvc else float("nan"),
               cv_radius_p90=_p([abs(r["cv_radius_err_px"]) for r in cv], 90),
               cv_gross_failures=int(sum(1 for r in rows if not r.get("cv_ok") or r["cv_center_err_px"] > 5.0)))
    return out


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="5 scenes per category, a smaller bias grid")
    ap.add_argument("--n", type=int, default=None, help="scenes per category (default 20, 5 with --quick)")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--skip-timing", action="store_true", help="accuracy only (timings need a quiet machine)")
    ap.add_argument("--timing-only", action="store_true",
                    help="only the timing; merged into the existing results file")
    args = ap.parse_args(argv)
    _setup()
    from _common import environment, save

    n = args.n if args.n is not None else (5 if args.quick else 20)
    t_all = time.perf_counter()
    tim = {} if args.skip_timing else {f"{p}@{D / 1000:.0f}000km": timing(args.seed, 5 if args.quick else 10, p, D)
                                       for D in (150000.0, 60000.0) for p in ("sigmoid", "auto")}
    for p, t in tim.items():
        print(f"locate ({p}, R {t['radius_px']:.0f} px, {t['n_pixels']} px fitted) on 1944x2592: first call "
              f"{t['first_call_s']:.2f} s (compilation), "
              f"after warm-up median {1000 * t['median_s']:.0f} ms (min {1000 * t['min_s']:.0f} ms); "
              f"parts {', '.join(f'{k} {1000 * v:.0f} ms' for k, v in t['parts_median_s'].items())}")
    if args.timing_only:
        import json

        path = Path(__file__).resolve().parent / "results" / "locate_accuracy.json"
        old = json.loads(path.read_text()) if path.exists() else {}
        old.update(timing=tim, timing_environment=environment())
        print(f"wrote {save('locate_accuracy', old)}")
        return old
    bias = bias_study(args.seed, args.quick)
    print("\nlimb bias at zero phase (radius_px - truth):")
    print(f"{'range km':>9} {'psf':>5} {'R px':>7} {'k':>6} {'bias px':>8} {'phys bias':>9} {'phys psf':>8}")
    for p in bias["points"]:
        print(f"{p['range_km']:9.0f} {p['psf_sigma_px']:5.2f} {p['radius_px']:7.2f} {p['k']:6.3f} {p['bias_px']:8.4f} "
              f"{p['phys_bias_px']:9.4f} {p['phys_psf_sigma_px']:8.3f}")
    print(f"correction b = c0 + c1 s + c2 R + c3 s R (s = 1.7/k): c = {np.round(bias['coefficients'], 5).tolist()}, "
          f"residual rms {bias['residual_rms_px']:.4f} px")
    coef = bias["coefficients"]
    results: dict[str, Any] = {}
    rows_all: dict[str, list[dict[str, Any]]] = {}
    for cat in CATEGORIES:
        rows = run_category(cat, n, args.seed)
        rows_all[cat] = rows
        results[cat] = summarise(rows, coef)
    print("\nsigmoid | rad p90c = with the calibrated radius correction | default (auto: physical lunar-Lambert profile, "
          "L estimated) | OpenCV")
    hdr = (f"{'category':12} {'ok':>5} {'ctr p50':>7} {'ctr p90':>7} {'ctr max':>7} {'rad p90':>7} {'radp90c':>7} "
           f"| {'ok':>5} {'ctr p50':>7} {'ctr p90':>7} {'ctr max':>7} {'rad p90':>7} "
           f"| {'ok':>5} {'ctr p50':>7} {'ctr p90':>7} {'rad p90':>7} {'gross':>5}")
    print(hdr)
    for cat in CATEGORIES:
        s = results[cat]
        print(f"{cat:12} {s['n_ok']:>2}/{s['n']:<2} {s['center_p50']:7.3f} {s['center_p90']:7.3f} {s['center_max']:7.3f} "
              f"{s['radius_p90']:7.3f} {s.get('radius_corr_p90', float('nan')):7.3f} "
              f"| {s['phys_n_ok']:>2}/{s['n']:<2} {s['phys_center_p50']:7.3f} {s['phys_center_p90']:7.3f} "
              f"{s['phys_center_max']:7.3f} {s['phys_radius_p90']:7.3f} "
              f"| {s['cv_n_ok']:>2}/{s['n']:<2} {s['cv_center_p50']:7.2f} {s['cv_center_p90']:7.2f} "
              f"{s['cv_radius_p90']:7.2f} {s['cv_gross_failures']:5d}")
        for r in rows_all[cat]:
            for pre in ("", "phys_"):
                if not r.get(f"{pre}ok"):
                    print(f"    {pre or 'sigmoid_'}failure #{r['index']}: {r[pre + 'error']}: {r[pre + 'message'][:140]}")
    out = {"environment": environment(), "quick": bool(args.quick), "n_per_category": n, "seed": args.seed,
           "timing": tim, "bias_study": bias, "summary": results, "scenes": rows_all,
           "wall_time_s": time.perf_counter() - t_all}
    path = save("locate_accuracy", out)
    print(f"\nwrote {path}  ({out['wall_time_s']:.0f} s)")
    return out


if __name__ == "__main__":
    main()
