r"""End-to-end navigation: render the Moon / the Earth from a known spacecraft state, run navigate.

For each case: a known epoch (DE421 for the Moon and Sun, offline) and a known observer
position; the camera is pointed at the body (boresight a little off the body centre so the body
is not on the principal point); the scene is built in the camera frame (body centre
``C_ci (r_b - r_o)``, Sun direction ``C_ci unit(r_sun - r_b)``, Earth orientation
``C_ci R_itrs^T`` at the epoch) and rendered once without noise (electrons, float).  Each Monte
Carlo run adds photon + read noise and digitises (by default 8 bit with 10 DN of extra
Gaussian noise, the Monte Carlo of Aerospace 2015 §7; ``--sensor 12bit`` for the renderer's
default sensor; seeded), writes nothing to disk, and
runs the same code as ``jaxlimb navigate`` (:func:`jaxlimb.cli._navigate.navigate_measurement`
on the measurement of :func:`jaxlimb.cli._navigate.locate_body`).  Reported per case: the mean
position error (bias), its RMS, the predicted 1-sigma, and the normalised error squared
``e^T P^-1 e`` whose mean is 3 (chi^2 with 3 degrees of freedom) when the covariance is right.

Run::

    .venv/bin/python benchmarks/navigate_e2e.py            # >= 100 runs per case
    .venv/bin/python benchmarks/navigate_e2e.py --quick    # 10 runs per case

Writes ``benchmarks/results/navigate_e2e.json`` (git SHA, versions, seeds, per-case numbers).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

EPOCH = "2026-03-01T12:00:00Z"


@dataclass(frozen=True)
class Case:
    """One end-to-end geometry.

    Attributes
    ----------
    name, body
        Label and ``"moon"``/``"earth"``.
    range_km
        Observer - body-centre distance.
    phase_deg
        Wanted Sun-body-observer angle (the observer direction is chosen on a grid to match it).
    latitude_deg
        Geocentric latitude of the observer in the body-fixed frame (Earth only).
    focal_mm, size_px
        Camera focal length and (square) image size; 2.2 um pixels.
    offset_px
        Where the body centre falls, relative to the principal point (row, col) px.
    reflectance
        Renderer photometric model.
    atmosphere_km
        Height of a rendered glow shell (Earth; 0 = none).
    """

    name: str
    body: str
    range_km: float
    phase_deg: float
    latitude_deg: float = 0.0
    focal_mm: float = 16.0
    size_px: int = 600
    offset_px: tuple[float, float] = (23.4, -31.7)
    reflectance: str = "lommel-seeliger"
    atmosphere_km: float = 0.0


CASES = (
    Case("moon-60000km-gibbous", "moon", 60000.0, 40.0, focal_mm=16.0, size_px=600),
    Case("moon-150000km-crescent", "moon", 150000.0, 120.0, focal_mm=16.0, size_px=300),
    Case("moon-380000km-full", "moon", 380000.0, 10.0, focal_mm=16.0, size_px=200),
    Case("earth-380000km-16mm", "earth", 380000.0, 40.0, latitude_deg=30.0, focal_mm=16.0, size_px=340),
    Case("earth-40000km-8mm", "earth", 40000.0, 40.0, latitude_deg=45.0, focal_mm=8.0, size_px=1300),
)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def build_case(case: Case, epoch: str = EPOCH) -> dict[str, Any]:
    """Truth state, attitude, camera and the rendered scene of ``case``."""
    from jaxlimb.cli._navigate import earth_rotation_icrf_to_itrs
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.geometry.ephemeris import body_position
    from jaxlimb.render import EARTH_RADII_KM, MOON_RADIUS_KM, Atmosphere, Scene

    r_sun = body_position("sun", epoch, "earth")
    if case.body == "moon":
        r_b = body_position("moon", epoch, "earth")
        R_if = np.eye(3)  # sphere: orientation irrelevant
        radii = (MOON_RADIUS_KM,) * 3
    else:
        r_b = np.zeros(3)
        R_if = earth_rotation_icrf_to_itrs(epoch)  # ICRF -> ITRS
        radii = EARTH_RADII_KM
    s_hat = _unit(r_sun - r_b)
    # observer direction from the body: latitude fixed (body frame), longitude chosen for the phase
    la = math.radians(case.latitude_deg)
    best = None
    for lon in np.radians(np.arange(0.0, 360.0, 0.25)):
        d_body = np.array([math.cos(la) * math.cos(lon), math.cos(la) * math.sin(lon), math.sin(la)])
        d = R_if.T @ d_body
        ph = math.degrees(math.acos(float(np.clip(d @ s_hat, -1, 1))))
        if best is None or abs(ph - case.phase_deg) < best[0]:
            best = (abs(ph - case.phase_deg), d)
    d = best[1]
    r_o = r_b + case.range_km * d
    cam = Camera(focal_length_mm=case.focal_mm, pixel_pitch_mm=2.2e-3, rows=case.size_px, cols=case.size_px)
    # attitude: the body centre appears at principal point + offset_px
    u_b = _unit(r_b - r_o)
    x_ref = _unit(np.cross(u_b, np.array([0.0, 0.0, 1.0])))
    y_ref = np.cross(u_b, x_ref)
    C0 = np.stack([x_ref, y_ref, u_b])  # inertial -> a camera frame with the body on the boresight
    # tilt the boresight so the body lands at offset_px: the body's camera direction is los(pp + offset)
    pp = np.array(cam.principal_point_rc)
    v_cam = cam.los(pp + np.array(case.offset_px))
    # rotation taking z to v_cam (in the camera frame)
    z = np.array([0.0, 0.0, 1.0])
    ax = np.cross(z, v_cam)
    ang = math.atan2(np.linalg.norm(ax), float(z @ v_cam))
    ax = ax / np.linalg.norm(ax)
    K = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
    Rz = np.eye(3) + math.sin(ang) * K + (1 - math.cos(ang)) * K @ K  # active: Rz @ z = v_cam
    C_ci = Rz @ C0
    q = C_ci @ (r_b - r_o)
    scene = Scene(
        radii=tuple(radii),
        center_cam=tuple(q),
        R_body_to_camera=C_ci @ R_if.T,
        sun_dir_cam=tuple(C_ci @ s_hat),
        atmosphere=Atmosphere(height_km=case.atmosphere_km) if case.atmosphere_km > 0 else None,
        name=case.body,
    )
    return {"case": case, "epoch": epoch, "r_o": r_o, "r_b": r_b, "C_ci": C_ci, "camera": cam, "scene": scene,
            "phase_deg": math.degrees(scene.phase_angle_rad)}


def render_clean(built: dict[str, Any]) -> tuple[np.ndarray, Any]:
    """Noise-free frame in electrons (background included) and the render truth."""
    from jaxlimb.render import RenderOptions, render_body

    opt = RenderOptions(reflectance=built["case"].reflectance, noise=False, bit_depth=None)
    return render_body(built["scene"], built["camera"], opt, seed=0)


SENSORS = {
    # Aerospace 2015 §7 Monte Carlo: 8-bit frames, sigma = 10 grey levels (plus photon and read noise)
    "8bit-10dn": {"bit_depth": 8, "extra_noise_dn": 10.0, "pedestal_dn": 30.0},
    # the renderer's default sensor: 12 bit, photon + read noise only (SNR ~130 at the limb)
    "12bit": {"bit_depth": 12, "extra_noise_dn": 0.0, "pedestal_dn": 0.0},
}


def noisy(frame_e: np.ndarray, seed: int, sensor: str = "8bit-10dn") -> np.ndarray:
    """Digitised frame with photon, read and extra Gaussian noise (:data:`SENSORS`), seeded.

    The 8-bit sensor has a dark pedestal of 30 DN (3 sigma), as real sensors do: without it the
    noise of the sky is clipped at 0 DN, the mean of the clipped pixels is no longer the edge
    model, and the fitted limb moves outward (measured: a 1.8 km range bias at 40 000 km).
    """
    from jaxlimb.render import RenderOptions
    from jaxlimb.render.sensor import digitise

    s = SENSORS[sensor]
    o = RenderOptions(bit_depth=s["bit_depth"])
    return digitise(frame_e + s["pedestal_dn"] * o.gain, np.random.default_rng(seed), bit_depth=o.bit_depth, full_well_e=o.full_well_e,
                    gain_e_per_dn=o.gain, read_noise_e=o.read_noise_e, extra_noise_dn=s["extra_noise_dn"],
                    photon_noise=True)


def hints_for(built: dict[str, Any], truth) -> dict[str, Any]:
    """The navigation filter's prior: body, range (1 % off), Sun direction."""
    return {"body": built["case"].body, "range_prior_km": 1.01 * truth.range_km, "sun_dir_camera": list(truth.sun_dir_cam)}


