"""The tables of the real-frames page (``docs/validation/real-frames.md``), read from
``benchmarks/results/real_frames.json``.

Registered with :mod:`results_tables` (loaded first by the docs hook): ``<!-- results: real_frames_epic -->``,
``<!-- results: euv_sun -->``.
"""

from __future__ import annotations

import math

import jaxlimb_results_tables as rt  # the sibling the hook loaded before this one


def _sigma_max(ans: dict) -> float | None:
    """The centre's 1-sigma, larger axis, of an answer (its covariance), or the one its refusal states."""
    c = ans.get("covariance") or {}
    if "center_r" in c:
        a, b, d = c["center_r"]["center_r"], c["center_r"]["center_c"], c["center_c"]["center_c"]
        return math.sqrt(0.5 * (a + d) + math.sqrt(0.25 * (a - d) ** 2 + b * b))
    msg = ans.get("message", "")
    if "1-sigma is " in msg:
        return float(msg.split("1-sigma is ")[1].split(" ")[0])
    return None


def _cells(row: dict) -> list[str]:
    ans, v = row["answer"], row["verdict"]
    status = "ok" if ans.get("status") == "ok" else f"`{ans.get('check', '?')}`"
    err = v.get("center_error_rc")
    return [status,
            "–" if err is None else f"{v['center_error_px']:.2f} ({err[0]:+.2f}, {err[1]:+.2f})",
            rt.f(_sigma_max(ans), 2),
            "–" if v.get("range_error_frac") is None else f"{100 * v['range_error_frac']:+.2f} % ({v['range_z']:+.2f}σ)",
            rt.f(v["semi_major_px_times_range_km"] / 1e8, 4) if "semi_major_px_times_range_km" in v else "–"]


@rt.renderer
def real_frames_epic() -> str:
    """Every EPIC frame as typed (centre tolerance 1 px) and with ``--max-center-sigma-px none``."""
    d = rt.load("real_frames.json")
    frames = d["frames"]
    rows = []
    for name in sorted(n for n in frames if n.startswith("epic_") and not n.endswith("_any_sigma")):
        date, ext = name.split("_")[1:3]
        typed, anyway = frames[name], frames.get(f"{name}_any_sigma")
        rows.append([f"{date} {ext}", *_cells(typed)[:1], *(_cells(anyway) if anyway else ["–"] * 5)])
    head = ["frame", "status as typed", "status, `--max-center-sigma-px none`", "centre − product centre (px)",
            "centre 1-σ, larger axis (px)", "range − metadata (σ)", "semi-major × range (10⁸ px km)"]
    scatter = d.get("epic_radius_times_range_scatter")
    note = ("" if scatter is None else
            f"\n*Semi-major axis × range over the frames answered with `--max-center-sigma-px none`: standard deviation "
            f"/ mean = {100 * scatter:.3f} %.*\n")
    return rt.table(head, rows) + note + rt.source("real_frames.json", d)


@rt.renderer
def euv_sun(rel: str = "euv_sun.json") -> str:
    """The real AIA 171 frame and the independent EUV renders, per radius (``benchmarks/euv_sun.py``)."""
    d = rt.load(rel)
    a = d["aia_171"]
    rows = [[f"`{a['frame']}` (real)", "1", "1" if a["status"] == "ok" else f"`{a.get('check')}`",
             a.get("profile", "–"), rt.f(a.get("center_err_px")), rt.f(a.get("nees"), 2),
             rt.f(a.get("radius_err_px"), 3, True)]]
    for R, v in d["radii"].items():
        s = v["summary"]
        rows.append([f"render, R = {R} px", s["n"], s["answered"], f"corona {s['corona']}/{s['answered']}",
                     f"{rt.f(s['median_px'])} / {rt.f(s['p90_px'])} / {rt.f(s['max_px'])}", rt.f(s["mean_nees"], 2),
                     rt.f(s["radius_err_median_px"], 3, True)])
    head = ["frames", "n", "answered", "profile", "centre error (px): median / p90 / max", "mean NEES",
            "radius − photosphere (px), median"]
    return rt.table(head, rows) + rt.source(rel, d)
