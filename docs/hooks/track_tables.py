"""The tables of the track page (``docs/track.md``), read from ``benchmarks/results/track_transfer*.json``.

Registered with :mod:`results_tables` (loaded first by the docs hook): ``<!-- results: track_transfer -->``,
``track_selfcal``, ``track_cli``, ``track_epic``, ``track_noise`` and ``track_efficiency``.
"""

from __future__ import annotations

import jaxlimb_results_tables as rt  # the sibling the hook loaded before this one

COLUMNS = (("track_transfer_no_bias.json", "monte_carlo_rendered", "rendered, `--no-bias`"),
           ("track_transfer_whole_prior.json", "monte_carlo_rendered", "rendered, whole model error as bias prior"),
           ("track_transfer.json", "monte_carlo_rendered", "rendered, split (default)"),
           ("track_transfer.json", "monte_carlo_drawn", "drawn, split (default)"),
           ("track_transfer_no_bias.json", "monte_carlo_drawn", "drawn, `--no-bias`"))


def _rows(runs: list[dict]) -> list[list[str]]:
    def band(m: dict, key: str) -> str:
        lo, hi = m[key]
        return f"[{lo:.2f}, {hi:.2f}]"

    def se(m: dict, key: str) -> str:
        v = m.get("standard_errors", {}).get(key)
        return "" if v is None else f" ± {v:.2f}"

    def ratio(m: dict) -> str:
        return (f"{m['smoother_rms_pos_km']:.2f} / {m['pcrb_rms_pos_km']:.2f} = **{m['smoother_over_pcrb']:.2f}**"
                + se(m, "smoother_over_pcrb"))

    def batch(m: dict) -> str:
        if "batch_rms_pos_km" not in m:
            return "–"
        return f"{m['batch_rms_pos_km']:.2f} / {m['pcrb_rms_pos_km']:.2f} = {m['batch_over_pcrb']:.2f}"

    rows = [("sequences × frames", lambda m: f"{m['sequences']} × {m['frames']}", "≥ 50 × ≥ 200"),
            ("mean NEES of the filtered state (6 expected)",
             lambda m: f"**{m['mean_nees_filtered']:.2f}**" + se(m, "mean_nees_filtered"),
             band(runs[0], "nees_band_95") + " (95 % band of a 50-run average)"),
            ("epochs whose run-average NEES is in that band", lambda m: f"{m['epochs_nees_in_band']:.0%}", ""),
            ("mean NIS (3 expected)", lambda m: f"**{m['mean_nis']:.2f}**" + se(m, "mean_nis"),
             band(runs[0], "nis_band_95")),
            ("epochs whose run-average NIS is in its band", lambda m: f"{m['epochs_nis_in_band']:.0%}", ""),
            ("frames gated", lambda m: f"{m['gated_fraction']:.1%}", ""),
            ("measurement NEES of `locate` against the truth (3 expected)",
             lambda m: f"{m['measurement_nees_mean']:.2f}", ""),
            ("smoother RMS position error / posterior CRB (km)", ratio, "≤ 1.2"),
            ("NEES of the smoothed position (3 expected)",
             lambda m: rt.f(m.get("smoother_nees_position_mean"), 2) + se(m, "smoother_nees_position_mean"), ""),
            ("batch fit's RMS position error / posterior CRB (km)", batch, ""),
            ("NEES of the batch fit's position (3 expected)", lambda m: rt.f(m.get("batch_nees_position_mean"), 2), "")]
    return [[name] + [fn(m) for m in runs] + [target] for name, fn, target in rows]


@rt.renderer
def track_transfer() -> str:
    """The Monte Carlo of ``benchmarks/track_transfer.py``: the filters side by side (``COLUMNS``)."""
    files = {rel: rt.load(rel) for rel, _, _ in COLUMNS}
    runs = [files[rel][part] for rel, part, _ in COLUMNS]
    head = ["quantity"] + [c for _, _, c in COLUMNS] + ["target"]
    split = files["track_transfer.json"]["monte_carlo_rendered"].get("model_error_split", {})
    parts = "; ".join(f"{b}: " + ", ".join(f"{k} {v[0]:.2f} [{v[1]:.2f}, {v[2]:.2f}]" for k, v in s.items())
                      for b, s in split.items())
    note = ("\n*± a standard error over the sequences (where recorded); the rendered sequences share measurements, "
            "so theirs are lower bounds.*\n")
    return (rt.table(head, _rows(runs)) + note + f"\n*The split on the rendered sequences (mean [min, max] over the "
            f"50): {parts}.*\n" + "".join(rt.source(rel, d) for rel, d in files.items()))