PROFILE: dict[str, str | None] = {"moon": None, "earth": None}
"""``--moon-profile`` / ``--earth-profile``: the limb model (``LocateOptions.profile`` /
``LocateOptions.profile``) per body; ``None`` = the CLI's default (auto)."""


def run_once(built: dict[str, Any], image: np.ndarray, truth) -> dict[str, Any]:
    """``jaxlimb navigate`` on one image (same code path as the CLI)."""
    from dataclasses import replace

    from jaxlimb.cli._navigate import earth_rotation_icrf_to_itrs, locate_body, navigate_measurement
    from jaxlimb.imaging import Hints

    case = built["case"]
    hints = Hints.from_dict(hints_for(built, truth))
    if case.body == "earth":
        R = built["C_ci"] @ earth_rotation_icrf_to_itrs(built["epoch"]).T
        hints = replace(hints, R_body_to_camera=R.tolist())
    if case.body == "earth" and PROFILE["earth"] is not None:
        from jaxlimb.pipeline import LocateOptions, locate

        meas = locate(image, built["camera"], hints, LocateOptions(profile=PROFILE["earth"]))
    elif case.body == "moon" and PROFILE["moon"] is not None:
        from jaxlimb.pipeline import LocateOptions, locate

        meas = locate(image, built["camera"], hints, LocateOptions(profile=PROFILE["moon"]))
    else:
        meas = locate_body(case.body, image, built["camera"], hints)
    out = navigate_measurement(case.body, meas, built["camera"], built["C_ci"], built["epoch"])
    e = np.asarray(out["position_km"]) - built["r_o"]
    P = np.asarray(out["covariance_km2"])
    out["error_km"] = e.tolist()
    out["nees"] = float(e @ np.linalg.solve(P, e))
    return out


