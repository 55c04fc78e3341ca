"""Markdown tables of the validation pages, read from ``benchmarks/results/*.json`` at build time.

A page asks for a table with a comment ``<!-- results: NAME ARG... -->``; :func:`render` returns the
table followed by a line naming the file it was read from and the commit recorded in it.  No number of
the validation pages is typed by hand: rerun the benchmark, rebuild the site, and the page follows.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"

_RENDERERS: dict[str, Callable[..., str]] = {}


def renderer(fn: Callable[..., str]) -> Callable[..., str]:
    _RENDERERS[fn.__name__] = fn
    return fn


def names() -> list[str]:
    return sorted(_RENDERERS)


def render(name: str, args: Sequence[str]) -> str:
    """The markdown of table ``name`` (``KeyError`` for an unknown name)."""
    return _RENDERERS[name](*args)


# ----------------------------------------------------------------------------------------- helpers
def load(rel: str) -> dict:
    path = RESULTS / rel
    if not path.is_file():
        raise FileNotFoundError(f"benchmarks/results/{rel} (cited by a validation page) does not exist")
    return json.loads(path.read_text())


def commit_of(d: dict) -> str:
    for key in ("environment", "meta"):
        env = d.get(key)
        if isinstance(env, dict) and env.get("git_sha") not in (None, "unknown"):
            return str(env["git_sha"])
    sha = d.get("git_sha")
    return str(sha)[:7] if sha else "not recorded"


def source(rel: str, d: dict | None = None) -> str:
    sha = commit_of(d) if d is not None else None
    at = "" if sha is None else ", commit not recorded" if sha == "not recorded" else f", recorded at commit `{sha}`"
    return f"\n*Source: `benchmarks/results/{rel}`{at}.*\n"


def f(x, digits: int = 3, signed: bool = False) -> str:
    """A number for a table; ``–`` for missing or non-finite."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return str(x)
    return f"{x:+.{digits}f}" if signed else f"{x:.{digits}f}"


def g(x, digits: int = 2) -> str:
    """A number in scientific notation (tolerances, tiny differences)."""
    return "–" if x is None else f"{x:.{digits}e}"


def table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    out = ["| " + " | ".join(h.replace("|", "\\|") for h in header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c).replace("|", "\\|") for c in r) + " |" for r in rows]
    return "\n".join(out) + "\n"


def failures(fail: dict | list | None) -> str:
    if not fail:
        return "–"
    if isinstance(fail, list):
        from collections import Counter

        fail = Counter(fail)
    return ", ".join(f"{k} {v}" for k, v in sorted(fail.items()))


def report_md(text: str) -> str:
    """A benchmark's own markdown report (``title`` lines before tables) as page markdown."""
    out: list[str] = []
    for line in text.strip().splitlines():
        if line and not line.startswith("|"):
            out += ["", f"**{line.strip()}**", ""]
        else:
            out.append(line)
    return "\n".join(out).strip() + "\n"


# ----------------------------------------------------------------------------------------- accuracy
@renderer
def families(rel: str, body: str) -> str:
    """Per-family accuracy of ``locate`` on the independent renderer's frames."""
    d = load(rel)
    rows = []
    for fam, s in d["summary"][body].items():
        rows.append([
            f"`{fam}`", f"{s['n_ok']}/{s['n']}",
            f"{f(s['center_median_px'])} / {f(s['center_p90_px'])} / {f(s['center_max_px'])}",
            f(s.get("range_abs_median_pct")), f(s.get("nees_mean"), 1), failures(s.get("failures")),
        ])
    head = ["family", "ok", "centre error median / p90 / max (px)", "range error median (%)", "centre NEES (2)",
            "typed failures"]
    a = d["args"]
    return table(head, rows) + source(rel, d) + f"*{a['n']} frames per family, seed {a['seed']}.*\n"


@renderer
def families_seeds(body: str, *rels: str) -> str:
    """Centre error median and NEES per family over several seeds' files (held-out frames)."""
    runs = [(rel, load(rel)) for rel in rels]
    fams = list(runs[0][1]["summary"][body])
    head = ["family"] + [f"seed {d['args']['seed']}" for _, d in runs]
    rows = []
    for fam in fams:
        row = [f"`{fam}`"]
        for _, d in runs:
            s = d["summary"][body].get(fam)
            row.append("–" if s is None or not s["n_ok"] else
                       f"{f(s['center_median_px'])} px, NEES {f(s['nees_mean'], 1)} ({s['n_ok']}/{s['n']})")
        rows.append(row)
    src = "".join(source(rel, d) for rel, d in runs)
    return table(head, rows) + src


