"""Monte Carlo of the whole ``locate`` pipeline: N noise realisations of one 1944x2592 frame.

The Moon is rendered once without noise (150 000 km, phase 45 deg, lunar-Lambert, PSF 1 px,
default camera), scaled to 80 % of the 8-bit range; each realisation adds Gaussian noise of
``--sigma`` grey levels (the Aerospace 2015 Monte Carlo uses 10), rounds and clips to 8 bits, and
runs ``locate`` (gradient front end, circular sigmoid with k estimated, body-centre correction;
``--profile auto`` for the physical limb profile, ``locate``'s default with a Sun direction).
Reports the wall time (target: 1000 frames <= 3 min on this 2-core machine), the time spent
making the noise, and the error statistics against the render's truth.

Run:  python benchmarks/locate_montecarlo.py [--n 1000] [--sigma 10] [--quick]
Writes benchmarks/results/locate_montecarlo.json.
"""

from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from tqdm.auto import tqdm  # noqa: E402

from _common import environment, save  # noqa: E402
from jaxlimb.geometry.camera import Camera  # noqa: E402
from jaxlimb.imaging import Hints  # noqa: E402
from jaxlimb.pipeline import LocateOptions, locate  # noqa: E402
from jaxlimb.render import RenderOptions, moon_scene, render_body  # noqa: E402


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--sigma", type=float, default=10.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="20 realisations")
    ap.add_argument("--profile", default="sigmoid", choices=("sigmoid", "auto"),
                    help="limb model: the papers' sigmoid (default, as in the Aerospace 2015 Monte Carlo) or "
                    "locate's default (the physical limb profile)")
    args = ap.parse_args(argv)
    n = 20 if args.quick else args.n
    cam = Camera.default()
    scene = moon_scene(150_000.0, 45.0, center_rc=(900.0, 1400.0), camera=cam, sun_angle_deg=30.0)
    clean, truth = render_body(scene, cam, RenderOptions(reflectance="lunar-lambert", psf_sigma_px=1.0,
                                                         bit_depth=None, noise=False), seed=args.seed)
    base = clean * (255.0 * 0.8 / clean.max())
    hints = Hints(body="moon", sun_dir_camera=tuple(float(v) for v in truth.sun_dir_cam))
    rng = np.random.default_rng(args.seed)
    opts = LocateOptions(compute_crlb=False, keep_pixels=False, profile=args.profile)

    def frame() -> np.ndarray:
        return np.clip(np.round(base + args.sigma * rng.standard_normal(base.shape)), 0, 255)

    t = time.perf_counter()
    locate(frame(), cam, hints, opts)
    first = time.perf_counter() - t
    errs, iters, t_noise = [], [], 0.0
    t0 = time.perf_counter()
    for _ in tqdm(range(n), desc="locate Monte Carlo", unit="frame"):
        a = time.perf_counter()
        img = frame()
        t_noise += time.perf_counter() - a
        m = locate(img, cam, hints, opts)
        errs.append((m.center_rc[0] - truth.center_rc[0], m.center_rc[1] - truth.center_rc[1],
                     m.radius_px - truth.apparent_radius_px))
        iters.append(m.iterations)
    wall = time.perf_counter() - t0
    e = np.asarray(errs)
    out = {
        "n": n, "sigma_dn": args.sigma, "frame": [cam.rows, cam.cols], "first_call_s": first, "wall_s": wall,
        "ms_per_frame": 1e3 * wall / n, "noise_generation_ms_per_frame": 1e3 * t_noise / n,
        "mean_error_rc_radius_px": e.mean(0).tolist(), "std_rc_radius_px": e.std(0).tolist(),
        "iterations_mean": float(np.mean(iters)), "truth": {"center_rc": list(truth.center_rc),
                                                           "radius_px": truth.apparent_radius_px},
        "environment": environment(),
    }
    print(f"first call {first:.1f} s; {n} frames in {wall:.1f} s ({out['ms_per_frame']:.0f} ms each, of which "
          f"{out['noise_generation_ms_per_frame']:.0f} ms making the noise)")
    print(f"error mean (row, col, radius) {np.round(e.mean(0), 4).tolist()} px, std {np.round(e.std(0), 4).tolist()} px")
    path = save("locate_montecarlo_quick" if args.quick else "locate_montecarlo", out)
    print(f"wrote {path}")
    return out


if __name__ == "__main__":
    main()