def monte_carlo(case: Case, n_runs: int, seed: int, progress: bool = True, sensor: str = "8bit-10dn") -> dict[str, Any]:
    built = build_case(case)
    t0 = time.perf_counter()
    frame, truth = render_clean(built)
    t_render = time.perf_counter() - t0
    errs, nees, sig, t_runs, fails = [], [], [], [], []
    it = range(n_runs)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc=case.name, file=sys.stderr)
    for k in it:
        img = noisy(frame, seed + k, sensor)
        t1 = time.perf_counter()
        try:
            out = run_once(built, img, truth)
        except Exception as e:  # recorded, not hidden: a failed run counts in the table
            fails.append(f"{type(e).__name__}: {e}")
            continue
        t_runs.append(time.perf_counter() - t1)
        errs.append(out["error_km"])
        nees.append(out["nees"])
        sig.append(out["sigma_km"])
    errs = np.asarray(errs)
    nees = np.asarray(nees)
    n = len(nees)
    # chi^2(3) mean 3, sd of the mean sqrt(6/n): the 99 % band of the mean
    band = 2.576 * math.sqrt(6.0 / max(n, 1))
    return {
        "case": case.__dict__ | {"offset_px": list(case.offset_px)},
        "phase_deg": built["phase_deg"],
        "range_km": truth.range_km,
        "n_runs": n_runs,
        "n_ok": n,
        "failures": fails[:5],
        "n_failures": len(fails),
        "bias_km": errs.mean(0).tolist() if n else None,
        "bias_norm_km": float(np.linalg.norm(errs.mean(0))) if n else None,
        "rms_error_km": float(np.sqrt((errs**2).sum(1).mean())) if n else None,
        "predicted_sigma_km": np.mean(sig, axis=0).tolist() if n else None,
        "predicted_sigma_norm_km": float(np.sqrt((np.asarray(sig) ** 2).sum(1).mean())) if n else None,
        "mean_nees": float(nees.mean()) if n else None,
        "median_nees": float(np.median(nees)) if n else None,
        "nees_99pct_band_of_mean": [3 - band, 3 + band],
        "render_s": t_render,
        "median_run_s": float(np.median(t_runs)) if t_runs else None,
        "seed": seed,
        "sensor": sensor,
    }


