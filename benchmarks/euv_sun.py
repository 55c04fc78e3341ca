"""The Sun in the extreme ultraviolet: ``locate`` on independent renders of an optically thin corona over an opaque
disc, and on the real SDO/AIA 171 A frame.

    nice python benchmarks/euv_sun.py [--radii 30,60,120] [--n 8] [--seed 2026] [--out euv_sun]

Frames: :func:`jaxlimb.render.independent.corona.euv_sun` (line-of-sight integration of three hydrostatic
components in a 1/rho^2 gravity with active regions, the occulter 0.2-1 % above the photosphere, a Gaussian PSF
with a scattered-light wing, Poisson and read noise), frame ``2.6 R`` square, hints ``body="sun"`` only.  Truth: the
photosphere's centre.  Per radius: frames answered, the profile that answered, the centre error median / p90 / max,
the mean NEES of the centre (chi-square with 2 degrees of freedom: 2) and the radius minus the photosphere's.
AIA: ``sun/aia_171_level1.fits`` against its header's WCS centre and ``RSUN_OBS``.  Written to
``benchmarks/results/<out>.json`` with the seed and the git SHA.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from _common import environment, save  # noqa: E402

from jaxlimb._data import shared_data_dir  # noqa: E402
from jaxlimb.errors import JaxlimbError  # noqa: E402
from jaxlimb.geometry.hints import Hints  # noqa: E402
from jaxlimb.imaging.io import load_image  # noqa: E402
from jaxlimb.imaging.sdo import AIA_171_FITS, sun_truth_from_header  # noqa: E402
from jaxlimb.pipeline import covariance_block, locate  # noqa: E402
from jaxlimb.render.independent.corona import euv_sun  # noqa: E402


def _row(image, center_rc, radius_px) -> dict:
    t0 = time.perf_counter()
    try:
        m = locate(image, None, Hints(body="sun"))
    except JaxlimbError as e:
        return {"status": "error", "check": e.check, "message": str(e)[:200], "seconds": time.perf_counter() - t0}
    err = np.subtract(m.center_rc, center_rc)
    cv = m.covariance
    P = covariance_block(cv)
    return {"status": "ok", "profile": m.extras["profile"]["model"], "front_end": m.front_end,
            "err_rc": err.tolist(), "center_err_px": float(np.hypot(*err)), "sigma_rc": np.sqrt(np.diag(P)).tolist(),
            "nees": float(err @ np.linalg.solve(P, err)), "radius_err_px": m.radius_px - float(radius_px),
            "seconds": time.perf_counter() - t0}


def _summary(rows: list[dict]) -> dict:
    ok = [r for r in rows if r["status"] == "ok"]
    e = np.array([r["center_err_px"] for r in ok]) if ok else np.array([np.nan])
    return {"n": len(rows), "answered": len(ok), "corona": sum(r.get("profile") == "corona" for r in ok),
            "median_px": float(np.median(e)), "p90_px": float(np.percentile(e, 90)), "max_px": float(np.max(e)),
            "mean_nees": float(np.mean([r["nees"] for r in ok])) if ok else None,
            "radius_err_median_px": float(np.median([r["radius_err_px"] for r in ok])) if ok else None}


def _aia() -> dict:
    img, info = load_image(shared_data_dir() / "sun" / AIA_171_FITS)
    truth = sun_truth_from_header(info.header)
    return {"frame": f"sun/{AIA_171_FITS}", **_row(img, truth.center_rc, truth.radius_px)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--radii", default="30,60,120")
    ap.add_argument("--n", type=int, default=8)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--out", default="euv_sun")
    a = ap.parse_args()
    out: dict = {"environment": environment(), "seed": a.seed, "n": a.n, "aia_171": _aia(), "radii": {}}
    print("AIA 171:", out["aia_171"])
    for R in (float(x) for x in a.radii.split(",")):
        rng = np.random.default_rng([a.seed, int(R)])
        rows = []
        for _ in range(a.n):
            f = euv_sun(rng, R, int(round(2.6 * R)))
            rows.append(_row(f.image, f.center_rc, f.radius_px))
        out["radii"][f"{R:g}"] = {"summary": _summary(rows), "rows": rows}
        print(f"R = {R:g} px:", out["radii"][f"{R:g}"]["summary"], flush=True)
    print(save(a.out, out))


if __name__ == "__main__":
    main()