@renderer
def locate_accuracy(rel: str = "locate_accuracy.json") -> str:
    d = load(rel)
    rows = []
    for cat, s in d["summary"].items():
        rows.append([
            f"`{cat}`", f"{s['n_ok']}/{s['n']}", f"{f(s['center_p90'])} / {f(s['radius_p90'])}",
            f"{s['phys_n_ok']}/{s['n']}", f"**{f(s['phys_center_p90'])} / {f(s['phys_radius_p90'])}**",
            f"{f(s['phys_center_p50'])}",
        ])
    head = ["scene", "sigmoid ok", "sigmoid: centre p90 / radius p90 (px)", "profile ok",
            "physical profile: centre p90 / radius p90 (px)", "profile centre median (px)"]
    return table(head, rows) + source(rel, d) + f"*{d['n_per_category']} scenes per category, seed {d['seed']}.*\n"


@renderer
def albedo_invariance(rel: str = "albedo_invariance.json") -> str:
    """The same scene under noise draws (uniform albedo) and under albedo draws (one noise draw)."""
    d = load(rel)
    rows = []
    for s in d["scenes"]:
        n, a = s["noise"], s["albedo"]
        rows.append([
            f"{s['body']}, {s['range_km']:,.0f} km, {s['phase_deg']:.0f}°",
            f"{f(n.get('mean_error_px'))} / {f(n.get('spread_px'))} / {f(n.get('mean_nees'), 1)}",
            f"{a['n_ok']}/{a['n']}",
            f"{f(a.get('median_error_px'))} / {f(a.get('p90_error_px'))}",
            f"{f(a.get('mean_error_px'))} / {f(a.get('spread_px'))} / {f(a.get('mean_nees'), 1)}",
            f(s.get("spread_ratio"), 1), failures(a.get("failures")),
        ])
    head = ["scene", "noise only: mean error / spread (px) / NEES", "albedo draws ok",
            "albedo: centre error median / p90 (px)", "albedo: mean error / spread (px) / NEES",
            "spread ratio albedo / noise", "typed failures"]
    return (table(head, rows) + source(rel, d)
            + f"*{d['noise_draws']} noise draws, {d['albedo_draws']} albedo draws per scene.*\n")


@renderer
def albedo_bias(rel: str = "albedo_bias.json") -> str:
    """One albedo-invariance scene located with parts of the profile changed (``benchmarks/albedo_bias.py``)."""
    d = load(rel)
    rows = []
    for name, v in d["variants"].items():
        for kind, x in v.items():
            s = x["summary"]
            mean, ax = s.get("mean_error_rc") or [None, None], s.get("mean_axes_error_px") or [None, None]
            rows.append([f"`{name}`", kind, f"{s['n_ok']}/{s['n']}",
                         f"{f(s.get('mean_error_px'))} ({f(mean[0], signed=True)}, {f(mean[1], signed=True)})",
                         f(s.get("spread_px")), f"{f(ax[0], signed=True)} / {f(ax[1], signed=True)}",
                         f(s.get("mean_nees"), 2), f(s.get("median_sigma_px"))])
    sc = d["scene"]
    head = ["variant", "albedo", "ok", "mean error (px) (row, col)", "spread (px)", "mean semi-axes error (px)",
            "mean NEES", "median sigma (px)"]
    return (table(head, rows) + source(rel, d)
            + f"*{sc['body']}, {sc['range_km']:,.0f} km, {sc['phase_deg']:.0f}°: {d['draws']} spots draws (one noise "
              f"draw), {d['noise_draws']} noise draws of the uniform albedo.*\n")


@renderer
def albedo_bound(rel: str = "albedo_bound.json") -> str:
    """The centre's Cramér--Rao bound without and with the spots family's albedo field marginalised."""
    d = load(rel)
    rows = [[f"moon, {s['range_km']:,.0f} km, {s['phase_deg']:.0f}° ({s['radius_px']:.0f} px)", f(s["white_px"], 4),
             f(s["field_px"], 4), f(s["albedo_part_px"], 4), f(s["ratio"], 2)] for s in d["scenes"]]
    head = ["scene", "noise-only bound (px, per axis)", "with the albedo field (px)", "albedo's part (px)",
            "albedo's part / noise-only"]
    return (table(head, rows) + source(rel, d)
            + f"*Spots-family prior: relative albedo σ {d['tau']:.3f}, correlation length {d['ell_deg']:.1f}°.*\n")


