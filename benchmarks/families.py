"""Per-family accuracy of ``jaxlimb.pipeline.locate`` on scenes from the independent renderer.

Usage::

    .venv/bin/python benchmarks/families.py [--quick] [--n N] [--seed S] [--bodies moon,earth]
                                            [--families own,maria,...] [--cache DIR] [--out NAME]

Scenes: :mod:`jaxlimb.render.independent` (written apart from the pipeline and its renderer),
``--n`` frames per family and body (default 6; ``--quick``: 1 frame of a few families).  The
family ``own`` is what the pipeline's physical profile assumes (uniform albedo, lunar-Lambert,
Gaussian PSF); every other family changes what the module docstring of
:mod:`jaxlimb.render.independent.families` lists.  ``locate`` gets the camera and the hints a
navigation filter has (body, Sun direction, range prior 5 % off; for the Earth also
``R_body_to_camera`` and ``atmosphere_km = 0``).  Each Earth frame is measured twice: with
``R_body_to_camera`` known and without it (``earth`` / ``earth_noR`` rows).  An ``earth_noR`` frame also
gets ``floor_px``: the centre error of its *true* limb ellipse mapped without the pole
(:func:`pole_unknown_floor_px`), the error no limb-only estimator can go below without the attitude (the
centre offset cannot be signed, :mod:`jaxlimb.pipeline.ellipsoid`, "Free ellipse").  Each body also gets an ``all``
row: the families pooled.

Reported per body and family: centre-of-body-image error (px) median / p90 / max, |radius
error| median (Moon: ``radius_px - f tan(alpha)``), |range error| median / max (%), the mean
NEES of the centre ``e^T P^-1 e`` with the reported 2x2 covariance (chi-square expectation 2), the mean
NEES of the range ``(e / sigma)^2`` with its reported variance (expectation 1; ``range_z`` per record; ``crlb_rc``:
the centre's noise-only Cramér--Rao sigmas ``locate`` reports),
typed failures by check, and the number of ``status ok`` answers with a non-physical
parameter (amplitude <= 0, ymax <= ymin, PSF sigma outside [0.1, 5] px, ``L`` outside
[-0.5, 1.5], a glow outside [0, 1] of ``amp`` (at the Sun's position angle and square to it) or its scale height outside [0.05, 10] px, non-finite or non-positive radius/range, centre sigma > 2 px).  Results go to
``benchmarks/results/<out>.json`` (default ``families``, ``families_quick`` with ``--quick``)
with the seed and the git SHA.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from jaxlimb.geometry.earth_cone import earth_position_from_ellipse

sys.path.insert(0, str(Path(__file__).resolve().parent))

QUICK_FAMILIES = {"moon": ("own", "maria"), "earth": ("own", "clouds")}
RENDER_VERSION = 1  # bump when the renderer's output changes (cache key)


def _setup() -> None:
    import jax

    jax.config.update("jax_enable_x64", True)


def family_case(body: str, family: str, idx: int, seed: int, cache: Path | None):
    """Render (or load from ``cache``) frame ``idx`` of ``family``."""
    from _common import cached

    from jaxlimb.render.independent import EARTH_FAMILIES, MOON_FAMILIES, earth_case, moon_case

    fams = MOON_FAMILIES if body == "moon" else EARTH_FAMILIES
    rng = np.random.default_rng([seed, 0 if body == "moon" else 1, fams.index(family), idx])
    return cached(cache, f"{body}_{family}_{idx}_s{seed}_v{RENDER_VERSION}.pkl",
                  lambda: moon_case(family, rng) if body == "moon" else earth_case(family, rng, far=bool(idx % 2)))


def _locate(case, hints: dict, options=None):
    """The public entry point, the same for every body (``jaxlimb.pipeline.locate``)."""
    from jaxlimb.imaging import Hints
    from jaxlimb.pipeline import locate

    return locate(case.image, case.camera, Hints.from_dict(hints), options)


def _options(center_floor_px: float | None, unresolved_glow: bool = True, profile: str = "auto"):
    """``LocateOptions`` for ``--center-floor`` (``EllipsoidOptions.center_floor_px``), ``--no-unresolved-glow``
    (``EllipsoidOptions.unresolved_glow = None``) and ``--profile``; ``None``: the defaults."""
    from jaxlimb.pipeline import LocateOptions
    from jaxlimb.pipeline import EllipsoidOptions

    kw = {} if center_floor_px is None else {"center_floor_px": center_floor_px}
    if not unresolved_glow:
        kw["unresolved_glow"] = None
    if not kw and profile == "auto":
        return None
    return LocateOptions(profile=profile, ellipsoid=EllipsoidOptions(**kw) if kw else None)


def nonphysical(m) -> list[str]:
    """Reasons a ``status ok`` measurement is not physical (module docstring); empty if none."""
    bad = []
    if not (m.ymax > m.ymin):
        bad.append("ymax<=ymin")
    prof = (m.extras or {}).get("profile") or {}
    if "amp" in prof and not prof["amp"] > 0:
        bad.append("amp<=0")
    if "psf_sigma_px" in prof and not 0.1 <= prof["psf_sigma_px"] <= 5.0:
        bad.append("psf_sigma")
    if "L" in prof and not -0.5 <= prof["L"] <= 1.5:
        bad.append("L")
    g, g1 = prof.get("glow", 0.0), prof.get("glow", 0.0) * (1.0 + prof.get("glow_tilt", 0.0))  # cpsi = 0 and 1
    if not (0.0 <= g <= 1.0 and 0.0 <= g1 <= 1.0) or not 0.05 <= prof.get("glow_scale_px", 1.0) <= 10.0:
        bad.append("glow")
    if m.radius_px is not None and not (math.isfinite(m.radius_px) and m.radius_px > 0):
        bad.append("radius")
    if m.range_km is not None and not (math.isfinite(m.range_km) and m.range_km > 0):
        bad.append("range")
    cov = m.covariance
    s = max(cov.get("center_r", {}).get("center_r", math.inf), cov.get("center_c", {}).get("center_c", math.inf))
    if not (math.isfinite(s) and math.sqrt(max(s, 0.0)) <= 2.0):
        bad.append("center_sigma")
    return bad


def _nees(m, err: np.ndarray) -> float | None:
    c = m.covariance
    try:
        from jaxlimb.pipeline import covariance_block
        P = covariance_block(c)
        return float(err @ np.linalg.solve(P, err))
    except (KeyError, np.linalg.LinAlgError):
        return None


def pole_unknown_floor_px(case) -> float:
    """The centre error (px) of the frame's true limb ellipse mapped with the pole unknown (the cone axis,
    :func:`jaxlimb.geometry.earth_cone.earth_position_from_ellipse` without ``pole_camera``): ``|gamma_off|`` in
    pixels, the unsigned centre offset of the spheroid (two mirror attitudes give the same limb and centres
    ``2 gamma_off`` apart, ``tests/pipeline_earth/test_earth_pipeline.py``), plus the mapping's own error."""

    t = case.truth
    p, _ = earth_position_from_ellipse(case.camera, t.ellipse_center_rc, t.semi_axes_px, t.angle_rad, np.zeros(3))
    return float(np.hypot(*(np.asarray(case.camera.project(-p)) - np.asarray(t.body_center_rc))))


