"""Render a cislunar transfer with the independent renderer and measure every frame with ``locate`` (cached).

What is rendered: one transfer (``jaxlimb.track.make_transfer``: 100 000 km from the Earth to 40 000 km from the
Moon in 3.5 days from 2026-03-07 12:00 UTC: the Earth about half lit, the Moon gibbous to nearly full from the
spacecraft; ``benchmarks/track_transfer.py`` reports the phase angles), ``--n-frames`` frames alternating
Earth / Moon, 256 x 256 px, focal length 1000 px, each body at a random place of the frame with a random roll.  The Earth: WGS-84 ellipsoid oriented by
its true rotation (skyfield ITRS), Lambert, uniform albedo; the Moon: Hapke law (not the pipeline's
lunar-Lambert profile); Sun from DE421; Gaussian PSF sigma 0.8 px, 12 bits with read noise.  The radiance of
each frame is rendered once (``--cache``); ``--realizations`` noise draws of it are digitised and measured by
``locate`` with the true camera, and draw 0 also with the *nominal* camera of the self-calibration study
(focal length +1 %, principal point off by (+2.0, -1.5) px).  Records go to ``CACHE/locate_<draw>.jsonl``, one
line per frame, and a rerun skips what is there.

``python benchmarks/track_render.py --cache /tmp/track-cache [--n-frames 200 --realizations 6]``; the analysis
is ``benchmarks/track_transfer.py``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

EPOCH = "2026-03-07T12:00:00Z"
THETA_TRUE = np.array([1000.0, 127.5, 127.5, 0.0])
THETA_NOMINAL = THETA_TRUE * np.array([1.01, 1.0, 1.0, 1.0]) + np.array([0.0, 2.0, -1.5, 0.0])
ROWS = COLS = 256


def scenario(n_frames: int, seed: int):  # noqa: ANN201
    """``(arc, prop, transfer)`` of the study (module docstring)."""
    from jaxlimb.geometry.ephemeris import epoch_to_jd_tdb
    from jaxlimb.track import Propagator, make_arc, make_transfer

    jd = epoch_to_jd_tdb(EPOCH)
    arc = make_arc(jd, jd + 3.6)
    prop = Propagator(arc.table)
    tr = make_transfer(arc, prop, n_frames, THETA_TRUE, ROWS, COLS, rng=np.random.default_rng(seed))
    return arc, prop, tr


def camera(theta: np.ndarray):  # noqa: ANN201
    from jaxlimb.geometry.camera import Camera

    return Camera(focal_length_mm=theta[0] * 0.0022, pixel_pitch_mm=0.0022, rows=ROWS, cols=COLS,
                  principal_point_rc=(float(theta[1]), float(theta[2])))


def frame_geometry(arc, tr, k: int) -> dict:  # noqa: ANN001
    """Camera-frame body centre, body-to-camera rotation and Sun direction of frame ``k``."""
    from jaxlimb.cli._navigate import earth_rotation_icrf_to_itrs

    b = tr.bodies[k]
    C = tr.C_true[k]
    bp = arc.body_position(b, tr.t[k : k + 1])[0]
    sun = arc.body_position("sun", tr.t[k : k + 1])[0]
    s = C @ (sun - bp)
    if b == "earth":
        R = C @ earth_rotation_icrf_to_itrs(arc.jd0 + tr.t[k] / 86400.0).T
    else:
        R = C  # a uniform Moon: any orientation
    return {"center_cam": C @ (bp - tr.states[k, :3]), "R": R, "sun": s / np.linalg.norm(s), "body": b}


def render(arc, tr, k: int, cache: Path) -> np.ndarray:  # noqa: ANN001
    from jaxlimb.render.independent import Body, Pinhole, Psf, PsfKind, Surface, render_radiance
    from jaxlimb.render.independent.surface import Photometry, Reflectance
    from jaxlimb.track.measurement import BODY_RADIUS_KM

    path = cache / f"radiance_{k:04d}.npy"
    if path.exists():
        return np.load(path)
    g = frame_geometry(arc, tr, k)
    radii = (6378.137, 6378.137, 6356.752) if g["body"] == "earth" else (BODY_RADIUS_KM["moon"],) * 3
    law = Photometry(law=Reflectance.LAMBERT) if g["body"] == "earth" else Photometry(law=Reflectance.HAPKE)
    pin = Pinhole.from_camera(camera(THETA_TRUE))
    rad = render_radiance(Body(radii, g["center_cam"], g["R"], g["sun"]), Surface(law), pin, Psf(PsfKind.GAUSSIAN, 0.8))
    tmp = path.with_suffix(f".{os.getpid()}.tmp.npy")
    np.save(tmp, rad)
    os.replace(tmp, path)  # two runs may render the same frame: never a partial file
    return rad


def measure(arc, tr, k: int, rad: np.ndarray, draw: int, theta: np.ndarray, seed: int) -> dict:  # noqa: ANN001
    from jaxlimb.errors import JaxlimbError
    from jaxlimb.imaging import Hints
    from jaxlimb.pipeline import locate
    from jaxlimb.render.independent import SensorSpec, digitise

    g = frame_geometry(arc, tr, k)
    spec = SensorSpec(bits=12, read_noise_dn=157.0 / (20000.0 / 4095), background_dn=40.0 / (20000.0 / 4095))
    img = digitise(rad, spec, np.random.default_rng([seed, draw, k]), (0, ROWS - 1, 0, COLS - 1))
    rng = np.random.default_rng([seed, draw, k, 1])
    D = float(np.linalg.norm(g["center_cam"]))
    hints = Hints(body=g["body"], sun_dir_camera=tuple(float(v) for v in g["sun"]),
                  range_prior_km=D * (1 + 0.05 * float(rng.standard_normal())),
                  **({"R_body_to_camera": g["R"].tolist(), "atmosphere_km": 0.0} if g["body"] == "earth" else {}))
    try:
        m = locate(img, camera(theta), hints)
        return {**m.to_json(), "frame": k}
    except JaxlimbError as e:
        return {"frame": k, "status": "error", "check": e.check, "message": " ".join(str(e).split())}


def main(argv: list[str] | None = None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, required=True)
    ap.add_argument("--n-frames", type=int, default=200)
    ap.add_argument("--realizations", type=int, default=6)
    ap.add_argument("--seed", type=int, default=38)
    ap.add_argument("--first-frame", type=int, default=0, help="start at this frame (split a run over processes)")
    ap.add_argument("--last-frame", type=int, default=None, help="stop before this frame")
    ap.add_argument("--draws", default=None, help="comma-separated subset of the draws (0.., nominal) to run")
    a = ap.parse_args(argv)
    a.cache.mkdir(parents=True, exist_ok=True)
    arc, prop, tr = scenario(a.n_frames, a.seed)
    draws = [("nominal", 0, THETA_NOMINAL)] + [(str(d), d, THETA_TRUE) for d in range(a.realizations)]
    order = [draws[1], draws[0], *draws[2:]]
    if a.draws is not None:
        order = [x for x in order if x[0] in a.draws.split(",")]
    for name, d, theta in order:
        out = a.cache / f"locate_{name}.jsonl"
        done = {json.loads(x)["frame"] for x in out.read_text().splitlines() if x.strip()} if out.exists() else set()
        t0 = time.time()
        with open(out, "a") as fh:
            for k in range(a.first_frame, a.n_frames if a.last_frame is None else a.last_frame):
                if k in done:
                    continue
                rec = measure(arc, tr, k, render(arc, tr, k, a.cache), d, theta, a.seed)
                fh.write(json.dumps(rec) + "\n")
                fh.flush()
        print(f"draw {name}: {time.time() - t0:.0f} s", file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