@renderer
def navigate_e2e(rel: str = "navigate_e2e.json") -> str:
    d = load(rel)
    rows = []
    for r in d["results"]:
        lo, hi = r["nees_99pct_band_of_mean"]
        rows.append([f"`{r['case']['name']}`", f"{f(r['phase_deg'], 0)}°", f"{r['n_ok']}/{r['n_runs']}",
                     f(r["bias_norm_km"], 2), f(r["rms_error_km"], 2), f(r["predicted_sigma_norm_km"], 2),
                     f"{f(r['mean_nees'], 2)} ({f(lo, 2)}–{f(hi, 2)})"])
    head = ["case", "phase", "ok", "bias (km)", "RMS error (km)", "predicted σ (km)", "mean NEES (99 % band)"]
    return table(head, rows) + source(rel, d)


@renderer
def earth_targets(rel: str = "earth_targets.json") -> str:
    d = load(rel)
    rows = [[f"{f(r['range_km'], 0)}", f"{f(r['focal_mm'], 0)}", f"{f(r['latitude_deg'], 0)}°", f"`{r['variant']}`",
             f"{f(r['center_err_px_mean'])} / {f(r['center_err_px_max'])}", f(r["pred_center_sigma_px"]),
             f"{f(r['range_err_pct_mean'], 4, True)}", f(r["pred_range_sigma_pct"], 4)] for r in d["rows"]]
    head = ["range (km)", "focal (mm)", "latitude", "variant", "centre error mean / max (px)", "predicted σ (px)",
            "range error mean (%)", "predicted σ (%)"]
    return table(head, rows) + source(rel, d)


@renderer
def horizon_vs_sigmoid(rel: str = "horizon_vs_sigmoid.json") -> str:
    d = load(rel)
    rows = [[f"`{r['frame']}`", r["arc"], r["method"], f"{r['n_ok']}/{r['n_ok'] + r['n_fail']}", f(r["center_rms_px"]),
             f(r["range_rms_pct"], 4), f(r.get("median_ms"), 1)] for r in d["rows"]]
    head = ["frame", "arc", "method", "ok", "centre RMS (px)", "range RMS (%)", "median ms"]
    return table(head, rows) + source(rel, d) + f"*{d['runs_per_frame']} noise realisations per frame.*\n"


@renderer
def sun_limb(rel: str = "sun_limb.json") -> str:
    d = load(rel)
    rows = []
    for r in d["results"]:
        sig, ld = r["sigmoid"], r["limb_darkened"]
        rows.append([f"`{r['file']}`", f(r["truth"]["radius_px"], 2),
                     sig.get("error", "").split(":")[0] or f"{f(sig['radius_err_px'], 3, True)} / {f(sig['center_err_px'])}",
                     f"{f(ld['radius_err_px'], 3, True)} / {f(ld['center_err_px'])}"])
    head = ["frame", "true radius (px)", "sigmoid: radius / centre error (px)", "limb-darkened disc: radius / centre error (px)"]
    return table(head, rows) + source(rel, d)


@renderer
def limb_arc(rel: str = "limb_arc.json") -> str:
    d = load(rel)
    rows = []
    for geo in d["geometries"] + [{"center_rc": None, "sun_angle_deg": None, "summary": d["all"]}]:
        s = geo["summary"]
        where = "all" if geo["center_rc"] is None else f"centre ({f(geo['center_rc'][0], 0)}, {f(geo['center_rc'][1], 0)})"
        rows.append([where, s["n"], f"{100 * s['fraction_in_frame']:.0f} %", f"{f(s['median_error_px'])} / {f(s['max_error_px'])}",
                     " / ".join(f(v, 2) for v in s["rms_over_sigma_rc"])])
    head = ["geometry", "n", "limb in frame", "centre error median / max (px)", "RMS error / σ (row / col)"]
    return table(head, rows) + source(rel, d)


