"""Few-pixel bodies: ``locate`` on independent renders of Moon-like spheres of radius 1-10 px, per radius bin.

    nice python benchmarks/small_bodies.py [--radii 1,2,3,5,7,10] [--n 20] [--seed 2026] [--compare 7,10]
                                           [--empty 10] [--law lunar-lambert] [--size 128 --focal 2000]
                                           [--out small_bodies]

Frames: :func:`jaxlimb.render.independent.small_bodies.small_body_case` (128x128, focal 2000 px, the body centre
anywhere -- sub-pixel -- 12 px inside the frame, lunar-Lambert, phase uniform in 0-90 deg, the Sun in any image
direction, Gaussian PSF sigma uniform in 0.5-1.5 px (``--law``: another reflectance law of the renderer, which the
few-pixel model does not assume; ``--size`` / ``--focal``: another frame, e.g. a wide field where the body lies far
off the boresight), 8, 12 or 16 bits, SNR of the brightest pixel uniform in 50-100);
hints: the body, the Sun direction, a range prior 5 % (1 sigma) off.  ``locate`` picks its strategy; at the radii of
``--compare`` the same frames are also measured with ``shape="sphere"`` (the limb strategy) and ``shape="small"``
(the few-pixel strategy), for the choice of the switch radius.  ``--empty``: frames of sky and noise only with the
same hints (a typed refusal expected).

Per radius and strategy: frames answered, the centre error against the image of the body centre (px) median / p90 /
max, the mean relative error of the radius (against the true apparent radius), the mean NEES of the centre
``e^T P^-1 e`` (chi-square with 2 degrees of freedom: 2), the share answered by the
fallback (the phase-corrected centre of brightness), and that estimate's own error and NEES on every frame (it is
reported beside the disc fit's answer).  Written to ``benchmarks/results/<out>.json`` with the seed and the git SHA,
and a markdown ``report``.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from _common import environment, save  # noqa: E402

from jaxlimb.errors import JaxlimbError  # noqa: E402
from jaxlimb.pipeline import LocateOptions, covariance_block, locate  # noqa: E402
from jaxlimb.render.independent.small_bodies import small_body_case  # noqa: E402
from jaxlimb.render.independent.surface import Reflectance  # noqa: E402


def _nees(err: np.ndarray, P: np.ndarray) -> float:
    return float(err @ np.linalg.solve(P, err))


def _measure(case, shape: str, R: float) -> dict:
    t0 = time.perf_counter()
    try:
        m = locate(case.image, case.camera, case.hints, LocateOptions(shape=shape))
    except JaxlimbError as e:
        return {"status": "error", "check": e.check, "message": str(e)[:200], "seconds": time.perf_counter() - t0}
    truth = np.asarray(case.truth.body_center_rc)
    err = np.subtract(m.center_rc, truth)
    cv = m.covariance
    P = covariance_block(cv)
    sb = m.extras.get("small_body") or {}
    out = {"status": "ok", "err_rc": err.tolist(), "center_err_px": float(np.hypot(*err)), "nees": _nees(err, P),
           "sigma_rc": np.sqrt(np.diag(P)).tolist(), "radius_px": m.radius_px, "method": sb.get("method", "limb"),
           "radius_rel_err": None if m.radius_px is None or R <= 0 else float(m.radius_px / R - 1.0),
           "seconds": time.perf_counter() - t0}
    if "moments_rc" in sb:  # the fallback's estimate, reported beside the disc fit
        e2 = np.subtract(sb["moments_rc"], truth)
        out.update(moments_err_px=float(np.hypot(*e2)), moments_nees=_nees(e2, np.asarray(sb["moments_cov"])))
    elif sb.get("method") == "moments":
        out.update(moments_err_px=out["center_err_px"], moments_nees=out["nees"])
    if "disc_vs_moments_chi2" in sb:  # the two centres' agreement; the disc fit's own error when it was refused for it
        out["disc_vs_moments_chi2"] = sb["disc_vs_moments_chi2"]
    if "disc_rc" in sb:
        out["disc_err_px"] = float(np.hypot(*np.subtract(sb["disc_rc"], truth)))
    return out


def _stats(x: list[float]) -> dict:
    if not x:
        return {"median": None, "p90": None, "max": None}
    a = np.asarray(x)
    return {"median": float(np.median(a)), "p90": float(np.percentile(a, 90)), "max": float(a.max())}


def _summary(recs: list[dict]) -> dict:
    ok = [r for r in recs if r["status"] == "ok"]
    fails: dict[str, int] = {}
    for r in recs:
        if r["status"] != "ok":
            fails[r["check"]] = fails.get(r["check"], 0) + 1
    mom = [r for r in ok if "moments_err_px" in r]
    rad = [r["radius_rel_err"] for r in ok if r.get("radius_rel_err") is not None]
    return {"n": len(recs), "n_ok": len(ok), "answered": len(ok) / len(recs),
            "center_err_px": _stats([r["center_err_px"] for r in ok]),
            "nees_mean": float(np.mean([r["nees"] for r in ok])) if ok else None,
            "radius_rel_err_mean": float(np.mean(rad)) if rad else None,
            "fallback_share": sum(r["method"] == "moments" for r in ok) / len(ok) if ok else None,
            "moments_err_px": _stats([r["moments_err_px"] for r in mom]),
            "moments_nees_mean": float(np.mean([r["moments_nees"] for r in mom])) if mom else None,
            "failures": fails, "seconds_median": float(np.median([r["seconds"] for r in recs]))}


def _fmt(x, f="{:.3f}") -> str:
    return "–" if x is None else f.format(x)


def _report(rows: list[dict], title: str) -> str:
    out = [title, "", "| radius (px) | strategy | answered | centre error median / p90 / max (px) | radius error mean "
                      "| NEES mean | fallback share | centre of brightness (phase-corrected) median / p90 (px), NEES "
                      "| refusals |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        s = r["summary"]
        e, m = s["center_err_px"], s["moments_err_px"]
        out.append(f"| {r['label']} | {r['shape']} | {s['n_ok']}/{s['n']} | {_fmt(e['median'])} / {_fmt(e['p90'])} / "
                   f"{_fmt(e['max'])} | {_fmt(s['radius_rel_err_mean'], '{:+.2%}')} | {_fmt(s['nees_mean'], '{:.2f}')} | "
                   f"{_fmt(s['fallback_share'], '{:.2f}')} | "
                   f"{_fmt(m['median'])} / {_fmt(m['p90'])}, {_fmt(s['moments_nees_mean'], '{:.2f}')} | "
                   f"{', '.join(f'{k} {v}' for k, v in s['failures'].items()) or '–'} |")
    return "\n".join(out)


def _cases(R: float, n: int, rng: np.random.Generator, law: Reflectance, frame: dict, empty: bool = False) -> list:
    return [small_body_case(R, float(rng.uniform(0.0, 90.0)), np.random.default_rng(int(rng.integers(2**31))),
                            snr=float(rng.uniform(50.0, 100.0)), bits=int(rng.choice([8, 12, 16])),
                            psf_sigma=(0.5, 1.5), law=law, empty=empty, **frame) for _ in range(n)]


def _row(label: str, R: float, shape: str, cases: list) -> dict:
    recs = [{**_measure(c, shape, R), **{k: c.meta[k] for k in ("phase_deg", "snr", "psf_sigma", "bits")}}
            for c in cases]
    row = {"label": label, "radius_px": R, "shape": shape, "records": recs, "summary": _summary(recs)}
    s = row["summary"]
    print(f"{label:>6s} {shape:6s} ok {s['n_ok']}/{s['n']} median {_fmt(s['center_err_px']['median'])} "
          f"p90 {_fmt(s['center_err_px']['p90'])} radius {_fmt(s['radius_rel_err_mean'], '{:+.2%}')} "
          f"NEES {_fmt(s['nees_mean'], '{:.2f}')} "
          f"fallback {_fmt(s['fallback_share'], '{:.2f}')} {s['failures']}", flush=True)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--radii", default="1,2,3,5,7,10")
    ap.add_argument("--n", type=int, default=20)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--compare", default="7,10", help="radii also measured with shape sphere and shape small")
    ap.add_argument("--empty", type=int, default=10, help="frames of sky and noise only")
    ap.add_argument("--law", default=Reflectance.LUNAR_LAMBERT.value, choices=[r.value for r in Reflectance],
                    help="the renderer's reflectance law (the few-pixel model's is lunar-Lambert)")
    ap.add_argument("--size", type=int, default=128, help="frame side (px)")
    ap.add_argument("--focal", type=float, default=2000.0, help="focal length (px)")
    ap.add_argument("--out", default="small_bodies")
    args = ap.parse_args()
    law = Reflectance(args.law)
    frame = {"size": args.size, "focal_px": args.focal}
    compare = {float(v) for v in args.compare.split(",") if v}
    rng = np.random.default_rng(args.seed)
    rows = []
    for R in (float(v) for v in args.radii.split(",")):
        cases = _cases(R, args.n, rng, law, frame)
        for shape in ("auto",) + (("sphere", "small") if R in compare else ()):
            rows.append(_row(f"{R:g}", R, shape, cases))
    if args.empty:
        rows.append(_row("none", 0.0, "auto", _cases(3.0, args.empty, rng, law, frame, empty=True)))
    title = (f"Moon-like spheres ({args.law}), {args.size}x{args.size}, focal length {args.focal:g} px, phase 0-90 deg, "
             "Gaussian PSF sigma 0.5-1.5 px, 8/12/16 bits, "
             f"SNR 50-100, {args.n} frames per radius, seed {args.seed}; 'none': {args.empty} frames of sky and noise "
             "with the same hints (a body of 3 px expected)")
    path = save(args.out, {"environment": environment(), "seed": args.seed, "args": vars(args), "rows": rows,
                           "report": _report(rows, title)})
    print(f"saved {path}")


if __name__ == "__main__":
    main()
