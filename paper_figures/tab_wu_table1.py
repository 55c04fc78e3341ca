"""Table 1 of Wu, Zou, Xu & Mao: LOS determination on one simulated 512 x 512 image, at phases 0, 30, 60 deg.

The paper (Amalthea, 3 deg templates, zero phase) places the body-centre image at (256, 256),
finds (255.5, 256.5) -- error (-0.5, 0.5) px -- in 121 ms (MATLAB, 3.1 GHz PC).  Our analogue:
Thebe rendered by :func:`jaxlimb.render.mesh.render_mesh` into a 512 x 512 image of the
default 16 mm / 2.2 um camera with the body centre at (256, 256), an off-grid view, lit at
phase 0, 30 and 60 deg, located by :func:`jaxlimb.irregular.locate_center` (Wu et al. +
guards; time = segmentation + matching + transform, median of repeated calls), by the figure
centre (FC), and by the checked :func:`jaxlimb.irregular.locate.locate_los` with the attitude
known (render-and-register) and, in full mode, unknown (phase-aware template search).  Below
it, the statistics over many views of ``fig09_wu_angle_error``'s live run.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

import _common
from fig09_wu_angle_error import BENCH_CMD, MESH, PAPER, PHASES, results, source_text

STEM = "tab_wu_table1"


def _sun(t: np.ndarray, phase: float) -> np.ndarray:
    u = -t / np.linalg.norm(t)
    a = np.cross(u, [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    return u * math.cos(math.radians(phase)) + a * math.sin(math.radians(phase))


def _err(call: Any, truth: np.ndarray) -> list[float] | str:
    from jaxlimb.errors import JaxlimbError

    try:
        return (np.asarray(call()) - truth).tolist()
    except JaxlimbError as e:
        return f"{e.check}"


def single_image(quick: bool) -> dict[str, Any]:
    """Table 1 setting: one 512 x 512 image with the body centre at (256, 256), at each phase."""
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.irregular import DatabaseOptions, build_database, load_mesh, locate_center
    from jaxlimb.irregular.locate import locate_los
    from jaxlimb.irregular.views import viewpoint_directions
    from jaxlimb.render.mesh import look_at_rotation, render_mesh

    step, tsize = (15.0, 256) if quick else (3.0, 512)
    cam = Camera(rows=512, cols=512)
    mesh = load_mesh(MESH)
    t0 = time.perf_counter()
    db = build_database(mesh, DatabaseOptions(step_deg=step, pole_axis="y", template_size_px=tsize), progress=False)
    build_s = time.perf_counter() - t0
    d = np.array([0.55, 0.32, 0.77])
    d /= np.linalg.norm(d)
    R = look_at_rotation(d, roll_rad=0.4)
    D = 2.0 * mesh.max_radius * cam.focal_px / 300.0  # bounding sphere 300 px across
    pr, pc = cam.principal_point_rc
    t = np.array([(256.0 - pc) * D / cam.focal_px, (256.0 - pr) * D / cam.focal_px, D])
    dirs = viewpoint_directions(db.alpha, db.beta, "y")
    ang = float(np.degrees(np.arccos(np.clip(dirs @ (-R.T @ t / np.linalg.norm(t)), -1, 1)).min()))
    per_phase = {}
    for ph in PHASES:
        sun = _sun(t, ph)
        out = render_mesh(mesh.vertices, mesh.faces, cam, R, t, sun_dir_camera=sun)
        m = locate_center(out.image, db, cam)
        times = []
        for _ in range(3 if quick else 10):
            t1 = time.perf_counter()
            locate_center(out.image, db, cam)
            times.append(1e3 * (time.perf_counter() - t1))
        row = {"true_center_rc": out.center_rc.tolist(), "match_center_rc": m.center_rc.tolist(),
               "match_error_rc": (m.center_rc - out.center_rc).tolist(), "fc_error_rc": (m.figure_center_rc - out.center_rc).tolist(),
               "locate_ms_median": float(np.median(times)),
               "known_error_rc": _err(lambda: locate_los(out.image, db, cam, sun, R).center_rc, out.center_rc)}
        if not quick:
            t1 = time.perf_counter()
            row["checked_error_rc"] = _err(lambda: locate_los(out.image, db, cam, sun).center_rc, out.center_rc)
            row["checked_s"] = time.perf_counter() - t1
        per_phase[f"{ph:g}"] = row
    return {"step_deg": step, "n_templates": len(db), "template_size_px": tsize, "build_s": build_s,
            "angle_to_template_deg": ang, "image_size_px": [512, 512], "phases": per_phase}


def main(out_dir: Path | str = _common.DEFAULT_OUT, quick: bool = False) -> list[Path]:
    """Make the Table 1 analogue (markdown + JSON) and a bar chart of the errors per phase."""
    plt = _common.setup()
    out_dir = Path(out_dir)
    one = single_image(quick)
    many = results(quick)

    def pair(v: list[float] | str, nd: int = 3) -> str:
        if isinstance(v, str):
            return f"typed failure ({v})"
        return f"({v[0]:.{nd}f}, {v[1]:.{nd}f}), modulus {math.hypot(*v):.{nd}f}"

    rows = ["| | paper (Amalthea, phase 0) | " + " | ".join(f"ours, phase {p}" for p in one["phases"]) + " |",
            "|---|---|" + "---|" * len(one["phases"])]
    ph = one["phases"]

    def line(label: str, paper: str, key: str) -> str:
        return f"| {label} | {paper} | " + " | ".join(pair(v[key]) if key in v else "-" for v in ph.values()) + " |"

    rows += [
        f"| Image size / template step | (512, 512) / 3 deg, 6962 | (512, 512) / {one['step_deg']:g} deg, {one['n_templates']} |"
        + " |" * (len(ph) - 1),
        "| Real value of imaging point of CTCB (pixel) | (256, 256) | " + " | ".join(f"({v['true_center_rc'][0]:.1f}, {v['true_center_rc'][1]:.1f})" for v in ph.values()) + " |",
        line("Error, matching (pixel)", "(-0.5, 0.5), modulus 0.71", "match_error_rc"),
        line("Error, figure centre FC (pixel)", "not given", "fc_error_rc"),
        line("Error, checked, attitude known (pixel)", "-", "known_error_rc"),
        line("Error, checked, attitude unknown, Sun known (pixel)", "-", "checked_error_rc"),
        "| Time, matching (ms) | 121 (MATLAB, 3.1 GHz) | " + " | ".join(f"{v['locate_ms_median']:.1f}" for v in ph.values()) + " |",
        f"| Database construction | 118 min | {one['build_s']:.1f} s |" + " |" * (len(ph) - 1),
    ]

    def ms(s: dict[str, Any], k: str) -> str:
        m = s.get(k + "_median_px")
        return f"{m:.3f} / {s[k + '_p90_px']:.3f}" if m is not None else "-"

    stats = ["| phase (deg), n | matching | FC | checked, attitude unknown (failures) | checked, attitude known (failures) |",
             "|---|---:|---:|---:|---:|"]
    for p, s in many["by_phase"].items():
        stats.append(f"| {p}, {s['n']} | {ms(s, 'err_match')} | {ms(s, 'err_fc')} | {ms(s, 'err_checked')} ({s['n_failed']['err_checked']}) "
                     f"| {ms(s, 'err_known')} ({s['n_failed']['err_known']}) |")

    fig, ax = plt.subplots()
    x = np.arange(len(ph))
    for i, (key, lab) in enumerate((("match_error_rc", "matching (Wu et al.)"), ("fc_error_rc", "FC"), ("known_error_rc", "checked, attitude known"),
                                    ("checked_error_rc", "checked, attitude unknown"))):
        vals = [math.hypot(*v[key]) if isinstance(v.get(key), list) else np.nan for v in ph.values()]
        ax.bar(x + (i - 1.5) * 0.2, vals, 0.2, label=lab)
    ax.axhline(PAPER["error_modulus_px"], color="0.3", ls="--", lw=0.8, label="paper, phase 0 (0.71 px)")
    ax.set_yscale("log")
    ax.set_xticks(x, [f"phase {p} deg" for p in ph])
    ax.set(ylabel="body-centre image error (px)", title="Wu et al. Table 1 analogue: error modulus (Thebe, 512 x 512)")
    ax.legend(fontsize="x-small")
    paths = [_common.save(fig, out_dir, STEM)]
    body = (
        "Paper: Wu et al. Table 1 (Amalthea, 20160 facets, one simulated 512 x 512 image, zero phase). Ours: Thebe (5040 faces, "
        f"pole axis y), one 512 x 512 image of the 16 mm / 2.2 um camera at phases 0/30/60 deg, {one['step_deg']:g} deg templates of "
        f"{one['template_size_px']} px, angle to the nearest template {one['angle_to_template_deg']:.2f} deg"
        f"{'; attitude-unknown search skipped in quick mode' if quick else ''}.\n\n" + "\n".join(rows)
        + f"\n\nOver many views -- {source_text(many, quick)}\n\nMedian / p90 error (px):\n\n" + "\n".join(stats)
    )
    paths.append(_common.write_caption(out_dir, STEM, "Table 1 (Wu et al.) analogue: LOS determination on one image", body, quick, {
        "paper": PAPER, "ours_single_image": one, "ours_many_views": {"source": many["source"], "by_phase": many["by_phase"]},
        "statistics_command": BENCH_CMD,
    }))
    return paths


if __name__ == "__main__":
    _common.cli(main, STEM)