@renderer
def earth_full_disc(rel: str = "earth_full_disc.json") -> str:
    d = load(rel)
    rows = []
    for body, fams in d["summary"].items():
        for fam, s in fams.items():
            ok = s["n_ok"]
            rows.append([body, f"`{fam}`", f"{ok}/{s['n']}",
                         "–" if not ok else f"{f(s['center_median_px'])} / {f(s['center_max_px'])}",
                         "–" if not ok else f(s.get("range_abs_median_pct")), failures(s.get("failures"))])
    head = ["attitude", "family", "ok", "centre error median / max (px)", "range error median (%)", "typed failures"]
    return table(head, rows) + source(rel, d)


@renderer
def earth_attitude_floor(rel: str = "earth_attitude_floor.json") -> str:
    d = load(rel)
    rows = []
    for group, s in d["summary"].items():
        if not isinstance(s, dict):
            continue
        k, u = s["locate_known"], s["locate_unknown"]
        rows.append([group, s["frames"], f"{f(k['median_px'])} / {f(k['p90_px'])}",
                     f"{f(u['median_px'])} / {f(u['p90_px'])} ({s['answered_unknown']})", f(s["bound_median_px"]),
                     f"{100 * s['share_bound_above_target']:.0f} %"])
    head = ["frames", "n", "R known: centre median / p90 (px)", "R unknown: median / p90 (answered)",
            "bound without R, median (px)", f"bound above {d['summary']['target_px']} px"]
    return table(head, rows) + source(rel, d)


# ----------------------------------------------------------------------------------------- irregular
@renderer
def report(rel: str) -> str:
    """A benchmark's own markdown report (``report`` key)."""
    d = load(rel)
    return report_md(d["report"]) + source(rel, d)


@renderer
def markdown_file(rel: str) -> str:
    """The first table of a caption file written beside a paper figure (``*.md``)."""
    path = RESULTS / rel
    if not path.is_file():
        raise FileNotFoundError(f"benchmarks/results/{rel} (cited by a validation page) does not exist")
    lines = path.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("|"))
    end = next((i for i in range(start, len(lines)) if not lines[i].startswith("|")), len(lines))
    made = next((line for line in lines if line.startswith("Made by:")), "")
    return "\n".join(lines[start:end]) + f"\n\n*Source: `benchmarks/results/{rel}`. {made}*\n"


# ----------------------------------------------------------------------------------------- real frames
@renderer
def cassini_enceladus(rel: str = "cassini_enceladus.json") -> str:
    d = load(rel)
    rows = []
    for name, fr in d["frames"].items():
        m = fr["measured_minus_predicted"]
        rows.append([f"`{name}`", fr["n_masked"], f"({f(m['delta_rc_px'][0], 2, True)}, {f(m['delta_rc_px'][1], 2, True)})",
                     f(m["angle_urad"], 1), f"({f(m['sigma_rc_px'][0], 2)}, {f(m['sigma_rc_px'][1], 2)})",
                     f(fr["radius_px"], 1), f"{f(fr['range_km'], 0)} / {f(fr['spice_range_km'], 0)}"])
    head = ["frame", "masked px", "measured − SPICE (row, col) px", "angle (µrad)", "σ (row, col) px", "radius (px)",
            "range measured / SPICE (km)"]
    motion = (f"\nMotion between the frames: measured ({f(d['measured_motion_px'][0], 2, True)}, "
              f"{f(d['measured_motion_px'][1], 2, True)}) px, phase correlation of the two images "
              f"({f(d['registration_motion_px'][0], 2, True)}, {f(d['registration_motion_px'][1], 2, True)}) px, "
              f"SPICE's prediction ({f(d['predicted_motion_px'][0], 2, True)}, {f(d['predicted_motion_px'][1], 2, True)}) px.\n")
    return table(head, rows) + motion + source(rel, d)


# ----------------------------------------------------------------------------------------- uncertainty
@renderer
def montecarlo_crlb(*rels: str) -> str:
    rows = []
    for rel in rels:
        d = load(rel)
        fixed = ",".join(d.get("fixed") or []) or "none"
        ratios = d["rms_over_crlb"]
        rows.append([f"`{d['options']['model']}`", fixed, f"{d['converged']}/{d['n']}",
                     ", ".join(f"{k} {f(v)}" for k, v in ratios.items()),
                     f"{min(ratios.values()):.3f}–{max(ratios.values()):.3f}"])
    head = ["model", "held", "converged", "RMS / CRLB per parameter", "range"]
    return table(head, rows) + "".join(source(rel) for rel in rels)


