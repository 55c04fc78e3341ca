"""Cassini ISS NAC frames of Enceladus: measured limb vs the SPICE prediction, end to end.

Both raw frames of ``shared/data/cassini`` (VICAR, read with rms-vicar; the second has 38
missing lines, masked) are located with the mission's own kernels and nothing typed by hand:
camera from the IK, image time from the label, predicted limb / Sun / range / orientation
from SPICE (:mod:`jaxlimb.geometry.spice`), the whole-limb stage
(:mod:`jaxlimb.pipeline.sphere.whole_limb`).  Reported per frame: the measured body centre and its
covariance, measured - predicted (px and microradians), the radius and range against the
prediction, the observer position from the measurement.  Between the frames (33 s apart):
the change of the residual against the combined sigma, and -- independent of SPICE -- the
body's motion from phase correlation of the two gradient images against the difference of
the two measured centres.

Run: ``python benchmarks/cassini_enceladus.py`` -> ``benchmarks/results/cassini_enceladus.json``
and the figure ``benchmarks/results/cassini_enceladus.png`` (predicted and measured limbs
over each frame).  Data: NASA/JPL Cassini ISS EDRs and SPICE kernels (MANIFEST.md).
"""

from __future__ import annotations

import json
import math

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from _common import RESULTS, environment, save  # noqa: E402

from jaxlimb._data import shared_data_dir  # noqa: E402
from jaxlimb.geometry.spice import observer_from_measurement, pointing_residual, spice_geometry  # noqa: E402
from jaxlimb.imaging.formats import read_frame  # noqa: E402
from jaxlimb.pipeline import covariance_block, locate  # noqa: E402

CASSINI = shared_data_dir() / "cassini"
KERNELS = sorted(str(p) for p in (CASSINI / "kernels").iterdir())
FRAMES = ("N1511803932_1", "N1511803965_3")


def _one(name: str):
    fr = read_frame(CASSINI / f"{name}.IMG")
    g = spice_geometry(KERNELS, fr.meta.image_time, fr.meta.instrument_id, fr.meta.target_name)
    m = locate(fr.data, g.camera, g.hints(), mask=fr.mask_or_none)
    c = m.covariance
    cov = covariance_block(c).tolist()
    res = {
        "image_time": fr.meta.image_time, "n_masked": fr.n_invalid,
        "measured_center_rc": list(m.center_rc), "center_covariance_px2": cov,
        "predicted_center_rc": list(g.center_rc),
        "measured_minus_predicted": pointing_residual(g, m.center_rc, cov),
        "radius_px": m.radius_px, "range_km": m.range_km, "spice_range_km": g.range_km,
        "spice_radii_km": list(g.radii_km),
        "observer": observer_from_measurement(g, m.los_camera, m.range_km),
        "edges_from_measured_limb": _edge_offsets(fr, _shapes(g, m)[0]),
        "edges_from_predicted_limb": _edge_offsets(fr, _shapes(g, m)[1]),
        "ck": _ck_probe(fr, g),
        "with_kernel_pck_radii": _kernel_shape(fr, g),
        "extras": {k: m.extras.get(k) for k in ("edge_fit", "angular_bins", "sigma_center_pixel_independent_px",
                                             "sigma_center_cluster_robust_px", "scale_vs_predicted", "polarity_split")},
    }
    return fr, g, m, res


def _edge_offsets(fr, shape) -> dict:
    """Median signed offsets (px, < 0 inside) of the image's own edges from the ellipse ``shape``: the dark
    limb (disc darker than the sky) and the lit limb, each found along the ellipse's normals
    (:func:`jaxlimb.imaging.predicted.limb_edges`, +-30 px, masked lines left out).  Small for the measured
    limb and large for the predicted one: the residual is in the prediction, not in the measurement."""
    from jaxlimb.imaging.predicted import limb_edges

    pts, step, ok = limb_edges(fr.data, shape, mask=fr.mask_or_none, search_px=30.0)
    x, y = shape.to_frame(pts)
    # signed distance along the normal, to first order: (r_ellipse(point) - 1) * local radius
    rn = np.sqrt((x / shape.a) ** 2 + (y / (shape.rho * shape.a)) ** 2)
    off = (rn - 1.0) * np.hypot(x, y) / np.where(rn > 0, rn, 1.0)
    out = {}
    for name, sel in (("dark", ok & (step < 0)), ("lit", ok & (step > 0))):
        out[f"{name}_n"] = int(sel.sum())
        out[f"{name}_median_px"] = float(np.median(off[sel])) if sel.any() else None
    return out


def _shapes(g, m):
    from jaxlimb.imaging.predicted import LimbShape

    e = m.ellipse
    meas = LimbShape(tuple(e.center_rc), e.semi_axes_px[0], e.semi_axes_px[1] / e.semi_axes_px[0], e.angle_rad)
    a, b = g.limb.semi_axes_px
    pred = LimbShape(tuple(g.limb.center_rc), float(a), float(b / a), float(g.limb.angle_rad))
    return meas, pred


