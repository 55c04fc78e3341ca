"""How close the Earth's centre can come with ``R_body_to_camera`` unknown: the Cramér--Rao bound and the mirror floor.

Usage::

    .venv/bin/python benchmarks/earth_attitude_floor.py [--families own,lambert,...] [--n 6] [--seed 2026]
                                                        [--samples 4000] [--cache DIR] [--out NAME] [--replot]

Frames: ``benchmarks/families.py``'s Earth frames (same seed, cache keys and hints; even index 40 000 km with the
8 mm lens, odd 380 000 km with the 16 mm).  Each is measured by ``locate`` twice, with the attitude and without it;
per frame are reported the centre error, the noise-only Cramér--Rao sigmas of the centre that ``locate`` returns
(``result.crlb``: the Fisher information of the fitted limb model at the estimate, with the measured noise level),
and the mirror floor (``families.pole_unknown_floor_px``: two mirror attitudes give the same limb, with centres
``2 gamma_off`` apart, so the minimum mean-square answer is their midpoint, ``gamma_off`` from either).

The *efficient-estimator* error of a frame without the attitude is ``|o + e|`` with ``o`` the floor (a fixed offset,
direction drawn uniformly) and ``e ~ N(0, diag(crlb_r^2, crlb_c^2))``; ``--samples`` draws per frame, pooled over the
frames ``locate`` answers, give its median and p90: what an unbiased estimator that reaches the bound would score on
the same frames, beside ``locate``'s own scores and a 0.15 px target.  The bound is the fitted model's:
exact on the ``own`` family, the noise-only part of the error on the others.  (A prior over the pole, e.g. the Sun's
declination, is information the bound does not hold: ``benchmarks/earth_pole_prior.py``.)

Results: ``benchmarks/results/<out>.json`` (default ``earth_attitude_floor``) and ``<out>.png``: per answered frame,
``locate``'s error without the attitude against its bound ``sqrt(floor^2 + crlb_r^2 + crlb_c^2)`` (near and far
marked), with the attitude-known errors beside them and the target line.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

TARGET_PX = 0.15


def _row(family: str, idx: int, seed: int, cache: Path | None) -> dict[str, Any]:
    from families import family_case, measure, pole_unknown_floor_px

    case = family_case("earth", family, idx, seed, cache)
    no_r = {k: v for k, v in case.hints.items() if k != "R_body_to_camera"}
    return {"family": family, "index": idx, "range_km": float(case.meta["range_km"]),
            "latitude_deg": float(case.meta["latitude_deg"]), "floor_px": pole_unknown_floor_px(case),
            "known": measure(case, case.hints), "unknown": measure(case, no_r)}


def efficient_errors(rows: list[dict], samples: int, rng: np.random.Generator) -> np.ndarray:
    """Pooled radial errors (px) of an efficient midpoint estimator on the answered frames (module docstring)."""
    out = []
    for r in rows:
        m = r["unknown"]
        if m["status"] != "ok" or "crlb_rc" not in m:
            continue
        ang = rng.uniform(0.0, 2.0 * math.pi, samples)
        o = r["floor_px"] * np.column_stack([np.cos(ang), np.sin(ang)])
        e = rng.standard_normal((samples, 2)) * np.asarray(m["crlb_rc"])[None, :]
        out.append(np.hypot(*(o + e).T))
    return np.concatenate(out) if out else np.zeros(0)


def bound_px(r: dict) -> float:
    """The frame's bound without the attitude: ``sqrt(floor^2 + crlb_r^2 + crlb_c^2)`` (px)."""
    return math.sqrt(r["floor_px"] ** 2 + sum(c * c for c in r["unknown"]["crlb_rc"]))


def _stats(x) -> dict[str, float | None]:
    x = np.asarray(x, float)
    if x.size == 0:
        return {"n": 0, "median_px": None, "p90_px": None}
    return {"n": int(x.size), "median_px": float(np.median(x)), "p90_px": float(np.percentile(x, 90))}