def earth_targets(n_noise: int, seed: int, reflectance: str = "lommel-seeliger",
                  profile: str | None = None) -> list[dict[str, Any]]:
    """The Earth targets: centre <= 0.1 px and range <= 0.1 % (known attitude).

    Earth at 380 000 km (16 mm, 340 px crop) and 40 000 km (8 mm, 1300 px), observer latitude
    0 / 30 / 60 deg, gibbous (40 deg phase); variants: ``R_body_to_camera`` known (default),
    unknown (free ellipse), and a 100 km glow shell rendered (``Atmosphere(100)``, scale height
    8 km) with ``atmosphere_km = 0`` in the hints.  ``n_noise`` 12-bit noise realisations each.
    """
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.imaging import Hints
    from jaxlimb.pipeline import LocateOptions, locate
    from jaxlimb.render import Atmosphere, RenderOptions, earth_scene, render_body

    opts = None if profile is None else LocateOptions(profile=profile)
    rows = []
    for D, f, size in ((380000.0, 16.0, 340), (40000.0, 8.0, 1300)):
        cam = Camera(focal_length_mm=f, rows=size, cols=size)
        for lat in (0.0, 30.0, 60.0):
            for variant in ("known_R", "free", "glow100"):
                atm = Atmosphere(height_km=100.0) if variant == "glow100" else None
                sc = earth_scene(D, lat, 40.0, center_rc=(size / 2 - 9.4, size / 2 + 13.1), camera=cam,
                                 sun_angle_deg=30.0, north_angle_deg=75.0, atmosphere=atm)
                frame, truth = render_body(sc, cam, RenderOptions(reflectance=reflectance, noise=False, bit_depth=None), seed=0)
                h = {"body": "earth", "range_prior_km": 1.01 * D, "sun_dir_camera": list(truth.sun_dir_cam)}
                if variant != "free":
                    h["R_body_to_camera"] = np.asarray(sc.R_body_to_camera).tolist()
                hints = Hints.from_dict(h)
                dc, dr, sc_, sr_, its, fits, ts = [], [], [], [], [], [], []
                for k in range(n_noise):
                    img = noisy(frame, seed + k, "12bit")
                    t0 = time.perf_counter()
                    m = locate(img, cam, hints, opts)
                    ts.append(time.perf_counter() - t0)
                    dc.append(np.subtract(m.center_rc, truth.center_rc))
                    dr.append(100.0 * (m.range_km / truth.range_km - 1))
                    sc_.append(math.hypot(math.sqrt(m.covariance["center_r"]["center_r"]), math.sqrt(m.covariance["center_c"]["center_c"])))
                    sr_.append(100.0 * math.sqrt(m.covariance["range_km"]["range_km"]) / truth.range_km)
                    its.append(max(ff["range_iterations"] for ff in m.extras["fits"]))
                    fits.append(len(m.extras["fits"]))
                dc = np.asarray(dc)
                rows.append({
                    "range_km": D, "focal_mm": f, "latitude_deg": lat, "variant": variant, "reflectance": reflectance,
                    "center_err_px_mean": float(np.hypot(*dc.mean(0))), "center_err_px_max": float(np.hypot(dc[:, 0], dc[:, 1]).max()),
                    "range_err_pct_mean": float(np.mean(dr)), "range_err_pct_maxabs": float(np.max(np.abs(dr))),
                    "pred_center_sigma_px": float(np.mean(sc_)), "pred_range_sigma_pct": float(np.mean(sr_)),
                    "max_range_iterations": int(max(its)), "max_fits": int(max(fits)),
                    "gamma_off_px": truth.gamma_off_rad * cam.focal_px, "median_s": float(np.median(ts)),
                    "model": m.extras.get("model"), "profile_L": m.extras.get("profile", {}).get("L"),
                })
                r = rows[-1]
                print(f"{D:8.0f} km {f:4.0f} mm lat {lat:4.0f} {variant:8s}: centre {r['center_err_px_mean']:.3f} px "
                      f"(max {r['center_err_px_max']:.3f}, 1s {r['pred_center_sigma_px']:.3f}), range {r['range_err_pct_mean']:+.4f} % "
                      f"(1s {r['pred_range_sigma_pct']:.4f}), iters {r['max_range_iterations']}, fits {r['max_fits']}, "
                      f"gamma_off {r['gamma_off_px']:.3f} px, {r['median_s']:.2f} s", file=sys.stderr)
    return rows