def measure(case, hints: dict, options=None) -> dict[str, Any]:
    """One ``locate`` run (``options``: ``LocateOptions`` or ``None``) against the truth of ``case``."""
    from jaxlimb.errors import JaxlimbError

    t = case.truth
    rec: dict[str, Any] = {}
    t0 = time.perf_counter()
    try:
        m = _locate(case, hints, options)
    except JaxlimbError as e:
        rec.update(status="error", check=e.check, message=str(e)[:200])
        return rec
    rec["time_s"] = time.perf_counter() - t0
    err = np.array(m.center_rc) - np.array(t.body_center_rc)
    c = m.covariance
    rec.update(status="ok", center_err_px=float(np.hypot(*err)), err_rc=err.tolist(), nees=_nees(m, err),
               nonphysical=nonphysical(m),
               cov_rc=[[c.get("center_r", {}).get(a) for a in ("center_r", "center_c")],
                       [c.get("center_c", {}).get(a) for a in ("center_r", "center_c")]])
    if m.radius_px is not None and case.meta["body"] == "moon":
        rec["radius_err_px"] = float(m.radius_px - t.apparent_radius_px)
    if m.range_km is not None:
        rec["range_err_pct"] = float(100.0 * (m.range_km - t.range_km) / t.range_km)
        var = c.get("range_km", {}).get("range_km")
        if var is not None and var > 0:  # the range's normalised error (its 1-dof NEES is z^2)
            rec["range_z"] = float((m.range_km - t.range_km) / math.sqrt(var))
    if m.crlb is not None and "center_r" in m.crlb:  # noise-only Cramer-Rao sigmas at the estimate (px)
        rec["crlb_rc"] = [float(m.crlb["center_r"]), float(m.crlb["center_c"])]
    rec["profile"] = (m.extras or {}).get("profile")
    rec["profile_rejected"] = (m.extras or {}).get("profile_rejected")
    return rec


def _q(a, q):
    return float(np.percentile(a, q)) if len(a) else None


def summarise(recs: list[dict]) -> dict[str, Any]:
    ok = [r for r in recs if r["status"] == "ok"]
    ce = [r["center_err_px"] for r in ok]
    ne = [r["nees"] for r in ok if r.get("nees") is not None]
    rad = [abs(r["radius_err_px"]) for r in ok if "radius_err_px" in r]
    rg = [abs(r["range_err_pct"]) for r in ok if "range_err_pct" in r]
    rz = [r["range_z"] ** 2 for r in ok if "range_z" in r]
    fails: dict[str, int] = {}
    for r in recs:
        if r["status"] != "ok":
            fails[r["check"]] = fails.get(r["check"], 0) + 1
    return {"n": len(recs), "n_ok": len(ok), "center_median_px": _q(ce, 50), "center_p90_px": _q(ce, 90),
            "center_max_px": max(ce) if ce else None, "radius_abs_median_px": _q(rad, 50),
            "range_abs_median_pct": _q(rg, 50), "range_abs_max_pct": max(rg) if rg else None,
            "nees_mean": float(np.mean(ne)) if ne else None,
            "range_nees_mean": float(np.mean(rz)) if rz else None, "failures": fails,
            "n_ok_nonphysical": sum(1 for r in ok if r["nonphysical"]),
            **({"floor_median_px": _q(fl, 50)} if (fl := [r["floor_px"] for r in recs if "floor_px" in r]) else {})}


