"""How much of ``locate``'s Moon covariance is the unknown albedo field's consider term, and does it make the
covariance honest?

Usage::

    .venv/bin/python benchmarks/albedo_consider.py [--n 6] [--seed 2026] [--families own,spots,...] [--cache DIR]

The Moon frames of ``benchmarks/families.py`` (same seeds, same cache), each through
:func:`jaxlimb.analysis.located.located_fit` and :func:`jaxlimb.analysis.albedo_consider.albedo_consider_of`.  Per
family: the mean NEES of the body centre (chi-square 2 dof expects 2) with ``locate``'s covariance, which carries the
albedo field's consider term where its other model-error terms do not; with the frame measured again without that
term (:func:`without_albedo_term`), and then with the limb sectors' sandwich made bias-reduced or correlated between
neighbouring sectors (:func:`sandwich_variants`); the field's median amplitude; and the median ratio of ``locate``'s
centre sigma to the one without the term.  Results:
``benchmarks/results/albedo_consider.json``.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def sandwich_variants(lf) -> dict[str, np.ndarray]:  # noqa: ANN001
    """``locate``'s centre covariance with its limb sectors' sandwich (CR1) replaced by the bias-reduced one (CR2, Bell
    & McCaffrey 2002) and by one whose sectors are correlated with their ``L`` neighbours (Newey & West 1987, Bartlett
    weights ``1 - k / (L + 1)``), ``L`` = 2 and 4; each mapped to the body centre."""
    from jaxlimb.analysis.albedo_consider import center_map
    from jaxlimb.model_error import (cluster_robust_bias_reduced, cluster_robust_covariance, sector_groups,
                                     with_model_error as widen)
    from jaxlimb.models.lunar_lambert import profile_model
    from jaxlimb.pipeline.profile.model_error import MODEL_ERROR_SECTORS, weighted_system

    rr, G = lf.final, MODEL_ERROR_SECTORS
    J, r, _, _ = weighted_system(rr, profile_model(rr.fit.params))
    g = sector_groups(np.asarray(rr.data.coords, float), (float(rr.fit.params.r0), float(rr.fit.params.c0)), G)
    C0 = rr.covariance_noise
    base = widen(C0, cluster_robust_covariance(J, r, g))
    scores = np.stack([np.bincount(g, weights=col * r, minlength=G) for col in J.T], axis=1)
    Ni = np.linalg.inv(J.T @ J)
    out = {"cr2": widen(C0, cluster_robust_bias_reduced(J, r, g))}
    for L in (2, 4):
        meat = scores.T @ scores
        for k in range(1, L + 1):
            X = scores[k:].T @ scores[:-k]
            meat += (1.0 - k / (L + 1)) * (X + X.T)
        out[f"hac{L}"] = widen(C0, G / (G - 1) * Ni @ meat @ Ni)
    M = center_map(lf)
    return {k: M @ (v - base) @ M.T for k, v in out.items()}


@contextlib.contextmanager
def without_albedo_term():
    """``locate`` as it was without the albedo field's term: the model-error stage's widening by it left out."""
    import jaxlimb.pipeline.profile.model_error as me

    keep = me.with_albedo_term
    me.with_albedo_term = lambda C, C0, Ca: C
    try:
        yield
    finally:
        me.with_albedo_term = keep


def frame_record(case) -> dict:  # noqa: ANN001
    """One frame: ``locate``'s centre error and NEES with the albedo term and without it (the same frame measured
    again with the term left out, and with the sandwich's variants there), or its typed failure."""
    from jaxlimb.analysis.albedo_consider import albedo_consider_of
    from jaxlimb.analysis.located import located_fit
    from jaxlimb.errors import JaxlimbError
    from jaxlimb.pipeline import covariance_block

    try:
        lf = located_fit(case.image, case.camera, case.hints)
        with without_albedo_term():
            lf0 = located_fit(case.image, case.camera, case.hints)
    except JaxlimbError as e:
        return {"status": type(e).__name__}
    ac = albedo_consider_of(lf)
    if ac is None:
        return {"status": "not_profile"}
    truth = np.asarray(case.truth.body_center_rc, float)
    e, e0 = (np.asarray(x.measurement.center_rc, float) - truth for x in (lf, lf0))
    P0 = covariance_block(lf0.measurement.covariance)
    variants = {f"nees_{k}": float(e0 @ np.linalg.solve(P0 + d, e0)) for k, d in sandwich_variants(lf0).items()}
    return {**variants, "status": "ok", "center_err_px": float(np.hypot(*e)), "tau": ac.tau, "ell_deg": ac.ell_deg,
            "nees_locate": float(e @ np.linalg.solve(ac.locate, e)), "nees_without": float(e0 @ np.linalg.solve(P0, e0)),
            "sigma_ratio": math.sqrt(np.trace(ac.locate) / np.trace(P0))}


def summarise(recs: list[dict]) -> dict:
    """Per-family means and medians over the answered frames."""
    ok = [r for r in recs if r["status"] == "ok"]
    if not ok:
        return {"n": len(recs), "n_ok": 0}
    col = lambda k: np.array([r[k] for r in ok])  # noqa: E731
    return {"n": len(recs), "n_ok": len(ok), "nees_locate": float(col("nees_locate").mean()),
            **{f"nees_{k}": float(col(f"nees_{k}").mean()) for k in ("cr2", "hac2", "hac4")},
            "nees_without": float(col("nees_without").mean()), "tau_median": float(np.median(col("tau"))),
            "sigma_ratio_median": float(np.median(col("sigma_ratio"))),
            "center_median_px": float(np.median(col("center_err_px")))}


def main(argv: list[str] | None = None) -> dict:
    import jax
    from tqdm import tqdm

    jax.config.update("jax_enable_x64", True)
    from _common import environment, save
    from families import family_case

    from jaxlimb.render.independent import MOON_FAMILIES

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=6, help="frames per family (default 6)")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--families", default=None, help="comma-separated subset (default all Moon families)")
    ap.add_argument("--cache", type=Path, default=None, help="directory keeping the renders (shared with families.py)")
    a = ap.parse_args(argv)
    fams = a.families.split(",") if a.families else list(MOON_FAMILIES)
    t0 = time.perf_counter()
    records: dict[str, list[dict]] = {}
    for fam, i in tqdm([(f, i) for f in fams for i in range(a.n)], desc="albedo consider"):
        records.setdefault(fam, []).append(frame_record(family_case("moon", fam, i, a.seed, a.cache)))
    summary = {f: summarise(r) for f, r in records.items()}
    summary["all"] = summarise([x for r in records.values() for x in r])
    for f, s in summary.items():
        if s["n_ok"]:
            print(f"{f:9s} {s['n_ok']}/{s['n']}  NEES {s['nees_without']:5.2f} -> {s['nees_locate']:5.2f}  "
                  f"(CR2 {s['nees_cr2']:.2f}, HAC2 {s['nees_hac2']:.2f}, HAC4 {s['nees_hac4']:.2f})  "
                  f"tau {s['tau_median']:.3f}  sigma x {s['sigma_ratio_median']:.2f}")
    out = {"args": {"n": a.n, "seed": a.seed, "families": fams}, "environment": environment(),
           "wall_s": time.perf_counter() - t0, "records": records, "summary": summary}
    save("albedo_consider", out)
    return out


if __name__ == "__main__":
    main()
