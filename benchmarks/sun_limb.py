"""Sigmoid ``locate`` vs the limb-darkened disc fit on the three SDO images (truth from the headers).

For each image: centre error and radius error of :func:`jaxlimb.pipeline.locate` (circular
sigmoid) and of :func:`jaxlimb.pipeline.sphere.sun.fit_limb_darkened` (started from the
sigmoid's circle, or from a thresholded disc when ``locate`` fails).  Truth: the MANIFEST for
the 512 px PNG; ``sun_truth_from_header`` (astropy.wcs, ``RSUN_OBS``) for the FITS files.
For ``resampled_hmi.fits`` the centre is also computed with ``CROTA2`` dropped, and from
the circle bounding the HMI pipeline's off-disc NaN mask (which the pipeline draws around
its own disc centre, independently of this file's WCS).

Run: ``python benchmarks/sun_limb.py`` -> ``benchmarks/results/sun_limb.json``.
"""

from __future__ import annotations

import time
import warnings

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from _common import environment, save  # noqa: E402

from jaxlimb._data import shared_data_dir  # noqa: E402
from jaxlimb.imaging.sdo import AIA_171_FITS, HMI_512_PNG, hmi_512_truth, RESAMPLED_HMI_FITS, sun_truth_from_header
from jaxlimb.imaging.io import load_image
from jaxlimb.pipeline import locate  # noqa: E402
from jaxlimb.pipeline.sphere.sun import fit_limb_darkened


def _nan_mask_circle(data: np.ndarray) -> dict:
    """Algebraic (Kasa) circle through the finite pixels bordering the NaN region."""
    from scipy import ndimage

    fin = np.isfinite(data)
    edge = fin & ndimage.binary_dilation(~fin)
    r, c = np.nonzero(edge)
    A = np.c_[r, c, np.ones_like(r)]
    s = np.linalg.lstsq(A, r.astype(float) ** 2 + c.astype(float) ** 2, rcond=None)[0]
    r0, c0 = s[0] / 2, s[1] / 2
    return {"center_rc": [float(r0), float(c0)], "radius_px": float(np.sqrt(s[2] + r0**2 + c0**2)), "n": int(r.size)}


def _threshold_disc(img: np.ndarray) -> tuple[tuple[float, float], float]:
    """Centroid and equivalent radius of the pixels above half the 99th percentile."""
    x = np.nan_to_num(img, nan=0.0)
    m = x > 0.5 * np.percentile(x, 99)
    r, c = np.nonzero(m)
    return (float(r.mean()), float(c.mean())), float(np.sqrt(m.sum() / np.pi))


def _errors(center_rc, radius, truth) -> dict:
    dr, dc = np.subtract(center_rc, truth.center_rc)
    return {"center_rc": [float(v) for v in center_rc], "radius_px": float(radius), "center_err_rc": [float(dr), float(dc)],
            "center_err_px": float(np.hypot(dr, dc)), "radius_err_px": float(radius - truth.radius_px)}


def run_one(name: str) -> dict:
    path = shared_data_dir() / "sun" / name
    out: dict = {"file": name}
    img_locate, _ = load_image(path)  # what locate / the CLI see (FITS NaN filled)
    if name.endswith(".fits"):
        from astropy.io import fits

        with fits.open(path) as hdul:
            hdr = hdul[0].header
            img_fit = np.asarray(hdul[0].data, dtype=float)  # NaN kept: the fit drops them
        truth = sun_truth_from_header(hdr)
        out["truth"] = {"center_rc": list(truth.center_rc), "radius_px": truth.radius_px, "crota2": float(hdr.get("CROTA2", 0.0))}
        if "CROTA2" in hdr:
            out["truth"]["center_rc_crota2_dropped"] = list(sun_truth_from_header(hdr, ignore_rotation=True).center_rc)
        if np.isnan(img_fit).any():
            out["nan_mask_circle"] = _nan_mask_circle(img_fit)
    else:
        img_fit = img_locate
        truth = hmi_512_truth()
        out["truth"] = {"center_rc": list(truth.center_rc), "radius_px": truth.radius_px}
    t = time.perf_counter()
    try:
        m = locate(img_locate)
        out["sigmoid"] = _errors(m.center_rc, m.radius_px, truth) | {"seconds": time.perf_counter() - t}
        start = (m.center_rc, m.radius_px)
    except Exception as e:  # noqa: BLE001 - a robustness case: record what happens
        out["sigmoid"] = {"error": f"{type(e).__name__}: {e}"}
        start = _threshold_disc(img_fit)
        out["start_from_threshold"] = {"center_rc": list(start[0]), "radius_px": start[1]}
    try:
        fit_limb_darkened(img_fit, *start)  # compile
        t = time.perf_counter()
        f = fit_limb_darkened(img_fit, *start)
        sec = time.perf_counter() - t
        p = f.params
        out["limb_darkened"] = _errors(f.center_rc, f.radius_px, truth) | {
            "seconds_warm": sec, "std_rc_a": [float(v) for v in np.sqrt(np.diag(f.covariance))],
            "u1": float(p.u1), "u2": float(p.u2), "sigma": float(p.sigma), "amp": float(p.amp), "ymin": float(p.ymin),
            "free": list(f.fit.free), "rms": float(f.fit.rms), "n_pixels": f.n_pixels, "annulus_px": f.annulus_px,
            "n_steps": int(f.fit.n_steps)}
        if "center_rc_crota2_dropped" in out.get("truth", {}):
            tc = out["truth"]["center_rc_crota2_dropped"]
            out["limb_darkened"]["center_err_px_vs_crota2_dropped"] = float(np.hypot(*np.subtract(f.center_rc, tc)))
            if "center_rc" in out["sigmoid"]:
                out["sigmoid"]["center_err_px_vs_crota2_dropped"] = float(np.hypot(*np.subtract(out["sigmoid"]["center_rc"], tc)))
    except Exception as e:  # noqa: BLE001
        out["limb_darkened"] = {"error": f"{type(e).__name__}: {e}"}
    return out


def main() -> None:
    warnings.simplefilter("ignore")
    rows = [run_one(n) for n in (HMI_512_PNG, RESAMPLED_HMI_FITS, AIA_171_FITS)]
    for r in rows:
        print(r["file"])
        for k in ("sigmoid", "limb_darkened"):
            v = r[k]
            if "error" in v:
                print(f"  {k:14s} {v['error']}")
            else:
                extra = f" u1={v['u1']:.3f} u2={v['u2']:.3f} sigma={v['sigma']:.3f}" if k == "limb_darkened" else ""
                print(f"  {k:14s} centre err {v['center_err_rc'][0]:+.3f},{v['center_err_rc'][1]:+.3f} px "
                      f"(|.| {v['center_err_px']:.3f}) radius err {v['radius_err_px']:+.3f} px{extra}")
        if "center_rc_crota2_dropped" in r["truth"]:
            print(f"  WCS centre {np.round(r['truth']['center_rc'], 3).tolist()}, CROTA2 dropped "
                  f"{np.round(r['truth']['center_rc_crota2_dropped'], 3).tolist()}"
                  + (f", NaN-mask circle {np.round(r['nan_mask_circle']['center_rc'], 3).tolist()}" if "nan_mask_circle" in r else ""))
    path = save("sun_limb", {"environment": environment(), "results": rows})
    print(f"saved {path}")


if __name__ == "__main__":
    main()
