"""How much of the Earth's covariance in the rendered transfer is the unresolved-glow consider term?

The transfer's Earth is rendered without an atmosphere (``benchmarks/track_render.py``); ``locate``'s covariance
carries the glow of a real one (``EllipsoidOptions.unresolved_glow``).  Every ``--stride``-th Earth frame of noise
draw 0 is located again with that term off, and its centre NEES (chi-square with 2 degrees of freedom: 2) and range
z-score are set beside those of the cached measurement (``CACHE/locate_0.jsonl``, the term on).

    python benchmarks/track_glow.py --cache /tmp/track-cache [--stride 5] [--n 20]   # -> results/track_glow.json

The cache is ``track_render.py``'s (its radiance files and ``locate_0.jsonl``; run that first).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from _common import environment, save


def _center_cov(ans: dict) -> np.ndarray:
    c = ans["covariance"]
    from jaxlimb.pipeline import covariance_block
    return covariance_block(c)


def _scores(ans: dict, truth_rc, range_km: float) -> dict:
    e = np.subtract(ans["center_rc"], truth_rc)
    return {"center_error_rc": e.tolist(), "center_nees": float(e @ np.linalg.solve(_center_cov(ans), e)),
            "range_z": (ans["range_km"] - range_km) / ans["covariance"]["range_km"]["range_km"] ** 0.5}


def _frame(arc, tr, k: int, cache: Path, track_render) -> dict:  # noqa: ANN001
    from jaxlimb.pipeline import EllipsoidOptions, LocateOptions
    from jaxlimb.pipeline import locate
    from jaxlimb.imaging import Hints
    from jaxlimb.render.independent import SensorSpec, digitise

    g = track_render.frame_geometry(arc, tr, k)
    spec = SensorSpec(bits=12, read_noise_dn=157.0 / (20000.0 / 4095), background_dn=40.0 / (20000.0 / 4095))
    rows, cols = track_render.ROWS, track_render.COLS
    img = digitise(track_render.render(arc, tr, k, cache), spec, np.random.default_rng([38, 0, k]),
                   (0, rows - 1, 0, cols - 1))
    rng = np.random.default_rng([38, 0, k, 1])  # the hints of track_render.measure, draw 0
    D = float(np.linalg.norm(g["center_cam"]))
    hints = Hints(body="earth", sun_dir_camera=tuple(float(v) for v in g["sun"]),
                  range_prior_km=D * (1 + 0.05 * float(rng.standard_normal())), R_body_to_camera=g["R"].tolist(),
                  atmosphere_km=0.0)
    m = locate(img, track_render.camera(track_render.THETA_TRUE), hints,
               LocateOptions(ellipsoid=EllipsoidOptions(unresolved_glow=None)))
    c, th = g["center_cam"], track_render.THETA_TRUE
    truth = (th[1] + th[0] * c[1] / c[2], th[2] + th[0] * c[0] / c[2])
    return {"frame": k, "truth_rc": list(truth), "range_km": D, "no_glow": _scores(m.to_json(), truth, D)}


def main() -> None:
    import jax

    jax.config.update("jax_enable_x64", True)
    import track_render

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cache", type=Path, required=True)
    ap.add_argument("--stride", type=int, default=5)
    ap.add_argument("--n", type=int, default=20)
    a = ap.parse_args()
    arc, _, tr = track_render.scenario(200, 38)
    cached = {r["frame"]: r for r in map(json.loads, (a.cache / "locate_0.jsonl").read_text().splitlines())}
    rows = []
    for k in [k for k in range(200) if tr.bodies[k] == "earth"][:: a.stride][: a.n]:
        row = _frame(arc, tr, k, a.cache, track_render)
        row["glow"] = _scores(cached[k], row["truth_rc"], row["range_km"])
        rows.append(row)
        print(k, {t: round(row[t]["center_nees"], 2) for t in ("glow", "no_glow")}, flush=True)
    summary = {t: {"center_nees_mean": float(np.mean([r[t]["center_nees"] for r in rows])),
                   "range_z_rms": float(np.sqrt(np.mean([r[t]["range_z"] ** 2 for r in rows])))}
               for t in ("glow", "no_glow")}
    print(summary)
    print(save("track_glow", {"environment": environment(), "stride": a.stride, "summary": summary, "rows": rows}))


if __name__ == "__main__":
    main()