@renderer
def montecarlo_detail(rel: str) -> str:
    d = load(rel)
    rows = [[f"`{k}`", f(d["rms"][k], 5), f(d["bias"][k], 5, True), f(d["crlb"][k], 5), f(d["rms_over_crlb"][k])]
            for k in d["rms"]]
    return table(["parameter", "RMS", "bias", "CRLB", "RMS / CRLB"], rows) + source(rel)


@renderer
def gradcheck(rel: str = "gradcheck.json") -> str:
    d = load(rel)
    by_model: dict[str, list[dict]] = {}
    for c in d["checks"]:
        by_model.setdefault(c["model"], []).append(c)
    rows = [[f"`{m}`", len(cs), g(max(c["max_rel_err"] for c in cs)), g(max(c["max_fd_err"] for c in cs)),
             "yes" if all(c["passed"] for c in cs) else "**no**"] for m, cs in by_model.items()]
    head = ["model", "parameters", "worst relative error vs jax.jacfwd", "worst error vs central differences", "passed"]
    return table(head, rows) + source(rel, d) + f"*Status: `{d['status']}`, {len(by_model)} models.*\n"


# ----------------------------------------------------------------------------------------- speed
@renderer
def solvers(rel: str = "solvers.json") -> str:
    d = load(rel)
    p = d["problem"]
    note = (f"\n*Problem: {p['shape'][0]}×{p['shape'][1]} image, circular sigmoid, radius {p['radius']} px, "
            f"k = {p['k']}, σ = {p['sigma']} DN, {p['n_pixels']} pixels; load average {', '.join(map(str, d['loadavg']))}.*\n")
    return d["table_md"].strip().replace("|Δ|", "\\|Δ\\|") + "\n" + note + source(rel, d)


@renderer
def optimistix_plumbing(rel: str = "optimistix_plumbing.json") -> str:
    d = load(rel)
    rows = [[r["solver"], f(r["ms_per_fit"], 2), f(r["steps_mean"], 1), str(r.get("steps_max", "–")),
             f(r["over_normal_lm"], 2), f(r["cpu_over_normal_lm"], 2), g(r["max_abs_diff_vs_normal_lm"], 1)]
            for r in d["rows"]]
    head = ["solver", "ms / fit", "steps", "max steps", "wall / NormalLM", "CPU / NormalLM", "max |Δ| vs NormalLM (px)"]
    return table(head, rows) + source(rel, d) + f"*{d['n']} realisations.*\n"


@renderer
def montecarlo_cli(rel: str = "montecarlo_cli.json") -> str:
    d = load(rel)
    rows = [["`jaxlimb montecarlo` (fits only)", f(d["command_ms_per_fit"], 2)],
            ["`jaxlimb montecarlo` (CPU time, both cores)", f(d["command_cpu_ms_per_fit"], 2)],
            ["`jaxlimb montecarlo` (whole command wall time)", f(d["command_wall_ms_per_fit"], 2)],
            ["SciPy `least_squares(method='lm')`, NumPy model and Jacobian", f(d["scipy_numpy_ms_per_fit"], 2)],
            ["SciPy `least_squares` driving the JAX model", f(d["scipy_jax_ms_per_fit"], 2)]]
    return table(["what", "ms per fit"], rows) + source(rel, d) + f"*n = {d['n']}.*\n"


@renderer
def compare_cli(rel: str = "compare.json", run: str = "off") -> str:
    """``jaxlimb compare``'s rows of one run (default: no compilation cache) and every run's process time."""
    d = load(rel)
    res = d["runs"][run]["result"]
    rows = [[r["solver"], f"{100 * r['success_rate']:.1f} %", f(r["iterations_mean"], 1), str(r["iterations_max"]),
             f(r["ms_per_fit"], 2), f(r["cpu_ms_per_fit"], 2), f(r["ms_over_first"], 2), f(r["compile_s"], 1),
             g(r["max_abs_diff_vs_first_px"], 1), failures(r["failures"])] for r in res["rows"]]
    head = ["solver", "ok", "iterations", "max it", "ms / fit", "CPU ms / fit", f"× {res['rows'][0]['solver']}",
            "compile s", "max |Δ| vs first (px)", "failures"]
    procs = "; ".join(f"{k} cache: wall {f(v['process_wall_s'], 1)} s, CPU {f(v['process_cpu_s'], 1)} s, load "
                      f"{v['loadavg_before'][0]:.1f} → {v['loadavg_after'][0]:.1f}" for k, v in d["runs"].items())
    return (table(head, rows) + source(rel, d) + f"*{d['n']} realisations, {res['devices']} XLA CPU devices; "
            f"rows of the run with the cache {run}. Whole process: {procs}.*\n")


