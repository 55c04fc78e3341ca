"""Cassini ISS NAC frames of Enceladus: measured limb vs the SPICE prediction, end to end.

Both raw frames of ``shared/data/cassini`` (VICAR, read with rms-vicar; the second has 38
missing lines, masked) are located with the mission's own kernels and nothing typed by hand:
camera from the IK, image time from the label, predicted limb / Sun / range / orientation
from SPICE (:mod:`jaxlimb.geometry.spice`), the whole-limb stage
(:mod:`jaxlimb.pipeline.whole_limb`).  Reported per frame: the measured body centre and its
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
from jaxlimb.pipeline import locate  # noqa: E402

CASSINI = shared_data_dir() / "cassini"
KERNELS = sorted(str(p) for p in (CASSINI / "kernels").iterdir())
FRAMES = ("N1511803932_1", "N1511803965_3")


def _one(name: str):
    fr = read_frame(CASSINI / f"{name}.IMG")
    g = spice_geometry(KERNELS, fr.meta.image_time, fr.meta.instrument_id, fr.meta.target_name)
    m = locate(fr.data, g.camera, g.hints(), mask=fr.mask_or_none)
    c = m.covariance
    cov = [[c["center_r"]["center_r"], c["center_r"]["center_c"]], [c["center_c"]["center_r"], c["center_c"]["center_c"]]]
    res = {
        "image_time": fr.meta.image_time, "n_masked": fr.n_invalid,
        "measured_center_rc": list(m.center_rc), "center_covariance_px2": cov,
        "predicted_center_rc": list(g.center_rc),
        "measured_minus_predicted": pointing_residual(g, m.center_rc, cov),
        "radius_px": m.radius_px, "range_km": m.range_km, "spice_range_km": g.range_km,
        "spice_radii_km": list(g.radii_km),
        "observer": observer_from_measurement(g, m.los_camera, m.range_km),
        "extras": {k: m.extras[k] for k in ("edge_fit", "angular_bins", "sigma_center_pixel_independent_px",
                                             "sigma_center_cluster_robust_px", "scale_vs_predicted")},
    }
    return fr, g, m, res


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
    out = {
        "frames": {f: r[3] for f, r in runs.items()},
        "residual_change_px": (db - da).tolist(), "combined_sigma_px": comb.tolist(),
        "residual_change_in_sigma": ((db - da) / comb).tolist(),
        "measured_motion_px": motion, "registration_motion_px": reg,
        "measured_minus_registration_px": (np.array(motion) - reg).tolist(),
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
    print("motion measured", np.round(motion, 2), "registration", np.round(reg, 2))
    print(json.dumps({"figure": str(RESULTS / "cassini_enceladus.png")}))
    return out


if __name__ == "__main__":
    main()