@rt.renderer
def track_selfcal(rel: str = "track_transfer.json") -> str:
    """The self-calibration row of ``benchmarks/track_transfer.py``."""
    d = rt.load(rel)
    s = d["self_calibration"]
    cam = s["camera"]

    def cell(name: str, i: int) -> str:
        c = cam[name]
        if c is None:
            return "unobservable"
        err = c["value"] - s["true"][i]
        return f"{c['value']:.4f} ± {c['sigma']:.4f} (error {err:+.4f}, {err / c['sigma']:+.2f} σ)"

    rows = [[f"{s['frames']}", s["measurements"], ", ".join(f"{v:g}" for v in s["nominal"]),
             cell("focal_px", 0), cell("principal_r", 1), cell("principal_c", 2), cell("k1", 3)]]
    head = ["frames", "measurements", "started at (f, r_c, c_c, k1)", "focal length (px)", "principal r (px)",
            "principal c (px)", "k1"]
    return "\n\n" + rt.table(head, rows) + rt.source(rel, d)


@rt.renderer
def track_cli(rel: str = "track_transfer.json") -> str:
    """The wall time of ``jaxlimb track`` on the measured frames, cold and warm compilation cache."""
    d = rt.load(rel)
    cold, warm = d["cli"]["wall_s_cold_warm"]
    return (f"**{cold:.0f} s** with an empty compilation cache and **{warm:.0f} s** with the cache the first run "
            f"filled (exit {d['cli']['exit']}; `benchmarks/results/{rel}`, commit `{rt.commit_of(d)}`)")


@rt.renderer
def track_epic(rel: str = "track_epic.json") -> str:
    """DSCOVR's position from each EPIC frame against its metadata (``benchmarks/track_epic.py``)."""
    d = rt.load(rel)
    rows = []
    for fr in d["frames"]:
        date = fr["frame"].rsplit("_", 1)[-1]
        day = f"{date[:4]}-{date[4:6]}-{date[6:]}"
        angle = rt.f(fr["boresight_vs_metadata_rad"] * 1e6, 0)
        att = rt.f(fr["attitude_sigma_rad"] * 1e6, 0)
        if fr["status"] != "ok":
            rows.append([day, f"refused: `{fr['check']}`", "", "", "", angle, att, "", ""])
            continue
        rows.append([day, f"{fr['error_range_km']:+,.0f}", f"{fr['sigma_range_km']:,.0f}", f"{fr['error_lateral_km']:,.0f}",
                     f"{fr['sigma_lateral_km']:,.0f}", angle, att, rt.f(fr["mahalanobis_sq"], 2),
                     "yes" if fr["within_3_sigma"] else "**no**"])
    head = ["frame", "range error (km)", "range sigma (km)", "lateral error (km)", "lateral sigma per axis (km)",
            "boresight vs metadata (µrad)", "attitude sigma (µrad)", "Mahalanobis²", "within 3 sigma"]
    att = d["attitude_sigma_rad"]
    how = f"from the other {len(d['frames']) - 1} frames (leave one out)" if att == "leave-one-out" else f"{att:g} rad"
    return (rt.table(head, rows) + f"\n*{d['measured']} of {len(d['frames'])} frames measured, {d['within_3_sigma']} "
            f"within 3 sigma (Mahalanobis² of range and both lateral axes below 14.16, chi-square's 99.73 % with 3 "
            f"degrees of freedom); attitude sigma {how}.*\n" + rt.source(rel, d))