@renderer
def cli_speed(rel: str = "cli_speed.json") -> str:
    d = load(rel)
    rows = [[f"`{k}`", f(d["median_s"][k], 2), f(d["first_call_s"][k], 2), f(d["ratio_to_jax_start"][k], 2),
             f(d["cpu_ratio_to_jax_start"][k], 2)] for k in d["median_s"]]
    head = ["process", "median wall (s)", "first call (s)", "wall / JAX start", "CPU / JAX start"]
    mf = d["many_frames"]
    many = (f"\nMany frames: `jaxlimb locate DIR --out F.jsonl` on {mf['n']} frames of {mf['frame'][0]}×{mf['frame'][1]}: "
            f"{f(mf['frames_per_s_after_first'], 1)} frames/s after the first.\n")
    load_ = f"*Load average before / after: {d['loadavg_before'][0]} / {d['loadavg_after'][0]}.*\n"
    return table(head, rows) + many + source(rel, d) + load_


@renderer
def warm_locate(rel: str = "warm_locate.json") -> str:
    d = load(rel)
    rows = [[f"`{k}`", f(v["wall_ms"], 1), f(v["cpu_ms"], 1)] for k, v in d["best"].items() if isinstance(v, dict)]
    return (table(["case", "best wall (ms)", "best CPU (ms)"], rows) + source(rel, d)
            + f"*Budget {d['budget_ms']} ms; {d['args']['rounds']} rounds.*\n")


@renderer
def irregular_speed(rel: str = "irregular_speed.json") -> str:
    d = load(rel)
    rows = [[f"`{r['case']}`", f(r["error_px"], 3), f(r["in_process_s"], 2), f(r["template_search_s"], 2),
             f(r["register_s"], 2), f(r["cli_s"], 2), f(r["cli_cpu_s"], 2)] for r in d["rows"]]
    head = ["frame", "error (px)", "in process (s)", "template search (s)", "registration (s)", "`los locate` wall (s)",
            "`los locate` CPU (s)"]
    return table(head, rows) + source(rel, d) + f"*JAX start in the same run: {f(d['jax_start_s'], 2)} s.*\n"


@renderer
def los_locate_speed(rel: str = "los_locate_speed.json") -> str:
    d = load(rel)
    versions = [v for v in ("after", "before") if v in d["rows"][0]]
    name = {"after": "this commit", "before": f"`{d['args']['before']}`"}
    rows = [[f"`{r['frame']}`", *(f"{f(r[v]['wall_s'], 2)} / {f(r[v]['cpu_s'], 2)}" for v in versions),
             f(r["after"]["error_px"], 3), f(r["load"], 1)] for r in d["rows"]]  # fmt: skip
    head = ["frame", *(f"{name[v]}: wall / CPU (s)" for v in versions), "error (px)", "load average"]
    med = "; ".join(f"{name[v]} wall {f(d['median'][v]['wall_s'], 2)} s, CPU {f(d['median'][v]['cpu_s'], 2)} s" for v in versions)
    return table(head, rows) + f"\nMedians over the frames: {med}.\n" + source(rel, d) + \
        f"*Medians of {d['args']['repeats']} processes per frame and version.*\n"


@renderer
def dask_montecarlo(rel: str = "dask_montecarlo.json") -> str:
    d = load(rel)
    rows = [[w, len(runs), " / ".join(f(r["process_s"], 1) for r in runs), f(d["median_process_s"][w], 1)]
            for w, runs in d["runs"].items()]
    tail = (f"\nSpeed-up of 2 workers over 1: **{f(d['speedup_2_vs_1'], 2)}×**; result files identical across runs: "
            f"{f(d['identical_result_files'])}.\n")
    return table(["workers", "runs", "process time per run (s)", "median (s)"], rows) + tail + source(rel, d) + \
        f"*n = {d['n']} trials.*\n"


