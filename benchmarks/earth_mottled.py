"""``locate`` on a mottled Lambert Earth (the project's renderer) across phase, near zero phase included.

Usage::

    .venv/bin/python benchmarks/earth_mottled.py [--phases 2,5,10,20,40,60,110,140] [--out NAME]

Scene: :func:`jaxlimb.render.earth_scene` at 300 000 km (16 mm lens, 420^2 frame, the disc 155 px in radius),
latitude 20 deg, ``AlbedoPatches(seed=K, amplitude=0.6)`` for each ``K`` of ``--seeds`` (default 4), Lambert reflectance, Gaussian PSF 0.9 px, 12 bit, 20 DN
of extra noise; ``locate`` gets the camera, the Sun direction, a range prior 1 % off and ``R_body_to_camera``.
Near zero phase the Lambert limb is dark and its traced rays fail the plain flatness test, so a limb tested on
flatness alone is not flagged patchy and the one-albedo profile answers far off; the trace tests their
flatness divided by the shading (:class:`jaxlimb.pipeline.ellipsoid.shading.RayShading`).  Prints and writes ``benchmarks/results/<out>.json`` (default
``earth_mottled``): per phase the status, centre error, centre sigmas and NEES.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def measure(phase_deg: float, patch_seed: int = 4) -> dict:
    """One rendered frame at ``phase_deg`` (albedo map ``AlbedoPatches(seed=patch_seed)``) and its ``locate`` answer against the truth."""
    from jaxlimb.errors import JaxlimbError
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.pipeline import locate
    from jaxlimb.render import RenderOptions, earth_scene, render_body
    from jaxlimb.render.scene import AlbedoPatches

    cam = Camera(focal_length_mm=16.0, rows=420, cols=420)
    sc = earth_scene(300000.0, 20.0, phase_deg, center_rc=(208.3, 211.6), camera=cam, sun_angle_deg=30.0,
                     albedo_patches=AlbedoPatches(seed=patch_seed, amplitude=0.6))
    opts = RenderOptions(reflectance="lambert", psf_sigma_px=0.9, bit_depth=12, extra_noise_dn=20.0)
    img, truth = render_body(sc, cam, opts, seed=3)
    hints = {"body": "earth", "range_prior_km": 1.01 * truth.range_km, "sun_dir_camera": list(truth.sun_dir_cam),
             "R_body_to_camera": np.asarray(sc.R_body_to_camera).tolist()}
    try:
        m = locate(img, cam, hints)
    except JaxlimbError as e:
        return {"phase_deg": phase_deg, "patch_seed": patch_seed, "status": "error", "check": e.check, "message": str(e)[:200]}
    err = np.subtract(m.center_rc, truth.center_rc)
    c = m.covariance
    from jaxlimb.pipeline import covariance_block
    P = covariance_block(c)
    return {"phase_deg": phase_deg, "patch_seed": patch_seed, "status": "ok", "center_err_px": float(np.hypot(*err)),
            "sigma_rc_px": np.sqrt(np.diag(P)).tolist(), "nees": float(err @ np.linalg.solve(P, err)),
            "patchy": (m.extras or {}).get("profile_rejected") is not None}


def main(argv=None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    from _common import environment, save

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--phases", default="2,5,10,20,40,60,110,140", help="comma-separated phase angles (deg)")
    ap.add_argument("--seeds", default="4", help="comma-separated AlbedoPatches seeds (one albedo map each)")
    ap.add_argument("--out", default="earth_mottled")
    a = ap.parse_args(argv)
    rows = [measure(float(p), int(k)) for k in a.seeds.split(",") for p in a.phases.split(",")]
    for r in rows:
        print(f"map {r['patch_seed']} phase {r['phase_deg']:5.1f}: " + (f"ok {r['center_err_px']:.3f} px, sigma {r['sigma_rc_px'][0]:.3f} / "
                                                f"{r['sigma_rc_px'][1]:.3f} px, NEES {r['nees']:.1f}"
                                                if r["status"] == "ok" else f"{r['check']}: {r['message'][:100]}"))
    ok = [r for r in rows if r["status"] == "ok"]
    summary = {"n": len(rows), "ok": len(ok)}
    if ok:
        e = np.array([r["center_err_px"] for r in ok])
        summary.update(median_px=float(np.median(e)), max_px=float(e.max()),
                       mean_nees=float(np.mean([r["nees"] for r in ok])))
    print("summary", summary)
    print("saved", save(a.out, {"args": vars(a), "environment": environment(), "summary": summary, "rows": rows}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
