"""How ``locate``'s covariance of the rendered transfer's frames compares with their errors, per body and part.

``locate`` reports a frame's covariance ``R = N + M``: ``N`` its noise-only bound (``covariance_noise``: the Cramér--Rao
bound with its correlations) and ``M`` its model-error term.  The filter of ``jaxlimb track`` keeps ``N`` and a
share ``alpha`` of ``M`` per body (:mod:`jaxlimb.track.variance`).  Here, over every noise draw of the cache
(``benchmarks/track_render.py``), for each body and measured component (row, column of the centre; the Earth's
range or the Moon's radius), with ``e`` the error against the truth:

* ``e^2 / N``: mean and median (chi-square with 1 degree of freedom: 1 and 0.455) and the fraction above 6.63
  (its 99 % quantile: 1 % expected), i.e. is ``N`` the size of the errors, and are they Gaussian;
* ``e^2 / R``: mean (1 if ``R`` is the size of the errors);
* the whole error's ``e^T N^-1 e`` with the bound's correlations (``covariance_noise``), with its variances
  alone, and ``e^T R^-1 e``: mean (chi-square with 3 degrees of freedom: 3) and the fraction above 11.34 (its 99 %
  quantile), and the median |correlation| of ``N``'s components; and by fifths of the arc (the body's frames in
  time order, every draw) the medians of ``e^T N^-1 e``, ``e^T R^-1 e`` and ``tr(N^-1 M) / 3`` (how many times the
  noise the model-error term is);
* ``M / N``: median, and the correlation over frames of ``log(e^2 / N)`` with ``log(M / N)``: does a frame's
  model-error term say which frames have the larger errors;
* the spread over the noise draws: per frame measured in at least two draws, the sample variance of its draws'
  measurements over the mean of their ``N`` (1 if ``N`` is the noise-only spread of the estimate ``locate``
  returns; the truth and any bias cancel), mean and median per component, and the mean by fifths of the arc;
* the mean NIS of each body's frames in ``benchmarks/results/track_transfer.json`` (the rendered Monte Carlo's
  per-epoch NIS; 3 expected).

    python benchmarks/track_noise.py --cache /tmp/track-cache      # -> results/track_noise.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, save  # noqa: E402

CHI2_1_99 = 6.635
CHI2_3_99 = 11.345
COMPONENTS = {"earth": ("row", "col", "range"), "moon": ("row", "col", "radius")}


def measured(arc, tr, draws: dict[str, dict[int, dict]]) -> list:  # noqa: ANN001
    """Per draw, its ``ok`` frames and their :func:`track_transfer.as_frames` (true camera and attitude)."""
    from track_transfer import THETA_TRUE, as_frames

    out = []
    for draw in draws.values():
        ks = [k for k in sorted(draw) if draw[k].get("status") == "ok"]
        out.append((ks, as_frames(arc, tr, [draw[k] for k in ks], tr.C_true[ks], THETA_TRUE, 0.0)))
    return out


def ratios(tr, frames: list) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:  # noqa: ANN001
    """Per body, over every ``ok`` frame of every draw (:func:`measured`): rows ``(e^2/N, e^2/R, M/N)`` by component
    ``(n, 3, 3)``, and the whole error's ``(e^T N^-1 e, e^T diag(N)^-1 e, e^T R^-1 e)`` and ``N``'s |correlations|
    (row-col, row-X, col-X), ``tr(N^-1 M) / 3`` and the frame ``(n, 8)``."""
    from jaxlimb.track.scenario import true_measurements

    z_true = true_measurements(tr)
    out: dict[str, list] = {"earth": [], "moon": []}
    whole: dict[str, list] = {"earth": [], "moon": []}
    for ks, fr in frames:
        e = fr.z - z_true[ks]
        e2 = e**2
        N = np.einsum("kii->ki", fr.R_noise)
        R = np.einsum("kii->ki", fr.R)
        for i, k in enumerate(ks):
            out[tr.bodies[k]].append(np.stack([e2[i] / N[i], e2[i] / R[i], (R[i] - N[i]) / N[i]]))
            rho = fr.R_noise[i] / np.sqrt(np.outer(N[i], N[i]))
            whole[tr.bodies[k]].append([e[i] @ np.linalg.solve(fr.R_noise[i], e[i]), e2[i] @ (1.0 / N[i]),
                                        e[i] @ np.linalg.solve(fr.R[i], e[i]), *np.abs(rho[[0, 0, 1], [1, 2, 2]]),
                                        np.trace(np.linalg.solve(fr.R_noise[i], fr.R[i] - fr.R_noise[i])) / 3.0, k])
    return {b: np.array(v) for b, v in out.items()}, {b: np.array(v) for b, v in whole.items()}


def draw_spread(tr, frames: list) -> dict:  # noqa: ANN001
    """Per body, the spread of each frame's measurements over the noise draws (:func:`measured`) against their ``N``
    (module docstring)."""
    z: dict[int, list] = {}
    for ks, fr in frames:
        for i, k in enumerate(ks):
            z.setdefault(k, []).append((fr.z[i], np.diag(fr.R_noise[i])))
    out = {}
    for b in ("earth", "moon"):
        ks = [k for k in sorted(z) if tr.bodies[k] == b and len(z[k]) >= 2]
        v = np.array([np.var([x[0] for x in z[k]], axis=0, ddof=1) / np.mean([x[1] for x in z[k]], axis=0) for k in ks])
        out[b] = {"frames": len(ks), "mean": v.mean(0).tolist(), "median": np.median(v, 0).tolist(),
                  "mean_by_fifth_of_the_arc": [v[f].mean(0).tolist() for f in np.array_split(np.arange(len(ks)), 5)]}
    return out


def vector_summary(q: np.ndarray) -> dict:
    """Mean and fraction above chi-square(3)'s 99 % quantile of each of :func:`ratios`' whole-error forms, and the
    median |correlation| of ``N``'s components."""
    out = {name: {"mean": float(q[:, j].mean()), "beyond_chi2_99": float(np.mean(q[:, j] > CHI2_3_99))}
           for j, name in enumerate(("N", "N_variances_only", "R"))}
    fifths = np.array_split(np.argsort(q[:, 7], kind="stable"), 5)
    return out | {"N_abs_correlation_median": dict(zip(("row_col", "row_X", "col_X"), np.median(q[:, 3:6], 0).tolist())),
                  "by_fifth_of_the_arc": [{"frames": [int(q[f, 7].min()), int(q[f, 7].max())],
                                           "eNe_median": float(np.median(q[f, 0])),
                                           "eRe_median": float(np.median(q[f, 2])),
                                           "M_over_N_median": float(np.median(q[f, 6]))} for f in fifths]}