def _meta() -> dict[str, Any]:
    import jaxlimb
    from _common import environment

    return {**environment(), "jaxlimb": getattr(jaxlimb, "__version__", None), "epoch": EPOCH}


def table(results: list[dict[str, Any]]) -> str:
    hdr = f"{'case':28s} {'phase':>6s} {'runs':>5s} {'fail':>4s} {'|bias| km':>10s} {'rms km':>9s} {'pred 1s km':>10s} {'mean NEES':>9s}"
    lines = [hdr, "-" * len(hdr)]
    for r in results:
        lines.append(
            f"{r['case']['name']:28s} {r['phase_deg']:6.1f} {r['n_ok']:5d} {r['n_failures']:4d} "
            f"{r['bias_norm_km'] or float('nan'):10.3f} {r['rms_error_km'] or float('nan'):9.3f} "
            f"{r['predicted_sigma_norm_km'] or float('nan'):10.3f} {r['mean_nees'] or float('nan'):9.2f}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="10 runs per case")
    ap.add_argument("--runs", type=int, default=100, help="runs per case (default 100)")
    ap.add_argument("--seed", type=int, default=20261122)
    ap.add_argument("--reflectance", default=None, help="override the cases' reflectance (e.g. uniform)")
    ap.add_argument("--cases", default=None, help="comma-separated case names (default all)")
    ap.add_argument("--out", default=None,
                    help="output JSON (default results/navigate_e2e.json, or results/earth_targets*.json)")
    ap.add_argument("--sensor", choices=sorted(SENSORS), default="8bit-10dn",
                    help="noise model (default: 8 bit, 10 DN, the Aerospace 2015 Monte Carlo)")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--earth-targets", action="store_true",
                    help="instead: the Earth locate targets (latitudes 0/30/60, known R / free / glow), "
                    "writes results/earth_targets.json")
    ap.add_argument("--earth-profile", choices=("auto", "sigmoid", "lunar-lambert"), default=None,
                    help="Earth limb model (LocateOptions.profile; default: the CLI's, i.e. auto)")
    ap.add_argument("--moon-profile", choices=("auto", "sigmoid", "lunar-lambert"), default=None,
                    help="Moon limb model (LocateOptions.profile; default: the CLI's, i.e. auto)")
    args = ap.parse_args(argv)
    args.out_given = args.out is not None
    if args.out is None:
        args.out = str(Path(__file__).parent / "results" / "navigate_e2e.json")
    PROFILE.update(moon=args.moon_profile, earth=args.earth_profile)
    if args.earth_targets:
        rows = earth_targets(2 if args.quick else 5, args.seed, args.reflectance or "lommel-seeliger", args.earth_profile)
        name = "earth_targets.json" if not args.reflectance else f"earth_targets_{args.reflectance}.json"
        p = Path(args.out) if args.out_given else Path(args.out).with_name(name)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps({"meta": _meta(), "rows": rows}, indent=1))
        print(f"wrote {p}")
        return 0
    n = 10 if args.quick else args.runs
    cases = [c for c in CASES if args.cases is None or c.name in args.cases.split(",")]
    if args.reflectance:
        from dataclasses import replace

        cases = [replace(c, reflectance=args.reflectance) for c in cases]
    results = [monte_carlo(c, n, args.seed + 1000 * i, progress=not args.no_progress, sensor=args.sensor) for i, c in enumerate(cases)]
    print(table(results))
    out = {"meta": _meta(), "runs_per_case": n, "sensor": args.sensor, "reflectance_override": args.reflectance,
           "results": results}
    p = Path(args.out)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(out, indent=1))
    print(f"wrote {p}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
