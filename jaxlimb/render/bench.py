"""Timing and accuracy report of the truth renderer: ``python -m jaxlimb.render.bench [--quick]``.

Prints, for the default 1944x2592 camera, the wall time of :func:`render_body` (default
options: Lommel-Seeliger, 89 sub-samples on edge pixels, 1 px PSF, Poisson + read noise,
12 bit) for Moons of ~150-600 px radius, an Earth at GEO with atmosphere, and the limb
accuracy (:func:`jaxlimb.render.validate.limb_accuracy`) of the rendered limb against the
image conic of Eq. (2) (Mortari et al. 2016) for off-axis spheres and a triaxial ellipsoid.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

from ..geometry.camera import Camera
from .body import RenderOptions, render_body
from .raytrace import render_radiance
from .scene import MOON_RADIUS_KM, Atmosphere, Scene, earth_scene, moon_scene
from .validate import limb_accuracy


def _time(fn, n: int) -> float:
    ts = []
    for _ in range(n):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return float(np.median(ts))


def main(argv: list[str] | None = None) -> dict[str, object]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one repetition per timing")
    args = ap.parse_args(argv)
    reps = 1 if args.quick else 3
    cam = Camera.default()
    out: dict[str, object] = {"timing_s": {}, "limb_accuracy_px": {}}
    render_body(moon_scene(100000.0, 30.0, camera=cam), cam, seed=0)  # warm-up (imports)
    for r_px in (150, 300, 600):
        D = math.hypot(MOON_RADIUS_KM * cam.focal_px / r_px, MOON_RADIUS_KM)
        sc = moon_scene(D, 60.0, center_rc=(900.0, 1300.0), camera=cam, sun_angle_deg=30.0)
        out["timing_s"][f"moon_r{r_px}px"] = _time(lambda: render_body(sc, cam, RenderOptions(), seed=1), reps)  # type: ignore[index]
    sc = earth_scene(42164.0, 30.0, 60.0, camera=cam, atmosphere=Atmosphere())
    out["timing_s"]["earth_geo_atmosphere"] = _time(lambda: render_body(sc, cam, RenderOptions(), seed=1), reps)  # type: ignore[index]

    off = Camera(rows=300, cols=400, principal_point_rc=(-700.0, -900.0))
    cases = {
        "sphere_r52_offaxis": moon_scene(MOON_RADIUS_KM * 145.0, 0.0, center_rc=(150.0, 200.0), camera=off),
        "sphere_r180_corner": moon_scene(70000.0, 0.0, center_rc=(190.0, 200.0), camera=cam),
    }
    from scipy.spatial.transform import Rotation

    R = Rotation.from_euler("zyx", [0.3, 0.5, -0.2]).as_matrix()
    cases["ellipsoid_60x45x40_offaxis"] = Scene(
        radii=(60.0, 45.0, 40.0), center_cam=tuple(off.los(np.array([140.0, 210.0])) * 3000.0), R_body_to_camera=R,
        sun_dir_cam=None,
    )
    for name, sc in cases.items():
        c = cam if name == "sphere_r180_corner" else off
        win = render_radiance(sc, c, "uniform", 89)
        out["limb_accuracy_px"][name] = limb_accuracy(win)  # type: ignore[index]
    print(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
