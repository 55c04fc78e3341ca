"""The Earth's centre with the attitude unknown, with and without the Sun-declination pole bound.

Usage::

    .venv/bin/python benchmarks/earth_pole_prior.py [--families own,lambert,...] [--n 6] [--seed 2026]
                                                   [--free-sun] [--cache DIR] [--out NAME]

Scenes: :func:`jaxlimb.render.independent.earth_case` (the independent renderer, ``benchmarks/families.py``'s Earth
frames) with the Sun drawn within 23.44 deg of the equator, as the real Sun is (``sun_declination_max_deg``; with
``--free-sun`` the Sun is placed freely, as in ``benchmarks/families.py``: the bound is then false for some frames).
Each frame is measured by ``locate`` without ``R_body_to_camera`` twice: the defaults (the cone axis, the unsigned
offset carried as a uniform error) and ``EllipsoidOptions(sun_declination_max_deg=23.44)``
(:mod:`jaxlimb.pipeline.ellipsoid.pole_prior`).  Prints per frame and per setting the centre error, NEES and the pole-unknown
floor (``benchmarks/families.py``), and writes ``benchmarks/results/<out>.json`` (default ``earth_pole_prior``, or
``earth_pole_prior_free_sun``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

OBLIQUITY_DEG = 23.44
RENDER_VERSION = 1  # of the real-Sun frames' cache files


def _case(family: str, idx: int, seed: int, cache: Path | None, free_sun: bool):
    from _common import cached
    from families import family_case as families_case

    from jaxlimb.render.independent import EARTH_FAMILIES, earth_case

    if free_sun:  # exactly benchmarks/families.py's frame (and its cache file)
        return families_case("earth", family, idx, seed, cache)
    rng = np.random.default_rng([seed, 1, EARTH_FAMILIES.index(family), idx])
    return cached(cache, f"earth_realsun_{family}_{idx}_s{seed}_v{RENDER_VERSION}.pkl",
                  lambda: earth_case(family, rng, far=bool(idx % 2), sun_declination_max_deg=OBLIQUITY_DEG))


def _row(case) -> dict[str, Any]:
    from families import measure, pole_unknown_floor_px

    from jaxlimb.pipeline import LocateOptions
    from jaxlimb.pipeline import EllipsoidOptions

    hints = {k: v for k, v in case.hints.items() if k != "R_body_to_camera"}
    bound = LocateOptions(ellipsoid=EllipsoidOptions(sun_declination_max_deg=OBLIQUITY_DEG))
    return {"meta": case.meta, "floor_px": pole_unknown_floor_px(case), "default": measure(case, hints),
            "bound": measure(case, hints, bound)}


def _summary(rows: list[dict], key: str) -> dict[str, Any]:
    ok = [r[key] for r in rows if r[key]["status"] == "ok"]
    e = np.array([r["center_err_px"] for r in ok])
    nees = [r["nees"] for r in ok if r.get("nees") is not None]
    out: dict[str, Any] = {"n": len(rows), "n_ok": len(ok)}
    if len(e):
        out.update(median_px=float(np.median(e)), p90_px=float(np.percentile(e, 90)), max_px=float(e.max()),
                   mean_nees=float(np.mean(nees)) if nees else None)
    return out


def main(argv=None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    from _common import add_earth_frame_args, environment, save

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_earth_frame_args(ap)
    ap.add_argument("--free-sun", action="store_true", help="the Sun placed freely (benchmarks/families.py's frames)")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    rows = []
    for fam in a.families.split(","):
        for i in range(a.n):
            r = _row(_case(fam, i, a.seed, a.cache, a.free_sun))
            r.update(family=fam, index=i)
            rows.append(r)
            d, b = r["default"], r["bound"]
            fmt = (lambda m: f"{m['center_err_px']:.3f} px NEES {m['nees']:.1f}" if m["status"] == "ok"
                   else m.get("check", "error"))
            print(f"{fam:9s} {i} {'far ' if r['meta']['range_km'] > 1e5 else 'near'} floor {r['floor_px']:.3f}: "
                  f"default {fmt(d)} | bound {fmt(b)}", flush=True)
    summary = {"default": _summary(rows, "default"), "bound": _summary(rows, "bound")}
    for k in ("near", "far"):
        sel = [r for r in rows if (r["meta"]["range_km"] > 1e5) == (k == "far")]
        summary[f"default_{k}"], summary[f"bound_{k}"] = _summary(sel, "default"), _summary(sel, "bound")
    print("summary", summary)
    out = a.out or ("earth_pole_prior_free_sun" if a.free_sun else "earth_pole_prior")
    print("saved", save(out, {"args": {k: str(v) for k, v in vars(a).items()}, "environment": environment(),
                              "summary": summary, "rows": rows}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