def summarise(rows: list[dict], samples: int, seed: int) -> dict[str, Any]:
    """Per range group (``near``, ``far``, ``all``): ``locate``'s errors with and without the attitude, the
    efficient-estimator errors, the median bound ``sqrt(floor^2 + crlb_r^2 + crlb_c^2)`` and the share of answered
    frames whose bound exceeds the target."""
    out: dict[str, Any] = {"target_px": TARGET_PX}
    for name, sel in (("near", lambda r: r["range_km"] < 1e5), ("far", lambda r: r["range_km"] >= 1e5),
                      ("all", lambda r: True)):
        rs = [r for r in rows if sel(r)]
        ok = [r for r in rs if r["unknown"]["status"] == "ok" and "crlb_rc" in r["unknown"]]
        bound = [bound_px(r) for r in ok]
        out[name] = {
            "frames": len(rs), "answered_unknown": len(ok),
            "locate_known": _stats([r["known"]["center_err_px"] for r in rs if r["known"]["status"] == "ok"]),
            "locate_unknown": _stats([r["unknown"]["center_err_px"] for r in ok]),
            "efficient_unknown": _stats(efficient_errors(ok, samples, np.random.default_rng(seed))),
            "bound_median_px": float(np.median(bound)) if bound else None,
            "share_bound_above_target": float(np.mean(np.array(bound) > TARGET_PX)) if bound else None,
            "crlb_radial_median_px": float(np.median([math.hypot(*r["unknown"]["crlb_rc"]) for r in ok])) if ok else None,
            "floor_median_px": float(np.median([r["floor_px"] for r in ok])) if ok else None}
    return out


def figure(rows: list[dict], path: Path) -> None:
    """The module docstring's figure, written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxlimb._io import atomic_path

    fig, ax = plt.subplots(figsize=(7, 6))
    for far, mark, label in ((False, "o", "40 000 km, 8 mm"), (True, "s", "380 000 km, 16 mm")):
        sel = [r for r in rows if (r["range_km"] >= 1e5) == far and r["unknown"]["status"] == "ok"
               and "crlb_rc" in r["unknown"]]
        b = [bound_px(r) for r in sel]
        ax.scatter(b, [r["unknown"]["center_err_px"] for r in sel], marker=mark, label=f"attitude unknown, {label}")
        ax.scatter(b, [r["known"]["center_err_px"] if r["known"]["status"] == "ok" else np.nan for r in sel],
                   marker=mark, facecolors="none", edgecolors="grey", label=f"same frame, attitude known ({label})")
    lim = [1e-3, 1.0]
    ax.plot(lim, lim, "k:", lw=0.8, label="error = bound")
    ax.axhline(TARGET_PX, color="r", lw=0.8, label=f"target {TARGET_PX} px")
    ax.axvline(TARGET_PX, color="r", lw=0.8, ls="--")
    ax.set(xscale="log", yscale="log", xlim=lim, ylim=lim, xlabel="bound sqrt(floor^2 + CRLB_r^2 + CRLB_c^2) (px)",
           ylabel="centre error (px)", title="Earth centre without the attitude: error against its bound")
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=80, format="png")
    plt.close(fig)


def _line(r: dict) -> str:
    k, u = r["known"], r["unknown"]
    fk = f"{k['center_err_px']:.3f}" if k["status"] == "ok" else k.get("check", "error")
    if u["status"] != "ok":
        return f"known {fk} | unknown {u.get('check', 'error')}"
    cr = u.get("crlb_rc", [float("nan")] * 2)
    return (f"known {fk} | unknown {u['center_err_px']:.3f} px, CRLB ({cr[0]:.3f}, {cr[1]:.3f}), "
            f"floor {r['floor_px']:.3f}")


def main(argv=None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    from _common import add_earth_frame_args, environment, save

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_earth_frame_args(ap)
    ap.add_argument("--samples", type=int, default=4000)
    ap.add_argument("--out", default="earth_attitude_floor")
    ap.add_argument("--replot", action="store_true", help="redraw <out>.png from <out>.json, measure nothing")
    a = ap.parse_args(argv)
    png = Path(__file__).resolve().parent / "results" / f"{a.out}.png"
    if a.replot:
        import json

        figure(json.loads(png.with_suffix(".json").read_text())["rows"], png)
        print("saved", png)
        return 0
    rows = []
    for fam in a.families.split(","):
        for i in range(a.n):
            rows.append(_row(fam, i, a.seed, a.cache))
            print(f"{fam:9s} {i} {'far ' if i % 2 else 'near'}: {_line(rows[-1])}", flush=True)
    summary = summarise(rows, a.samples, a.seed)
    for k in ("near", "far", "all"):
        s = summary[k]
        print(f"{k:4s} answered {s['answered_unknown']}/{s['frames']}: locate known median "
              f"{s['locate_known']['median_px']}, unknown median {s['locate_unknown']['median_px']} / p90 "
              f"{s['locate_unknown']['p90_px']}; efficient estimator median {s['efficient_unknown']['median_px']} / p90 "
              f"{s['efficient_unknown']['p90_px']}; bound above {TARGET_PX} px on {s['share_bound_above_target']}")
    figure(rows, png)
    print("saved", save(a.out, {"args": {k: str(v) for k, v in vars(a).items()}, "environment": environment(),
                                "summary": summary, "rows": rows}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
