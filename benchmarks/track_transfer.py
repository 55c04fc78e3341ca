"""Filter consistency, smoother vs its posterior Cramér--Rao bound, self-calibration and speed on the rendered
cislunar transfer of ``benchmarks/track_render.py`` (run that first with the same ``--cache``).

What is rendered and what is drawn:

* rendered: the frames of one transfer (``track_render.py``), each digitised ``R`` times with independent noise
  (``--realizations`` there) and measured by ``locate``; a frame enters the study when at least one draw was
  measured;
* Monte Carlo (``--sequences``, default 50): every sequence takes, for each frame, one of its measured draws at
  random (the rendered measurement and the covariance ``locate`` reported for it), a new attitude error
  (10 µrad per axis) and a new prior drawn from ``P0`` (1000 km, 1 m/s per axis) about the truth; the truth is the
  same trajectory.  So the measurement errors are the pipeline's own on independent renders (bias included),
  resampled; with ``R`` draws per frame the sequences share measurements, which the numbers below do not hide:
  the per-epoch averages are over correlated runs;
* drawn: the same sequences with Gaussian measurements drawn from the covariance ``locate`` reported (the
  filter's own consistency, with a measurement model that holds by construction).

The filter, smoother and batch fit carry the bodies' bias states (:mod:`jaxlimb.track.bias`), with the split of
``locate``'s model error into independent, constant and walking parts estimated from each sequence
(:func:`jaxlimb.track.filter_with_split`; ``--no-bias``: the filter that takes every frame's error as independent);
the posterior CRB is that of the same model (each sequence's split).
``measurement_errors_draw0``: ``locate``'s errors on draw 0 against the truth, per body (:func:`measurement_errors`).

Statistics: per epoch, the average over sequences of the filtered 6-state NEES and of the NIS, against the
two-sided 95 % band of the ``N``-run average (:func:`jaxlimb.track.average_band`); the grand means, with their
standard errors over the sequences (:func:`standard_errors`); the
smoother's and the batch fit's RMS position error against the posterior CRB (:func:`jaxlimb.track.posterior_crlb`),
and the NEES of their positions.
Self-calibration: the draw measured with the nominal camera (focal length +1 %, principal point off by
(+2.0, -1.5) px), :func:`jaxlimb.track.track` with ``calibrate=True``.  Speed: ``jaxlimb track`` on the
measured frames (``--resume`` on a measurements file: the time after ``locate``), in a subprocess, twice: with
an empty compilation cache, then with the cache the first run filled.

``python benchmarks/track_transfer.py --cache /tmp/track-cache`` -> ``benchmarks/results/track_transfer.json``
(``--no-bias``: ``track_transfer_no_bias.json``).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import environment, save  # noqa: E402
from track_render import THETA_NOMINAL, THETA_TRUE, camera, scenario  # noqa: E402

#: Process noise of the Monte Carlo's filter (km^2/s^3): the truth has no unmodelled acceleration; 1e-18 adds
#: ~0.1 km of position uncertainty over the 3.5-day arc (the CLI's default, 1e-15, ~3 km, is for real flights)
Q_PSD = 1e-18
DOCS_PLOT = Path(__file__).resolve().parents[1] / "docs" / "track_transfer.png"


def load_records(cache: Path) -> dict[str, dict[int, dict]]:
    out = {}
    for p in sorted(cache.glob("locate_*.jsonl")):
        recs = {}
        for line in p.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                recs[int(r["frame"])] = r
        out[p.stem.removeprefix("locate_")] = recs
    return out


def kept_frames(draws, n_frames: int) -> list[int]:  # noqa: ANN001
    """The frames the study keeps (its epochs): those ``locate`` answered ``ok`` in at least one of ``draws``."""
    return [k for k in range(n_frames) if any(d.get(k, {}).get("status") == "ok" for d in draws)]


def as_frames(arc, tr, recs: list[dict], C: np.ndarray, theta: np.ndarray, att_sigma: float):  # noqa: ANN001, ANN201
    from jaxlimb.track import frames_from_records

    rows = [{"image": f"frame{r['frame']:04d}", "t_s": float(tr.t[r["frame"]]), "C_ci": C[i], "body": tr.bodies[r["frame"]],
             "measurement": r} for i, r in enumerate(recs)]
    return frames_from_records(rows, arc, camera(theta), attitude_sigma_rad=att_sigma)


def monte_carlo(arc, prop, tr, draws, keep, n_seq: int, seed: int, drawn: bool, bias: bool = True) -> dict:  # noqa: ANN001
    from jaxlimb.track import average_band, filter_with_split, fit_arc, nees, posterior_crlb
    from jaxlimb.track.scenario import perturb_attitudes, true_measurements

    rng = np.random.default_rng([seed, int(drawn)])
    P0 = np.diag([1000.0**2] * 3 + [1e-3**2] * 3)
    z_true = true_measurements(tr)[keep]
    N_f, N_nis, E_s, crb_tr, used, mnees, b_s, splits, S_n, E_b, B_n = [], [], [], [], [], [], [], [], [], [], []
    for s in range(n_seq):
        recs = [_pick(draws, k, rng) for k in keep]
        C = perturb_attitudes(tr.C_true[keep], 1e-5, rng)
        fr = as_frames(arc, tr, recs, C, THETA_TRUE, 1e-5)
        if drawn:
            fr.z[:] = z_true + np.einsum("kij,kj->ki", np.linalg.cholesky(fr.R), rng.standard_normal(fr.z.shape))
        x0 = tr.x0 + np.linalg.cholesky(P0) @ rng.standard_normal(6)
        measured = fr
        fr, bm, res, split = filter_with_split(measured, prop, (0.0, x0, P0), bias, q=Q_PSD)
        if split is not None:
            splits.append(split.to_json())
        truth = tr.states[keep]
        N_f.append(nees(res.x_filt, res.P_filt, truth))
        N_nis.append(np.where(res.used, res.nis, np.nan))
        E_s.append(res.x_smooth[:, :3] - truth[:, :3])
        fit = fit_arc(fr, prop, float(fr.t[0]), res.x_smooth[0], bias=bm)
        Xb, Pb = fit.states(prop, fr.t)
        E_b.append(Xb[:, :3] - truth[:, :3])
        B_n.append(nees(Xb[:, :3], Pb[:, :3, :3], truth[:, :3]).mean())
        S_n.append(nees(res.x_smooth[:, :3], res.P_smooth[:, :3, :3], truth[:, :3]).mean())
        pc = posterior_crlb(fr, prop, tr.x0, 0.0, P0, bias=bm)
        crb_tr.append(np.trace(pc[:, :3, :3], axis1=1, axis2=2))
        if res.bias is not None:
            b_s.append(res.bias.to_json(res.b_smooth, res.b_smooth_cov))
        used.append(res.used)
        d = measured.z - z_true  # against the covariance locate reported
        mnees.append(float(np.mean(np.einsum("ki,ki->k", d, np.linalg.solve(measured.R, d[..., None])[..., 0]))))
    N_f, N_nis, E_s, crb_tr = np.array(N_f), np.array(N_nis), np.array(E_s), np.array(crb_tr)
    lo6, hi6 = average_band(n_seq, 6)
    lo3, hi3 = average_band(n_seq, 3)
    a_nees = N_f.mean(0)
    with warnings.catch_warnings():  # a frame every sequence gated has no NIS average (NaN)
        warnings.simplefilter("ignore", RuntimeWarning)
        a_nis = np.nanmean(N_nis, 0)
    err2 = np.sum(E_s**2, -1)
    ratio_k = np.sqrt(err2.mean(0) / crb_tr.mean(0))
    se = standard_errors(N_f, N_nis, err2, crb_tr, np.array(S_n), np.random.default_rng([seed, 2]))
    return {
        "sequences": n_seq, "frames": len(keep), "nees_band_95": [lo6, hi6], "nis_band_95": [lo3, hi3],
        "mean_nees_filtered": float(a_nees.mean()), "median_epoch_nees": float(np.median(a_nees)),
        "epochs_nees_in_band": float(np.mean((a_nees >= lo6) & (a_nees <= hi6))),
        "mean_nis": float(np.nanmean(a_nis)), "epochs_nis_in_band": float(np.nanmean((a_nis >= lo3) & (a_nis <= hi3))),
        "gated_fraction": float(1 - np.mean(used)),
        "smoother_rms_pos_km": float(np.sqrt(err2.mean())), "pcrb_rms_pos_km": float(np.sqrt(crb_tr.mean())),
        "smoother_over_pcrb": float(np.sqrt(err2.mean() / crb_tr.mean())),
        "batch_rms_pos_km": float(np.sqrt(np.mean(np.sum(np.array(E_b) ** 2, -1)))),
        "batch_over_pcrb": float(np.sqrt(np.mean(np.sum(np.array(E_b) ** 2, -1)) / crb_tr.mean())),
        "batch_nees_position_mean": float(np.mean(B_n)),
        "bias_states": bias,
        "bias_smoothed": {n: {k: float(np.mean([b[n][k] for b in b_s if n in b])) for k in ("value", "sigma", "prior_sigma")}
                          | {"sequences": sum(n in b for b in b_s)} for n in dict.fromkeys(x for b in b_s for x in b)},
        "smoother_over_pcrb_epochs_median_max": [float(np.median(ratio_k)), float(np.max(ratio_k))],
        "measurement_nees_mean": float(np.mean(mnees)),
        "model_error_split": {b: {k: [float(np.mean(v)), float(np.min(v)), float(np.max(v))]
                                  for k, v in ((k, [x[b][k] for x in splits]) for k in splits[0][b])}
                              for b in (splits[0] if splits else {})},
        "smoother_nees_position_mean": float(np.mean(S_n)),
        "standard_errors": se,
        "epoch_nees": a_nees.tolist(), "epoch_nis": a_nis.tolist(),
    }


def standard_errors(N_f: np.ndarray, N_nis: np.ndarray, err2: np.ndarray, crb: np.ndarray, S_n: np.ndarray,
                    rng: np.random.Generator, n_boot: int = 2000) -> dict[str, float]:
    """Standard errors of the Monte Carlo's means over its sequences: the spread of the per-sequence means over
    ``sqrt(n)`` for the filtered NEES, the NIS and the smoothed position's NEES; a bootstrap over the sequences for
    the smoother's RMS error over the posterior CRB.  Sequences that share measurements (the rendered ones: a few
    noise draws per frame) are not independent, and these are then lower bounds."""
    n = N_f.shape[0]
    with warnings.catch_warnings():  # a sequence with every frame gated has no NIS
        warnings.simplefilter("ignore", RuntimeWarning)
        per_seq = {"mean_nees_filtered": N_f.mean(1), "mean_nis": np.nanmean(N_nis, 1),
                   "smoother_nees_position_mean": S_n}
    out = {k: float(np.nanstd(v, ddof=1) / np.sqrt(n)) for k, v in per_seq.items()}
    idx = rng.integers(0, n, (n_boot, n))
    boot = np.sqrt(err2.mean(1)[idx].mean(1) / crb.mean(1)[idx].mean(1))
    return out | {"smoother_over_pcrb": float(boot.std(ddof=1))}


def measurement_errors(arc, tr, draw: dict[int, dict], keep) -> dict:  # noqa: ANN001
    """``locate``'s errors against the truth on one draw, per body: each component normalised by its sigma (mean =
    a bias; RMS), the centre's error along the Sun's image direction as a fraction of the apparent radius (the
    ``sun_offset`` of :mod:`jaxlimb.track.bias`) and the relative size error (``scale``), with the standard error
    of their means, the autocorrelation of the normalised errors against the lag in frames of that body, and the two
    errors by the model ``locate`` fitted (:func:`by_model`)."""
    from jaxlimb.track.bias import apparent_radius_px
    from jaxlimb.track.measurement import sun_direction_px
    from jaxlimb.track.scenario import true_measurements

    ks = [k for k in keep if draw.get(k, {}).get("status") == "ok"]
    fr = as_frames(arc, tr, [draw[k] for k in ks], tr.C_true[ks], THETA_TRUE, 0.0)
    e = fr.z - true_measurements(tr)[ks]
    sd = np.sqrt(np.einsum("kii->ki", fr.R))
    size = apparent_radius_px(fr)
    d = np.array([np.asarray(sun_direction_px(fr.C[i] @ (fr.body_pos[i] - tr.states[k, :3]),
                                              fr.C[i] @ (fr.sun_pos[i] - tr.states[k, :3]))) for i, k in enumerate(ks)])
    along = np.einsum("ki,ki->k", e[:, :2], d)
    along_sd = np.sqrt(np.einsum("ki,kij,kj->k", d, fr.R[:, :2, :2], d))
    out = {}
    for b in ("earth", "moon"):
        m = np.array([tr.bodies[k] == b for k in ks])
        n = e[m] / sd[m]
        na = along[m] / along_sd[m]

        def ac(x: np.ndarray) -> list[float]:
            x = x - x.mean()
            return [float(np.mean(x[:-lag] * x[lag:]) / np.mean(x * x)) for lag in (1, 2, 3, 5, 10, 20)]

        so, sc = along[m] / size[m], e[m, 2] / fr.z[m, 2]
        r_sc = tr.states[np.array(ks)[m], :3]
        u, s_ = fr.body_pos[m] - r_sc, fr.sun_pos[m] - fr.body_pos[m]  # observer -> body, body -> Sun
        phase = np.degrees(np.arccos(np.clip(np.einsum("ki,ki->k", -u, s_) / np.linalg.norm(u, axis=1)
                                             / np.linalg.norm(s_, axis=1), -1, 1)))
        out[b] = {"frames": int(m.sum()), "phase_deg_first_last_min_max": [float(phase[0]), float(phase[-1]),
                                                                          float(phase.min()), float(phase.max())],
                  "sun_offset_by_fifth_of_the_arc_mean_se": [[float(q.mean()), float(q.std(ddof=1) / np.sqrt(q.size))]
                                                              for q in np.array_split(along[m] / size[m], 5)],
                  "mean_normalised_row_col_X": n.mean(0).tolist(),
                  "rms_normalised_row_col_X": np.sqrt((n**2).mean(0)).tolist(),
                  "mean_normalised_along_sun": float(na.mean()), "along_sun_px_mean": float(along[m].mean()),
                  "sun_offset_mean_se": [float(so.mean()), float(so.std(ddof=1) / np.sqrt(m.sum()))],
                  "scale_mean_se": [float(sc.mean()), float(sc.std(ddof=1) / np.sqrt(m.sum()))],
                  "autocorrelation_lags": [1, 2, 3, 5, 10, 20], "autocorrelation_along_sun": ac(na),
                  "autocorrelation_X": ac(n[:, 2]),
                  "by_model": by_model([draw[k] for k in np.array(ks)[m]], so, sc)}
    return out


def by_model(recs: list[dict], sun_offset: np.ndarray, scale: np.ndarray) -> dict:
    """The ``sun_offset`` and ``scale`` errors of :func:`measurement_errors` grouped by the model ``locate`` fitted
    (``extras.profile.model``): per model the frames and the mean and standard error of each."""
    names = np.array([str((r.get("extras", {}).get("profile") or {}).get("model", "-")) for r in recs])

    def mean_se(x: np.ndarray) -> list:
        return [float(x.mean()), float(x.std(ddof=1) / np.sqrt(x.size)) if x.size > 1 else None]

    return {str(name): {"frames": int((names == name).sum()), "sun_offset_mean_se": mean_se(sun_offset[names == name]),
                        "scale_mean_se": mean_se(scale[names == name])} for name in dict.fromkeys(names)}


def _pick(draws: list[dict[int, dict]], k: int, rng: np.random.Generator) -> dict:
    ok = [d[k] for d in draws if d.get(k, {}).get("status") == "ok"]
    return ok[int(rng.integers(len(ok)))]


def self_calibration(arc, prop, tr, nominal: dict[int, dict], draw0: dict[int, dict], keep, seed: int) -> dict:  # noqa: ANN001
    from jaxlimb.track import track
    from jaxlimb.track.scenario import perturb_attitudes

    from dataclasses import replace

    rng = np.random.default_rng([seed, 7])
    ks = [k for k in keep if nominal.get(k, {}).get("status") == "ok"]
    source = "locate with the nominal camera"
    if len(ks) >= 0.8 * len(keep):
        fr = as_frames(arc, tr, [nominal[k] for k in ks], perturb_attitudes(tr.C_true[ks], 1e-5, rng), THETA_NOMINAL, 1e-5)
    else:  # locate ran with the true camera (its ranges use the true f); the estimator starts from the nominal one
        ks = [k for k in keep if draw0.get(k, {}).get("status") == "ok"]
        fr = as_frames(arc, tr, [draw0[k] for k in ks], perturb_attitudes(tr.C_true[ks], 1e-5, rng), THETA_TRUE, 1e-5)
        fr = replace(fr, theta=np.tile(THETA_NOMINAL, (len(ks), 1)))
        source = "locate with the true camera (draw 0); the estimator starts from the nominal camera"
    t = time.perf_counter()
    res = track(fr, prop, calibrate=True)
    cam = res.fit.camera
    out = {"measurements": source, "frames": len(ks), "seconds": time.perf_counter() - t, "camera": cam,
           "model_error_split": res.split.to_json() if res.split is not None else None,
           "observability": res.fit.observability.to_json(), "nominal": THETA_NOMINAL.tolist(), "true": THETA_TRUE.tolist()}
    if cam["focal_px"] is not None:
        f = cam["focal_px"]
        out["focal_rel_error"] = f["value"] / THETA_TRUE[0] - 1
        out["focal_error_sigmas"] = (f["value"] - THETA_TRUE[0]) / f["sigma"]
    for i, n in ((1, "principal_r"), (2, "principal_c")):
        if cam[n] is not None:
            out[f"{n}_error_px"] = cam[n]["value"] - THETA_TRUE[i]
            out[f"{n}_error_sigmas"] = (cam[n]["value"] - THETA_TRUE[i]) / cam[n]["sigma"]
    e = res.filt.x_smooth - tr.states[ks]
    out["smoother_rms_pos_km"] = float(np.sqrt(np.mean(np.sum(e[:, :3] ** 2, 1))))
    return out


def cli_speed(arc, tr, draw: dict[int, dict], keep) -> dict:  # noqa: ANN001
    """``jaxlimb track`` on the measured frames after ``locate`` (a measurements file and ``--resume``)."""
    from jaxlimb.cli import build_parser
    from jaxlimb.cli._batch import run_settings
    from jaxlimb.cli._track import measurement_namespace
    from jaxlimb.geometry.attitude import dcm_to_quat

    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        (d / "camera.json").write_text(json.dumps(camera(THETA_TRUE).to_dict()))
        with open(d / "frames.jsonl", "w") as ff:
            for k in keep:
                q = dcm_to_quat(tr.C_true[k])
                ff.write(json.dumps({"image": str(d / f"frame{k:04d}.png"), "epoch": arc.jd0 + tr.t[k] / 86400.0,
                                     "body": tr.bodies[k], "attitude": {"quaternion": q.tolist()},
                                     "true_state": tr.states[k].tolist()}) + "\n")
        # the records carry the digest of the settings that made them, as ``jaxlimb track`` writes them (--resume)
        ns = build_parser().parse_args(["track", "--frames", str(d / "frames.jsonl"), "--camera", str(d / "camera.json")])
        settings = run_settings(measurement_namespace(ns, d / "m.jsonl"))
        with open(d / "m.jsonl", "w") as fm:
            for k in keep:
                fm.write(json.dumps({**draw[k], "image": str(d / f"frame{k:04d}.png"), "run_settings": settings}) + "\n")
        cmd = [sys.executable, "-m", "jaxlimb.cli", "track", "--frames", str(d / "frames.jsonl"), "--camera",
               str(d / "camera.json"), "--measurements", str(d / "m.jsonl"), "--resume", "--out", str(d / "t.jsonl"),
               "--plot", str(d / "t.png"), "--json"]
        env = {**os.environ, "JAXLIMB_CACHE_DIR": str(d / "jaxcache")}  # a fresh compilation cache: run 1 cold
        walls = []
        for _ in range(2):  # cold (compiles), then warm (the persistent cache of run 1)
            (d / "t.jsonl").unlink(missing_ok=True)
            t = time.perf_counter()
            p = subprocess.run(cmd, capture_output=True, text=True, env=env)
            walls.append(time.perf_counter() - t)
        summary = json.loads(p.stdout.strip().splitlines()[-1]) if p.stdout.strip() else {"stderr": p.stderr[-500:]}
        if (d / "t.png").exists():  # the picture of docs/track.md
            shutil.copyfile(d / "t.png", DOCS_PLOT)
    return {"command": "jaxlimb track --frames F --camera C --measurements M --resume --out T --plot P --json",
            "exit": p.returncode, "wall_s_cold_warm": walls, "frames": len(keep), "summary": {k: v for k, v in summary.items()
                                                                                      if k not in ("observability",)}}


def main(argv: list[str] | None = None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, required=True)
    ap.add_argument("--n-frames", type=int, default=200)
    ap.add_argument("--sequences", type=int, default=50)
    ap.add_argument("--seed", type=int, default=38)
    ap.add_argument("--no-bias", action="store_true", help="the filter without the bodies' bias states")
    ap.add_argument("--skip", default="", help="comma-separated parts to skip: rendered,drawn,selfcal,cli")
    a = ap.parse_args(argv)
    arc, prop, tr = scenario(a.n_frames, a.seed)
    recs = load_records(a.cache)
    draws = [v for k, v in recs.items() if k != "nominal"]
    keep = kept_frames(draws, a.n_frames)
    skip = set(a.skip.split(","))
    out_errors = measurement_errors(arc, tr, draws[0], keep)
    print("errors", out_errors, flush=True)
    out = {"seed": a.seed, "environment": environment(), "frames_rendered": a.n_frames, "draws": len(draws),
           "frames_measured": len(keep),
           "failed_checks": sorted({d[k]["check"] for d in draws for k in d if d[k].get("status") != "ok"}),
           "measurement_errors_draw0": out_errors}
    for name, drawn in (("rendered", False), ("drawn", True)):
        if name not in skip:
            out[f"monte_carlo_{name}"] = monte_carlo(arc, prop, tr, draws, keep, a.sequences, a.seed, drawn,
                                                       not a.no_bias)
            print(name, {k: v for k, v in out[f"monte_carlo_{name}"].items() if not k.startswith("epoch_")}, flush=True)
    if "selfcal" not in skip:
        out["self_calibration"] = self_calibration(arc, prop, tr, recs.get("nominal", {}), draws[0], keep, a.seed)
        print("selfcal", out["self_calibration"], flush=True)
    if "cli" not in skip:
        out["cli"] = cli_speed(arc, tr, draws[0], [k for k in keep if draws[0].get(k, {}).get("status") == "ok"])
        print("cli", out["cli"], flush=True)
    print(save("track_transfer_no_bias" if a.no_bias else "track_transfer", out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
