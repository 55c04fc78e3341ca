"""Few-pixel bodies: ``locate`` on independent renders of Moon-like spheres of radius 1-10 px, per radius bin.

    python benchmarks/small_bodies.py [--radii 1,2,3,5,7,10] [--n 8] [--seed 2026] [--law lunar-lambert]
                                      [--psf gaussian] [--compare-sphere 5,7,10] [--out small_bodies]

Frames: :func:`jaxlimb.render.independent.small_bodies.small_body_case` (128x128, focal 2000 px, the body centre
anywhere 12 px inside the frame, phase uniform in 0-60 deg, Sun in any image direction, Gaussian PSF sigma 0.6-1.2 px,
12 bits, SNR of the brightest pixel uniform in 50-100); hints: the body, the Sun direction, a range prior 5 % (1 sigma)
off.  ``locate`` picks its strategy (the few-pixel body below 5 px of expected radius); with ``--compare-sphere`` the
radii listed are also measured with ``shape="sphere"`` (the limb strategy), for the choice of the threshold.

Per radius bin: frames answered, the centre error (the image of the body centre, px) median / p90 / max, the mean
NEES of the centre ``e^T P^-1 e`` (chi-square expectation 2), the method (disc fit or centre of brightness), typed
refusals.  Written to ``benchmarks/results/<out>.json`` with the seed and the git SHA, and a markdown ``report``.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from _common import environment, save  # noqa: E402

from jaxlimb.errors import JaxlimbError  # noqa: E402
from jaxlimb.pipeline import LocateOptions, locate  # noqa: E402
from jaxlimb.render.independent import PsfKind, Reflectance  # noqa: E402
from jaxlimb.render.independent.small_bodies import small_body_case  # noqa: E402


def _measure(case, shape: str) -> dict:
    t0 = time.perf_counter()
    try:
        m = locate(case.image, case.camera, case.hints, LocateOptions(shape=shape))
    except JaxlimbError as e:
        return {"status": "error", "check": e.check, "message": str(e)[:200], "seconds": time.perf_counter() - t0}
    err = np.subtract(m.center_rc, case.truth.body_center_rc)
    cv = m.covariance
    P = np.array([[cv["center_r"]["center_r"], cv["center_r"]["center_c"]],
                  [cv["center_c"]["center_r"], cv["center_c"]["center_c"]]])
    return {"status": "ok", "err_rc": err.tolist(), "center_err_px": float(np.hypot(*err)),
            "nees": float(err @ np.linalg.solve(P, err)), "sigma_rc": np.sqrt(np.diag(P)).tolist(),
            "radius_px": m.radius_px, "method": (m.extras.get("small_body") or {}).get("method", "limb"),
            "seconds": time.perf_counter() - t0}


def _summary(recs: list[dict]) -> dict:
    ok = [r for r in recs if r["status"] == "ok"]
    e = np.array([r["center_err_px"] for r in ok]) if ok else np.array([])
    fails: dict[str, int] = {}
    for r in recs:
        if r["status"] != "ok":
            fails[r["check"]] = fails.get(r["check"], 0) + 1
    methods: dict[str, int] = {}
    for r in ok:
        methods[r["method"]] = methods.get(r["method"], 0) + 1
    return {"n": len(recs), "n_ok": len(ok), "median_px": float(np.median(e)) if ok else None,
            "p90_px": float(np.percentile(e, 90)) if ok else None, "max_px": float(e.max()) if ok else None,
            "nees_mean": float(np.mean([r["nees"] for r in ok])) if ok else None, "methods": methods,
            "failures": fails}


def _fmt(x, f="{:.3f}") -> str:
    return "–" if x is None else f.format(x)


def _report(rows: list[dict], title: str) -> str:
    out = [title, "| radius (px) | strategy | answered | centre error median / p90 / max (px) | NEES mean | method "
                  "| refusals |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        s = r["summary"]
        out.append(f"| {r['radius_px']:g} | {r['shape']} | {s['n_ok']}/{s['n']} | {_fmt(s['median_px'])} / "
                   f"{_fmt(s['p90_px'])} / {_fmt(s['max_px'])} | {_fmt(s['nees_mean'], '{:.2f}')} | "
                   f"{', '.join(f'{k} {v}' for k, v in s['methods'].items()) or '–'} | "
                   f"{', '.join(f'{k} {v}' for k, v in s['failures'].items()) or '–'} |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--radii", default="1,2,3,5,7,10")
    ap.add_argument("--n", type=int, default=8)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--law", default="lunar-lambert", choices=[r.value for r in Reflectance])
    ap.add_argument("--psf", default="gaussian", choices=[k.value for k in PsfKind])
    ap.add_argument("--compare-sphere", default="5,7,10")
    ap.add_argument("--out", default="small_bodies")
    args = ap.parse_args()
    radii = [float(v) for v in args.radii.split(",")]
    compare = {float(v) for v in args.compare_sphere.split(",") if v}
    rng = np.random.default_rng(args.seed)
    rows = []
    for R in radii:
        cases = [small_body_case(R, float(rng.uniform(0.0, 60.0)), np.random.default_rng(int(rng.integers(2**31))),
                                 snr=float(rng.uniform(50.0, 100.0)), law=Reflectance(args.law),
                                 psf_kind=PsfKind(args.psf)) for _ in range(args.n)]
        for shape in ("auto",) + (("sphere",) if R in compare else ()):
            recs = [{**_measure(c, shape), "phase_deg": c.meta["phase_deg"], "snr": c.meta["snr"],
                     "psf_sigma": c.meta["psf_sigma"]} for c in cases]
            rows.append({"radius_px": R, "shape": shape, "records": recs, "summary": _summary(recs)})
            s = rows[-1]["summary"]
            print(f"R {R:5.1f} {shape:6s} ok {s['n_ok']}/{s['n']} median {_fmt(s['median_px'])} p90 {_fmt(s['p90_px'])} "
                  f"NEES {_fmt(s['nees_mean'], '{:.2f}')} {s['methods']} {s['failures']}", flush=True)
    title = (f"Moon-like spheres, {args.law}, {args.psf} PSF, 128x128, phase 0-60 deg, SNR 50-100, {args.n} frames per "
             f"radius, seed {args.seed}")
    path = save(args.out, {"environment": environment(), "seed": args.seed, "args": vars(args), "rows": rows,
                           "report": _report(rows, title)})
    print(f"saved {path}")


if __name__ == "__main__":
    main()