@renderer
def pipeline_families(*rels: str) -> str:
    """One table per results file of ``benchmarks/pipeline_families.py``: the centre per family."""
    out = []
    for rel in rels or ("pipeline_families.json",):
        d = load(rel)
        rows = [[f"`{k}`", f"{s['n_ok']} / {s['n']}", f"{f(s['row']['bias'], 3, True)}, {f(s['col']['bias'], 3, True)}",
                 f"{f(s['row']['rms'])}, {f(s['col']['rms'])}", f"{f(s['sigma_row_mean'])}, {f(s['sigma_col_mean'])}",
                 f"{f(s['crlb_row_mean'])}, {f(s['crlb_col_mean'])}", f(s["nees_mean"], 2), f(s["nees_median"], 2),
                 f"{f(s['coverage']['68'], 2)} / {f(s['coverage']['95'], 2)}"] for k, s in d["summary"].items()]
        head = ["family", "answered", "bias row, col (px)", "RMS row, col (px)", "mean σ row, col (px)",
                "mean CRLB row, col (px)", "mean NEES", "median NEES", "inside 68 % / 95 %"]
        fails = ", ".join(f"{k} {v}" for k, v in d.get("failures", {}).items()) or "none"
        out.append(f"`{d['command']}`\n\n" + table(head, rows) + source(rel, d)
                   + f"*Typed failures: {fails}; process wall time {f(d['process_wall_s'], 0)} s.*\n")
    return "\n".join(out)


@renderer
def locate_montecarlo(rel: str = "locate_montecarlo.json") -> str:
    d = load(rel)
    rows = [[d["n"], f"{d['frame'][0]}×{d['frame'][1]}", f(d["sigma_dn"], 0), f(d["ms_per_frame"], 0),
             f(d["first_call_s"], 1), ", ".join(f(v, 4, True) for v in d["mean_error_rc_radius_px"]),
             ", ".join(f(v, 4) for v in d["std_rc_radius_px"])]]
    head = ["frames", "size", "σ (DN)", "ms / frame", "first call (s)", "mean error row, col, radius (px)",
            "std row, col, radius (px)"]
    return table(head, rows) + source(rel, d)


@renderer
def small_bodies(rel: str = "small_bodies.json") -> str:
    d = load(rel)
    rows = []
    for r in d["rows"]:
        s = r["summary"]
        e, m = s["center_err_px"], s["moments_err_px"]
        rad = s.get("radius_rel_err_mean")
        rows.append([r["label"], r["shape"], f"{s['n_ok']}/{s['n']}", f"{f(e['median'])} / {f(e['p90'])} / {f(e['max'])}",
                     "–" if rad is None else f"{100 * rad:+.2f} %", f(s["nees_mean"], 2), f(s["fallback_share"], 2),
                     f"{f(m['median'])} / {f(m['p90'])}",
                     f(s["moments_nees_mean"], 2), failures(s["failures"])])
    head = ["radius (px)", "strategy", "answered", "centre error median / p90 / max (px)", "radius error (mean)",
            "NEES mean", "fallback share", "centre of brightness, phase-corrected: median / p90 (px)", "its NEES mean",
            "typed refusals"]
    return table(head, rows) + source(rel, d)


@renderer
def albedo_consider(rel: str = "albedo_consider.json") -> str:
    """The Moon families' centre NEES with ``locate``'s covariance, without its albedo term, and with the sandwich's
    variants in place of that term."""
    d = load(rel)
    rows = [[fam, f"{s['n_ok']}/{s['n']}", f(s["nees_locate"], 2), f(s["nees_without"], 2),
             " / ".join(f(s[f"nees_{k}"], 2) for k in ("cr2", "hac2", "hac4")),
             f(s["tau_median"], 3), f(s["sigma_ratio_median"], 2)] for fam, s in d["summary"].items() if s.get("n_ok")]
    head = ["family", "answered", "mean NEES, locate", "without the albedo term",
            "without it, sandwich CR2 / neighbours 2 / 4", "field amplitude τ (median)",
            "centre σ with / without the term (median)"]
    return table(head, rows) + source(rel, d) + "*Mean NEES: χ²₂ expects 2.*\n"