def _fmt(v, f="{:.3f}"):
    return "-" if v is None else f.format(v)


def print_table(summary: dict[str, dict[str, dict]]) -> None:
    print(f"{'body':10s} {'family':10s} {'n/ok':>6s} {'med':>7s} {'p90':>7s} {'max':>7s} {'|dR|':>7s} "
          f"{'rng%med':>8s} {'rng%max':>8s} {'NEES':>8s} {'rngNEES':>8s} {'nonphys':>7s}  failures")
    for body, fams in summary.items():
        for fam, s in fams.items():
            print(f"{body:10s} {fam:10s} {s['n']:>3d}/{s['n_ok']:<2d} {_fmt(s['center_median_px']):>7s} "
                  f"{_fmt(s['center_p90_px']):>7s} {_fmt(s['center_max_px']):>7s} {_fmt(s['radius_abs_median_px']):>7s} "
                  f"{_fmt(s['range_abs_median_pct'], '{:.4f}'):>8s} {_fmt(s['range_abs_max_pct'], '{:.4f}'):>8s} "
                  f"{_fmt(s['nees_mean'], '{:.1f}'):>8s} {_fmt(s.get('range_nees_mean'), '{:.1f}'):>8s} "
                  f"{s['n_ok_nonphysical']:>7d}  {s['failures'] or ''}"
                  + (f"  floor {s['floor_median_px']:.3f}" if "floor_median_px" in s else ""))


def run(bodies, families, n: int, seed: int, cache: Path | None, progress=print, options=None) -> dict[str, Any]:
    from jaxlimb.render.independent import EARTH_FAMILIES, MOON_FAMILIES

    records: dict[str, dict[str, list]] = {}
    for body in bodies:
        fams = [f for f in (MOON_FAMILIES if body == "moon" else EARTH_FAMILIES) if families is None or f in families]
        for fam in fams:
            for i in range(n):
                case = family_case(body, fam, i, seed, cache)
                rows = [(body, case.hints)]
                if body == "earth":
                    rows.append(("earth_noR", {k: v for k, v in case.hints.items() if k != "R_body_to_camera"}))
                for name, hints in rows:
                    rec = measure(case, hints, options)
                    rec["meta"] = case.meta
                    if name == "earth_noR":
                        rec["floor_px"] = pole_unknown_floor_px(case)
                    records.setdefault(name, {}).setdefault(fam, []).append(rec)
                    progress(f"{name:9s} {fam:9s} {i}: {rec['status']} "
                             + (f"{rec['center_err_px']:.3f} px" if rec["status"] == "ok" else rec["check"]))
    summary = {b: {**{f: summarise(r) for f, r in fams.items()}, "all": summarise([x for r in fams.values() for x in r])}
               for b, fams in records.items()}
    return {"records": records, "summary": summary}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="1 frame of 2 families per body")
    ap.add_argument("--n", type=int, default=None, help="frames per family and body (default 6)")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--bodies", default="moon,earth")
    ap.add_argument("--families", default=None, help="comma-separated subset")
    ap.add_argument("--cache", type=Path, default=None, help="directory to keep rendered frames in between runs")
    ap.add_argument("--out", default=None)
    ap.add_argument("--center-floor", type=float, default=None,
                    help="EllipsoidOptions.center_floor_px for the Earth (default: the library's)")
    ap.add_argument("--no-unresolved-glow", action="store_false", dest="unresolved_glow",
                    help="EllipsoidOptions.unresolved_glow = None for the Earth (the fit's covariance alone)")
    ap.add_argument("--profile", default="auto", help="LocateOptions.profile (default auto)")
    a = ap.parse_args(argv)
    _setup()
    from _common import environment, save

    bodies = [b for b in a.bodies.split(",") if b]
    fams = set(a.families.split(",")) if a.families else None
    if a.quick and fams is None:
        fams = set(QUICK_FAMILIES["moon"]) | set(QUICK_FAMILIES["earth"])
    n = a.n if a.n is not None else (1 if a.quick else 6)
    t0 = time.perf_counter()
    res = run(bodies, fams, n, a.seed, a.cache, options=_options(a.center_floor, a.unresolved_glow, a.profile))
    print_table(res["summary"])
    out = {"args": {"n": n, "seed": a.seed, "bodies": bodies, "families": sorted(fams) if fams else None,
                    "quick": a.quick, "center_floor_px": a.center_floor,
                    "unresolved_glow": a.unresolved_glow, "profile": a.profile}, "environment": environment(), "wall_s": time.perf_counter() - t0, **res}
    path = save(a.out or ("families_quick" if a.quick else "families"), out)
    print(f"saved {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