@rt.renderer
def track_noise(rel: str = "track_noise.json") -> str:
    """``locate``'s covariance of the transfer's frames against their errors, per body (``benchmarks/track_noise.py``)."""
    d = rt.load(rel)
    nis = d.get("mean_nis_rendered") or {}
    rows = []
    for body, s in d["bodies"].items():
        for comp, v in s.items():
            if comp == "frames":
                continue
            rows.append([body, comp, rt.f(v["e2_over_N_mean"], 2), rt.f(v["e2_over_N_median"], 2),
                         f"{100 * v['beyond_chi2_99']:.1f} %", rt.f(v["e2_over_R_mean"], 2),
                         rt.f(v["M_over_N_median"], 1), rt.f(v["corr_log_e2_log_M"], 2),
                         rt.f(nis[body], 2) if body in nis and comp == "row" else ""])
    head = ["body", "component", "mean e²/N (1)", "median e²/N (0.45)", "e²/N > 6.63 (1 %)", "mean e²/R (1)",
            "median M/N", "corr(log e²/N, log M/N)", "mean NIS (3)"]
    whole = [[b, rt.f(v["N"]["mean"], 2), f"{100 * v['N']['beyond_chi2_99']:.1f} %",
              rt.f(v["N_variances_only"]["mean"], 2), f"{100 * v['N_variances_only']['beyond_chi2_99']:.1f} %",
              rt.f(v["R"]["mean"], 2), " / ".join(rt.f(x, 2) for x in v["N_abs_correlation_median"].values())]
             for b, v in d.get("whole_error", {}).items()]
    whole_head = ["body", "mean eᵀN⁻¹e (3)", "above 11.34 (1 %)", "the same with N's variances only", "above 11.34",
                  "mean eᵀR⁻¹e (3)", "N's median |correlation|: row-col / row-size / col-size"]
    fifths = [[b, f"{x['frames'][0]}–{x['frames'][1]}", rt.f(x["eNe_median"], 1), rt.f(x["eRe_median"], 2),
               rt.f(x["M_over_N_median"], 0)]
              for b, v in d.get("whole_error", {}).items() for x in v.get("by_fifth_of_the_arc", [])]
    fifth_head = ["body", "frames (a fifth of the arc)", "median eᵀN⁻¹e (2.37)", "median eᵀR⁻¹e (2.37)",
                  "median tr(N⁻¹M)/3"]
    return (rt.table(head, rows) + f"\n*{d['draws']} noise draws of every frame; N: `locate`'s noise-only bound, "
            "M: its model-error term, R = N + M; expected values in brackets.*\n\n"
            + (rt.table(whole_head, whole) + "\n" if whole else "")
            + (rt.table(fifth_head, fifths) + "\n" if fifths else "") + rt.source(rel, d))


@rt.renderer
def phase_across_disc(rel: str = "phase_across_disc.json") -> str:
    """``benchmarks/phase_across_disc.py``: ``locate``'s error on the transfer's close Moon frames under three laws,
    each point at its own phase angle and with the phase held at the body's across the disc."""
    d = rt.load(rel)
    fr = d["frames"]
    head = ["law", "phase angle", "frames", "along the Sun (px)", "along / radius", "mean abs across (px)",
            "size (px)"]
    rows = [[*key.split(", "), str(v["frames"]), rt.f(v["along_px"], 4, True), rt.f(v["along_over_radius"], 5, True),
             rt.f(v["abs_across_px"], 4), rt.f(v["size_px"], 4, True)] for key, v in d["summary"].items()]
    span = (f"\n*Frames {fr[0]['frame']}–{fr[-1]['frame']} of the transfer: radius "
            f"{min(x['radius_px'] for x in fr):.0f}–{max(x['radius_px'] for x in fr):.0f} px, phase "
            f"{min(x['phase_deg'] for x in fr):.1f}–{max(x['phase_deg'] for x in fr):.1f}°, angular radius "
            f"{min(x['alpha0_deg'] for x in fr):.2f}–{max(x['alpha0_deg'] for x in fr):.2f}°; each error the mean of "
            f"{d['draws']} noise draws, then over the frames.*\n")
    laws = ("lambert", "lunar-lambert", "hapke")
    per = [[str(x["frame"]), f"{x['phase_deg']:.1f}", f"{x['alpha0_deg']:.2f}", f"{x['radius_px']:.1f}"]
           + [rt.f(x[law][var].get("along_px"), 4, True) for law in laws for var in ("per point", "held")
              if law != "lambert" or var == "per point"] for x in fr]
    per_head = ["frame", "phase (°)", "angular radius (°)", "radius (px)", "Lambert", "lunar-Lambert",
                "lunar-Lambert, held", "Hapke", "Hapke, held"]
    return (rt.table(head, rows) + span + "\n*Along the Sun (px), frame by frame:*\n\n" + rt.table(per_head, per)
            + "\n" + rt.source(rel, d))


@rt.renderer
def track_efficiency(rel: str = "track_efficiency.json") -> str:
    """The batch fit's error against the posterior CRB on drawn measurements (``benchmarks/track_efficiency.py``)."""
    d = rt.load(rel)
    rows = [["sequences × frames", f"{d['sequences']} × {d['frames']}"],
            ["batch RMS position error / posterior CRB (km)",
             f"{d['batch_rms_pos_km']:.2f} / {d['pcrb_rms_pos_km']:.2f} = **{d['batch_over_pcrb']:.3f}** ± "
             f"{d['batch_over_pcrb_se']:.3f}"],
            ["the batch's own position sigma / posterior CRB", f"{d['batch_cov_over_pcrb']:.4f}"],
            ["NEES of the batch fit's position (3 expected)",
             f"{d['batch_nees_position_mean']:.2f} ± {d['batch_nees_position_se']:.2f}"],
            ["initial state, along the CRB's eigendirections: mean squared error / bound (1 expected)",
             ", ".join(f"{e['mse_over_variance']:.2f}" for e in d["initial_state_eigendirections"])]]
    return rt.table(["quantity", "value"], rows) + rt.source(rel, d)
