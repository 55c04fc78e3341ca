"""Limb arcs of a body larger than the frame (close approach): accuracy and honesty of the covariance.

Rendered Moons (``jaxlimb.render``, lunar-Lambert, PSF 1 px, 8 bit, 2 DN read noise) of apparent
radius ~330 px in a 400x500 frame (half-diagonal 320 px) with the centre outside the frame, so that
21-27 % of the limb is in the frame; phase 30 deg with the lit limb toward the visible arc.  Hints:
the Moon, the Sun direction and a range prior 1 % off (the expected disc exceeds the frame, so
``locate`` measures the arc: :func:`jaxlimb.pipeline.sphere.predicted.PredictedLimbSphere`).  Per geometry, a
small Monte Carlo over noise seeds: centre error (px) against the render's truth, its scatter
against the reported 1-sigma.

Run: ``python benchmarks/limb_arc.py [--n 8]`` -> ``benchmarks/results/limb_arc.json``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from _common import environment, save  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "pipeline"))
from _scenes import SMALL_CAMERA, scene  # noqa: E402

from jaxlimb.imaging import Hints  # noqa: E402
from jaxlimb.pipeline import locate  # noqa: E402

RANGE_KM = 7386.0  # apparent radius ~330 px with f = 1403 px
#: (body-centre image, Sun angle in the image: the lit limb faces the visible arc)
GEOMETRIES = (((-40.0, 250.0), -90.0), ((420.0, 250.0), 90.0), ((200.0, -30.0), 0.0), ((-40.0, -40.0), -45.0))


def _fraction_in_frame(center_rc, radius: float) -> float:
    t = np.linspace(0, 2 * np.pi, 7200, endpoint=False)
    r, c = center_rc[0] + radius * np.sin(t), center_rc[1] + radius * np.cos(t)
    return float(np.mean((r >= 0) & (r <= SMALL_CAMERA.rows - 1) & (c >= 0) & (c <= SMALL_CAMERA.cols - 1)))


def _run(center_rc, sun_angle: float, seed: int) -> dict:
    img, truth = scene(RANGE_KM, 30.0, center_rc, sun_angle_deg=sun_angle, seed=seed)
    hints = Hints(body="moon", range_prior_km=RANGE_KM * 1.01, sun_dir_camera=tuple(float(v) for v in truth.sun_dir_cam))
    t0 = time.perf_counter()
    m = locate(img, SMALL_CAMERA, hints)
    cov = m.covariance
    return {
        "seed": seed, "error_rc": [m.center_rc[0] - truth.center_rc[0], m.center_rc[1] - truth.center_rc[1]],
        "sigma_rc": [math.sqrt(cov["center_r"]["center_r"]), math.sqrt(cov["center_c"]["center_c"])],
        "sigma_pixel_independent_rc": m.extras["sigma_center_pixel_independent_px"],
        "range_error_frac": m.range_km / truth.range_km - 1.0, "seconds": time.perf_counter() - t0,
        "fraction_in_frame": _fraction_in_frame(truth.center_rc, truth.apparent_radius_px),
    }


def _summary(runs: list[dict]) -> dict:
    e = np.array([r["error_rc"] for r in runs])
    s = np.array([r["sigma_rc"] for r in runs])
    sp = np.array([r["sigma_pixel_independent_rc"] for r in runs])
    err = np.hypot(e[:, 0], e[:, 1])
    rms = np.sqrt(np.mean(e**2, axis=0))
    return {"n": len(runs), "max_error_px": float(err.max()), "median_error_px": float(np.median(err)),
            "rms_error_rc": rms.tolist(), "mean_sigma_rc": s.mean(0).tolist(),
            "rms_over_sigma_rc": (rms / s.mean(0)).tolist(),
            "rms_over_pixel_independent_sigma_rc": (rms / sp.mean(0)).tolist(),
            "fraction_in_frame": runs[0]["fraction_in_frame"]}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=8, help="noise seeds per geometry (default 8)")
    a = ap.parse_args(argv)
    out = {"geometries": [], "environment": environment()}
    for center, sun in GEOMETRIES:
        runs = [_run(center, sun, seed) for seed in range(1, a.n + 1)]
        g = {"center_rc": list(center), "sun_angle_deg": sun, "summary": _summary(runs), "runs": runs}
        out["geometries"].append(g)
        s = g["summary"]
        print(f"centre {center}: {100 * s['fraction_in_frame']:.0f} % of the limb in frame; error median "
              f"{s['median_error_px']:.3f} max {s['max_error_px']:.3f} px; rms/sigma {np.round(s['rms_over_sigma_rc'], 2)} "
              f"(pixel-independent sigma: {np.round(s['rms_over_pixel_independent_sigma_rc'], 2)})", flush=True)
    allr = [r for g in out["geometries"] for r in g["runs"]]
    out["all"] = _summary(allr)
    save("limb_arc", out)
    print("all:", {k: out["all"][k] for k in ("max_error_px", "median_error_px", "rms_over_sigma_rc")})
    return out


if __name__ == "__main__":
    main()