def _ck_probe(fr, g) -> dict:
    """The CK's pointing about the image time: the camera's angular rate (urad/s, px/s) and the predicted
    centre at -1, -0.5, +0.5, +1 s minus the one at the image time (px)."""
    import spiceypy as sp

    from jaxlimb.geometry.spice import camera_from_ik, instrument_from, loaded_kernels

    with loaded_kernels(KERNELS):
        inst = instrument_from(fr.meta.instrument_id)
        cam, F = camera_from_ik(inst), np.asarray(inst.flip, float)
        et = sp.str2et(fr.meta.image_time)
        X = np.asarray(sp.sxform("J2000", inst.spice_name, et))
        W = X[3:, :3] @ X[:3, :3].T
        w = np.array([W[2, 1], W[0, 2], W[1, 0]])

        def center(t):
            pos, _ = sp.spkpos(g.target, t, "J2000", "CN+S", inst.observer)
            return cam.project(F @ np.asarray(sp.pxform("J2000", inst.spice_name, t)) @ np.asarray(pos))

        c0 = center(et)
        shifts = {f"{dt:+.1f}s": (center(et + dt) - c0).tolist() for dt in (-1.0, -0.5, 0.5, 1.0)}
    return {"rate_urad_s": float(np.linalg.norm(w) * 1e6), "rate_px_s": float(np.linalg.norm(w[:2]) * cam.focal_px),
            "predicted_center_shift_px": shifts}


def _kernel_shape(fr, g) -> dict:
    """The same frame with the held limb shape from the kernels' 2002 PCK radii (``pck00007.tpc``: Voyager's)
    instead of the IAU 2015 table's (Archinal et al. 2018) that the prediction takes: how much of the residual the
    older shape model makes."""
    from dataclasses import replace

    from jaxlimb.geometry.spice import loaded_kernels, spice_body_radii

    with loaded_kernels(KERNELS):
        radii = spice_body_radii(g.target)
    m = locate(fr.data, g.camera, replace(g.hints(), body_radii_km=radii), mask=fr.mask_or_none)
    c = m.covariance
    cov = covariance_block(c).tolist()
    s = m.extras.get("polarity_split") or {}
    return {"radii_km": list(radii), "measured_center_rc": list(m.center_rc), "center_covariance_px2": cov,
            "radius_px": m.radius_px, "range_km": m.range_km, "measured_minus_predicted": pointing_residual(g, m.center_rc, cov),
            "polarity_split_delta_rc_px": s.get("delta_rc_px"), "polarity_split_chi2": s.get("chi2")}


def _registration(fa, fb) -> list[float]:
    import cv2
    from scipy import ndimage

    m = ndimage.binary_erosion(fb.mask, iterations=6)

    def grad(f):
        s = ndimage.gaussian_filter(f.data, 1.5)
        return np.where(m, np.sqrt(np.hypot(ndimage.sobel(s, 0), ndimage.sobel(s, 1))), 0).astype(np.float32)

    (dx, dy), _ = cv2.phaseCorrelate(grad(fa), grad(fb), cv2.createHanningWindow(fa.data.shape[::-1], cv2.CV_32F))
    return [float(dy), float(dx)]


def _figure(runs, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxlimb._io import atomic_path
    from jaxlimb.imaging.predicted import LimbShape

    fig, axs = plt.subplots(2, 2, figsize=(12, 12))
    for row, (name, (fr, g, m, res)) in zip(axs, runs.items()):
        e = m.ellipse
        meas = LimbShape(e.center_rc, e.semi_axes_px[0], e.semi_axes_px[1] / e.semi_axes_px[0], e.angle_rad)
        phi = np.linspace(0, 2 * np.pi, 1440)
        pm = meas.from_frame(meas.a * np.cos(phi), meas.rho * meas.a * np.sin(phi))
        pp = g.limb.points(1440)
        d = res["measured_minus_predicted"]
        for ax, zoom in zip(row, (None, (m.center_rc[0] - m.radius_px - 25, m.center_rc[1] - 90))):
            win = fr.data if zoom is None else fr.data[int(zoom[0]):int(zoom[0]) + 60, int(zoom[1]):int(zoom[1]) + 180]
            ax.imshow(fr.data, cmap="gray", vmin=np.percentile(win, 1), vmax=np.percentile(win, 99.7 if zoom is None else 99))
            ax.plot(pp[:, 1], pp[:, 0], "c-", lw=0.8, label="SPICE prediction")
            ax.plot(pm[:, 1], pm[:, 0], "r-", lw=0.8, label="measured limb")
            ax.plot(*g.center_rc[::-1], "c+", ms=12)
            ax.plot(*m.center_rc[::-1], "r+", ms=12)
            if zoom is not None:
                ax.set_xlim(zoom[1], zoom[1] + 180)
                ax.set_ylim(zoom[0] + 60, zoom[0])
                ax.set_title("zoom: top (dark) limb")
            else:
                ax.set_title(f"{name} ({res['image_time']})\nmeasured - SPICE = ({d['delta_rc_px'][0]:.2f}, "
                             f"{d['delta_rc_px'][1]:.2f}) px = {d['angle_urad']:.1f} urad", fontsize=10)
                ax.legend(loc="lower right", fontsize=8)
    fig.text(0.5, 0.01, "Cassini ISS NAC raw frames and SPICE kernels: NASA/JPL (via the OMINAS demo data)", ha="center")
    fig.tight_layout(rect=(0, 0.02, 1, 1))
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=80, format="png")
    plt.close(fig)