def summary(r: np.ndarray, names: tuple[str, ...]) -> dict:
    """The numbers of the module docstring for one body's ``(n, 3, 3)`` ratios."""
    out = {"frames": int(r.shape[0])}
    for j, name in enumerate(names):
        eN, eR, MN = r[:, 0, j], r[:, 1, j], r[:, 2, j]
        ok = (eN > 0) & (MN > 0)
        out[name] = {"e2_over_N_mean": float(eN.mean()), "e2_over_N_median": float(np.median(eN)),
                     "beyond_chi2_99": float(np.mean(eN > CHI2_1_99)), "e2_over_R_mean": float(eR.mean()),
                     "M_over_N_median": float(np.median(MN)),
                     "corr_log_e2_log_M": float(np.corrcoef(np.log(eN[ok]), np.log(MN[ok]))[0, 1])}
    return out


def nis_by_body(tr, draws: dict[str, dict[int, dict]], rel: str = "track_transfer.json") -> dict[str, float] | None:  # noqa: ANN001
    """Mean NIS of each body's epochs in the rendered Monte Carlo of ``results/track_transfer.json`` (its epochs: the
    frames ``track_transfer.py`` keeps)."""
    from track_transfer import kept_frames

    path = RESULTS / rel
    d = json.loads(path.read_text()) if path.exists() else {}
    mc = d.get("monte_carlo_rendered")
    keep = kept_frames(draws.values(), len(tr.bodies))
    if not mc or len(mc["epoch_nis"]) != len(keep):
        return None
    nis, bodies = np.array(mc["epoch_nis"], float), np.array([tr.bodies[k] for k in keep])
    return {b: float(np.nanmean(nis[bodies == b])) for b in ("earth", "moon")}


def main(argv: list[str] | None = None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    from track_transfer import load_records, scenario

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, required=True)
    ap.add_argument("--n-frames", type=int, default=200)
    ap.add_argument("--seed", type=int, default=38)
    a = ap.parse_args(argv)
    arc, _, tr = scenario(a.n_frames, a.seed)
    draws = {k: v for k, v in load_records(a.cache).items() if k != "nominal"}
    frames = measured(arc, tr, draws)
    r, q = ratios(tr, frames)
    out = {"environment": environment(), "draws": len(draws),
           "bodies": {b: summary(r[b], COMPONENTS[b]) for b in ("earth", "moon")},
           "whole_error": {b: vector_summary(q[b]) for b in ("earth", "moon")},
           "spread_over_draws_over_N": draw_spread(tr, frames), "mean_nis_rendered": nis_by_body(tr, draws)}
    print(json.dumps(out["bodies"], indent=1))
    print(save("track_noise", out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
