"""Table 1 of Wu, Zou, Xu & Mao: LOS determination on one simulated 512 x 512 image.

The paper (Amalthea, 3 deg templates) places the body-centre image at (256, 256), finds
(255.5, 256.5) -- error (-0.5, 0.5) px -- in 121 ms (MATLAB, 3.1 GHz PC).  Our analogue:
Thebe rendered by :func:`jaxlimb.render.mesh.render_mesh` into a 512 x 512 image of the
default 16 mm / 2.2 um camera with the body centre at (256, 256), an off-grid view, located by
:func:`jaxlimb.irregular.locate_centre` (time = segmentation + matching + transform, median of
repeated calls), then densified and (full mode) refined; FC beside it.  Below it, the
statistics over many views: from ``benchmarks/results/irregular_los.json`` (made by
``python benchmarks/irregular_los.py``) in full mode, from the small live run of
``fig09_wu_angle_error`` in quick mode (or when that file is absent).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

import _common
from fig09_wu_angle_error import BENCH_CMD, MESH, PAPER, results, source_text

STEM = "tab_wu_table1"


def single_image(quick: bool) -> dict[str, Any]:
    """Table 1 setting: one 512 x 512 image with the body centre at (256, 256)."""
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.irregular import DatabaseOptions, build_database, densify_match, load_mesh, locate_centre, refine_centre
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
    size = 300.0  # apparent diameter of the bounding sphere (px)
    D = 2.0 * mesh.max_radius * cam.focal_px / size
    pr, pc = cam.principal_point_rc
    t = np.array([(256.0 - pc) * D / cam.focal_px, (256.0 - pr) * D / cam.focal_px, D])
    out = render_mesh(mesh.vertices, mesh.faces, cam, R, t)
    dirs = viewpoint_directions(db.alpha, db.beta, "y")
    ang = float(np.degrees(np.arccos(np.clip(dirs @ (-R.T @ t / np.linalg.norm(t)), -1, 1)).min()))
    m = locate_centre(out.image, db, cam)
    times = []
    for _ in range(3 if quick else 10):
        t1 = time.perf_counter()
        locate_centre(out.image, db, cam)
        times.append(1e3 * (time.perf_counter() - t1))
    dn = densify_match(m.mask, db, cam, m)
    res: dict[str, Any] = {
        "step_deg": step, "n_templates": len(db), "template_size_px": tsize, "build_s": build_s,
        "angle_to_template_deg": ang, "image_size_px": [512, 512], "true_centre_rc": out.centre_rc.tolist(),
        "match_centre_rc": m.centre_rc.tolist(), "match_error_rc": (m.centre_rc - out.centre_rc).tolist(),
        "densified_centre_rc": dn.centre_rc.tolist(), "densified_error_rc": (dn.centre_rc - out.centre_rc).tolist(),
        "fc_centre_rc": m.figure_centre_rc.tolist(), "fc_error_rc": (m.figure_centre_rc - out.centre_rc).tolist(),
        "locate_ms_median": float(np.median(times)),
    }
    if not quick:
        t1 = time.perf_counter()
        r = refine_centre(out.image, db, cam, m)
        res["refine_s"] = time.perf_counter() - t1
        res["refined_centre_rc"] = r.centre_rc.tolist()
        res["refined_error_rc"] = (r.centre_rc - out.centre_rc).tolist()
    return res


def main(out_dir: Path | str = _common.DEFAULT_OUT, quick: bool = False) -> list[Path]:
    """Make the Table 1 analogue (markdown + JSON) and a bar chart of the errors."""
    plt = _common.setup()
    out_dir = Path(out_dir)
    one = single_image(quick)
    many = results(quick)
    s = many["summary"]

    def pair(v: list[float], nd: int = 2) -> str:
        return f"({v[0]:.{nd}f}, {v[1]:.{nd}f})"

    def mod(v: list[float]) -> float:
        return float(math.hypot(*v))

    rows = [
        "| | paper (Amalthea) | ours (Thebe) |", "|---|---|---|",
        f"| Image size (pixel) | (512, 512) | {pair(one['image_size_px'], 0)} |",
        f"| Template step / templates | 3 deg / 6962 | {one['step_deg']:g} deg / {one['n_templates']} |",
        f"| Angle to the nearest template (deg) | - | {one['angle_to_template_deg']:.2f} |",
        f"| Real value of imaging point of CTCB (pixel) | (256, 256) | {pair(one['true_centre_rc'], 1)} |",
        f"| Generated value, matching (pixel) | (255.5, 256.5) | {pair(one['match_centre_rc'], 3)} |",
        f"| Error, matching (pixel) | (-0.5, 0.5), modulus 0.71 | {pair(one['match_error_rc'], 3)}, modulus {mod(one['match_error_rc']):.3f} |",
        f"| Error, matching + densification (pixel) | - | {pair(one['densified_error_rc'], 3)}, modulus {mod(one['densified_error_rc']):.3f} |",
    ]
    if "refined_error_rc" in one:
        rows.append(f"| Error, + refinement (pixel) | - | {pair(one['refined_error_rc'], 3)}, modulus "
                    f"{mod(one['refined_error_rc']):.3f} ({one['refine_s']:.1f} s) |")
    rows += [
        f"| Error, figure centre FC (pixel) | not given | {pair(one['fc_error_rc'], 3)}, modulus {mod(one['fc_error_rc']):.3f} |",
        f"| Time consumption (ms) | 121 (MATLAB, 3.1 GHz) | {one['locate_ms_median']:.1f} (segmentation + match + transform, 2 cores) |",
        f"| Database construction | 118 min | {one['build_s']:.1f} s |",
    ]

    def ms(k: str) -> str:
        m = s.get(k + "_median_px")
        return f"{m:.3f} / {s[k + '_p90_px']:.3f}" if m is not None else "-"

    stats = ["| error (px), median / p90 | matching | densified | refined | FC | BC |", "|---|---:|---:|---:|---:|---:|",
             f"| Thebe, phase 0, n = {s['n']} | {ms('err_match')} | {ms('err_densified')} | {ms('err_refined')} | {ms('err_fc')} | {ms('err_bc')} |"]
    extra: dict[str, Any] = {}
    if many["source"] == "benchmark":
        b = many["benchmark"]
        for lab, ss in (("Thebe, phase 30", b["accuracy_thebe"].get("phase_30")), ("Thebe, phase 60", b["accuracy_thebe"].get("phase_60")),
                        ("Phobos, phase 0", b.get("accuracy_phobos", {}).get("phase_0"))):
            if ss:
                extra[lab] = ss
                cells = [f"{ss[k + '_median_px']:.3f} / {ss[k + '_p90_px']:.3f}" if k + "_median_px" in ss else "-"
                         for k in ("err_match", "err_densified", "err_refined", "err_fc", "err_bc")]
                stats.append(f"| {lab}, n = {ss['n']} ({ss['n_failed']} failed) | " + " | ".join(cells) + " |")
        q = b["query"]
        stats.append("\nAt phase 30 and 60 deg the segmented figure is the lit part only, not the silhouette the templates "
                     "store (Wu et al. test zero phase only), so matching, like FC and BC, is off by the unlit part.")
        stats.append(f"\nQuery time (1944 x 2592 camera): match + transform {q['query_match_transform_ms_median']:.1f} ms median, "
                     f"segmentation {q['segmentation_ms_median']:.1f} ms median.")

    # ---- bar chart: error modulus, paper vs ours
    labels = ["paper\nmatching", "ours\nmatching", "ours\ndensified"]
    vals = [PAPER["error_modulus_px"], mod(one["match_error_rc"]), mod(one["densified_error_rc"])]
    if "refined_error_rc" in one:
        labels.append("ours\nrefined")
        vals.append(mod(one["refined_error_rc"]))
    labels.append("ours\nFC")
    vals.append(mod(one["fc_error_rc"]))
    med = [None, s.get("err_match_median_px"), s.get("err_densified_median_px")]
    if "refined_error_rc" in one:
        med.append(s.get("err_refined_median_px"))
    med.append(s.get("err_fc_median_px"))
    fig, ax = plt.subplots()
    x = np.arange(len(labels))
    ax.bar(x[:1] - 0.2, vals[:1], 0.4, color="0.5", label="paper, Table 1 image (Amalthea)")
    ax.bar(x[1:] - 0.2, vals[1:], 0.4, color="C0", label="ours, Table 1 setting (Thebe, 512 x 512)")
    ax.bar(x[1:] + 0.2, [np.nan if v is None else v for v in med[1:]], 0.4, color="C1", alpha=0.7,
           label=f"median over {s['n']} views ({'benchmark' if many['source'] == 'benchmark' else 'quick live run'})")
    ax.set_yscale("log")
    ax.set_xticks(x, labels)
    ax.set(ylabel="body-centre image error (px)", title="Wu et al. Table 1 analogue: error modulus")
    ax.legend(fontsize="small")
    paths = [_common.save(fig, out_dir, STEM)]
    body = (
        "Paper: Wu et al. Table 1 (Amalthea, 20160 facets, one simulated 512 x 512 image). Ours: Thebe (5040 faces, "
        f"pole axis y), one 512 x 512 image of the 16 mm / 2.2 um camera, zero phase, {one['step_deg']:g} deg templates of "
        f"{one['template_size_px']} px{'; refinement skipped in quick mode' if quick else ''}.\n\n" + "\n".join(rows)
        + f"\n\nOver many views -- {source_text(many, quick)}\n\n" + "\n".join(stats)
    )
    paths.append(_common.write_caption(out_dir, STEM, "Table 1 (Wu et al.) analogue: LOS determination on one image", body, quick, {
        "paper": PAPER, "ours_single_image": one, "ours_many_views": {"source": many["source"], "source_command": BENCH_CMD,
                                                                     "git_sha_source": many.get("git_sha"), "thebe_phase_0": s, **extra},
    }))
    return paths


if __name__ == "__main__":
    _common.cli(main, STEM)