def main() -> dict:
    runs = {f: _one(f) for f in FRAMES}
    (fa, _, ma, ra), (fb, _, mb, rb) = runs[FRAMES[0]], runs[FRAMES[1]]
    da, db = (np.array(r["measured_minus_predicted"]["delta_rc_px"]) for r in (ra, rb))
    sa, sb = (np.sqrt(np.diag(r["center_covariance_px2"])) for r in (ra, rb))
    comb = np.hypot(sa, sb)
    reg = _registration(fa, fb)
    motion = (np.array(mb.center_rc) - np.array(ma.center_rc)).tolist()
    pred_motion = (np.array(rb["predicted_center_rc"]) - np.array(ra["predicted_center_rc"])).tolist()
    out = {
        "frames": {f: r[3] for f, r in runs.items()},
        "residual_change_px": (db - da).tolist(), "combined_sigma_px": comb.tolist(),
        "residual_change_in_sigma": ((db - da) / comb).tolist(),
        "measured_motion_px": motion, "registration_motion_px": reg,
        "measured_minus_registration_px": (np.array(motion) - reg).tolist(),
        "measured_minus_registration_in_sigma": ((np.array(motion) - reg) / comb).tolist(),
        "predicted_motion_px": pred_motion,
        "predicted_minus_registration_px": (np.array(pred_motion) - reg).tolist(),
        "predicted_minus_registration_urad": float(np.hypot(*(np.array(pred_motion) - reg)) / runs[FRAMES[0]][1].camera.focal_px * 1e6),
        "environment": environment(),
    }
    _figure(runs, RESULTS / "cassini_enceladus.png")
    save("cassini_enceladus", out)
    for f, r in out["frames"].items():
        d = r["measured_minus_predicted"]
        print(f"{f}: centre {r['measured_center_rc'][0]:.2f} {r['measured_center_rc'][1]:.2f} "
              f"(sigma {math.sqrt(r['center_covariance_px2'][0][0]):.3f} {math.sqrt(r['center_covariance_px2'][1][1]):.3f}) px; "
              f"measured - SPICE {d['delta_rc_px'][0]:+.2f} {d['delta_rc_px'][1]:+.2f} px ({d['angle_urad']:.1f} urad); "
              f"radius {r['radius_px']:.2f} px, range {r['range_km']:.0f} km (SPICE {r['spice_range_km']:.0f})")
    print("residual change", np.round(db - da, 2), "combined sigma", np.round(comb, 3))
    print("motion measured", np.round(motion, 2), "registration", np.round(reg, 2), "predicted", np.round(pred_motion, 2))
    print("measured - registration in sigma", np.round(out["measured_minus_registration_in_sigma"], 2),
          "; predicted - registration", np.round(out["predicted_minus_registration_px"], 2), "px =",
          round(out["predicted_minus_registration_urad"], 1), "urad")
    for f, r in out["frames"].items():
        w = r["with_kernel_pck_radii"]
        d = w["measured_minus_predicted"]["delta_rc_px"]
        print(f"{f} with the kernels' 2002 PCK radii: range {w['range_km']:.0f} km, centre {w['measured_center_rc'][0]:.2f} {w['measured_center_rc'][1]:.2f} px, "
              f"measured - SPICE {d[0]:+.2f} {d[1]:+.2f} px; lit - dark split "
              f"{w['polarity_split_delta_rc_px'][0]:+.2f} {w['polarity_split_delta_rc_px'][1]:+.2f} px (chi2 {w['polarity_split_chi2']:.0f})")
    for f, r in out["frames"].items():
        ps = r["extras"]["polarity_split"]
        print(f"{f}: lit - dark split {ps['delta_rc_px'][0]:+.2f} {ps['delta_rc_px'][1]:+.2f} px (chi2 {ps['chi2']:.0f})")
    for f, r in out["frames"].items():
        em, ep, ck = r["edges_from_measured_limb"], r["edges_from_predicted_limb"], r["ck"]
        print(f"{f}: image edges from the measured limb: dark {em['dark_median_px']:+.2f} px ({em['dark_n']}), lit "
              f"{em['lit_median_px']:+.2f} px ({em['lit_n']}); from the predicted limb: dark {ep['dark_median_px']:+.2f}, "
              f"lit {ep['lit_median_px']:+.2f} px; CK rate {ck['rate_urad_s']:.1f} urad/s = {ck['rate_px_s']:.2f} px/s")
    print(json.dumps({"figure": str(RESULTS / "cassini_enceladus.png")}))
    return out


if __name__ == "__main__":
    main()
