"""Benchmark of the checked model-based line of sight of irregular bodies.

Independent renders (``jaxlimb.render.mesh``, Lommel-Seeliger, Gaussian noise
``--noise`` DN) of the shared meshes (Thebe, Eros; Phobos unless ``--quick``) and of
generated bodies no database was built from before (``jaxlimb.irregular.shapes``:
Gaussian random sphere, contact binary, elongated body), random attitudes (uniform
on SO(3), so off any template grid), phases 0/30/60 deg (Sun azimuth random), a
1024^2 camera (focal 1500 px) at 3x and 10x the body's long axis (bounding-sphere
diameter), every other frame off-centre.  Error = distance of ``center_rc`` to the
projection of the mesh origin (docs/design.md).

Two modes of :func:`jaxlimb.irregular.locate.locate_los`:

* ``unknown``: Sun direction known, attitude unknown (template search + registration);
* ``known``: ``R_body_to_camera`` known (render-and-register), phases up to 90 deg.

``--baseline`` also runs the previous pipeline (template match + soft-silhouette
refinement, ``--no-refine`` off) on the same frames, reported as "before".

Run::

    .venv/bin/python benchmarks/irregular_los.py --quick      # ~1 min on 2 busy cores
    .venv/bin/python benchmarks/irregular_los.py --views 2    # 84 frames, ~5 min at load 5-7

Writes ``benchmarks/results/irregular_los.json`` (or ``--out``).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results" / "irregular_los.json"


def bodies(quick: bool) -> dict:
    """name -> (mesh, pole axis of the view sphere)."""
    from jaxlimb._data import shared_data_dir
    from jaxlimb.irregular.mesh import load_mesh
    from jaxlimb.irregular.shapes import generate_shape

    m = shared_data_dir() / "meshes"
    out = {"thebe": (load_mesh(m / "thebe.obj"), "y"), "eros": (load_mesh(m / "eros007790.tab"), "z")}
    if not quick:
        out["phobos"] = (load_mesh(m / "phobos.obj"), "y")
    for fam, seed in (("gaussian-sphere", 11), ("contact-binary", 12), ("elongated", 13)):
        out[f"gen:{fam}"] = (generate_shape(fam, seed), "z")
    return out


def camera():
    from jaxlimb.geometry.camera import Camera

    return Camera(focal_length_mm=30.0, pixel_pitch_mm=0.02, rows=1024, cols=1024)


def view_geometry(max_radius: float, cam, phase_deg: float, dist_factor: float, off_center: bool, rng):
    """A random view: attitude ``R``, body centre ``t`` (camera frame, km) and Sun direction."""
    from scipy.spatial.transform import Rotation

    D = dist_factor * 2.0 * max_radius
    R = Rotation.random(random_state=int(rng.integers(1 << 31))).as_matrix()
    u = np.array([0.0, 0.0, 1.0])
    if off_center:
        rad_px = cam.focal_px * max_radius / (D - max_radius)
        lim = max(cam.rows / 2 - rad_px - 20, 0.0)
        off = rng.uniform(-lim, lim, 2)
        u = np.array([off[1] / cam.focal_px, off[0] / cam.focal_px, 1.0])
        u /= np.linalg.norm(u)
    t = D * u
    tv = -u
    a = rng.normal(size=3)
    a -= (a @ tv) * tv
    a /= np.linalg.norm(a)
    ph = math.radians(phase_deg)
    return R, t, tv * math.cos(ph) + a * math.sin(ph)


def make_view(mesh, cam, phase_deg: float, dist_factor: float, off_center: bool, noise: float, rng):
    """A random view (:func:`view_geometry`): image, truth centre, attitude, Sun direction (camera frame)."""
    from jaxlimb.render.mesh import MeshRenderOptions, render_mesh

    R, t, sun = view_geometry(mesh.max_radius, cam, phase_deg, dist_factor, off_center, rng)
    opts = MeshRenderOptions(noise_sigma=noise, seed=int(rng.integers(1 << 30)), albedo=200.0, background=10.0)
    out = render_mesh(mesh.vertices, mesh.faces, cam, R, t, sun_dir_camera=sun, options=opts)
    return out.image, out.center_rc, R, t, sun


def run_case(db, cam, img, truth, R, t, sun, mode: str) -> dict:
    from jaxlimb.errors import JaxlimbError
    from jaxlimb.irregular.locate import locate_los

    t0 = time.perf_counter()
    row: dict = {}
    try:
        res = locate_los(img, db, cam, sun, R if mode == "known" else None, float(np.linalg.norm(t)) * 1.05)
        e = res.center_rc - truth
        row["err_px"] = float(np.linalg.norm(e))
        row["sd_px"] = float(math.sqrt(np.trace(res.fit.covariance_rc)))
        row["nees"] = float(e @ np.linalg.solve(res.fit.covariance_rc, e))
        row["excess"] = res.fit.excess_frac
    except JaxlimbError as e:
        row["failure"] = f"{e.check}: {e}"[:200]
    row["seconds"] = time.perf_counter() - t0
    return row


def run_baseline(db, cam, img, truth, sun) -> dict:
    """The previous pipeline: template match (Wu et al.) + soft-silhouette refinement, unchecked."""
    from jaxlimb.errors import JaxlimbError
    from jaxlimb.irregular.matching import locate_center
    from jaxlimb.irregular.refine import refine_center

    t0 = time.perf_counter()
    try:
        m = locate_center(img, db, cam)
        r = refine_center(img, db, cam, m, sun_dir_camera=sun)
        return {"err_px": float(np.linalg.norm(r.center_rc - truth)), "seconds": time.perf_counter() - t0}
    except JaxlimbError as e:
        return {"failure": f"{e.check}: {e}"[:200], "seconds": time.perf_counter() - t0}


def summarise(rows: list[dict]) -> dict:
    errs = np.array([r["err_px"] for r in rows if "err_px" in r])
    n = len(rows)
    out = {"n": n, "failures": n - errs.size}
    if errs.size:
        out.update(
            median_px=float(np.median(errs)),
            p90_px=float(np.percentile(errs, 90)),
            max_px=float(errs.max()),
            ok_above_3px=int((errs > 3.0).sum()),
            nees_mean=float(np.mean([r["nees"] for r in rows if "nees" in r])) if any("nees" in r for r in rows) else float("nan"),
            median_seconds=float(np.median([r["seconds"] for r in rows])),
        )
    return out


def table(title: str, groups: dict[str, list[dict]]) -> str:
    lines = [f"\n{title}", "| group | n | typed failures | median / p90 / max px | ok with error > 3 px | mean NEES (2) | median s |",
             "|---|---|---|---|---|---|---|"]
    for g, rows in groups.items():
        s = summarise(rows)
        if "median_px" in s:
            cell = f"{s['median_px']:.3f} / {s['p90_px']:.3f} / {s['max_px']:.3f}"
            lines.append(f"| {g} | {s['n']} | {s['failures']} | {cell} | {s['ok_above_3px']} | {s['nees_mean']:.1f} | {s['median_seconds']:.1f} |")
        else:
            lines.append(f"| {g} | {s['n']} | {s['failures']} | - | 0 | - | - |")
    return "\n".join(lines)


def rows_by(rows: list[dict], key: str) -> dict[str, list[dict]]:
    g: dict[str, list[dict]] = {}
    for r in rows:
        g.setdefault(f"{key} {r[key]}", []).append(r)
    g["all"] = rows
    return g


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one view per body, phase and mode; Phobos skipped")
    ap.add_argument("--views", type=int, default=2, help="views per body, phase and distance (full run)")
    ap.add_argument("--noise", type=float, default=2.0, help="noise sigma (DN) on a 200 DN body")
    ap.add_argument("--baseline", action="store_true", help="also run the previous pipeline on the same frames")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--bodies", nargs="*", help="only these bodies (names as printed)")
    ap.add_argument("--merge", nargs="*", metavar="JSON", help="only combine the rows of earlier runs and print the tables")
    ap.add_argument("--out", default=str(RESULTS))
    args = ap.parse_args(argv)
    os.environ.setdefault("JAXLIMB_CACHE", str(Path(__file__).resolve().parent / "results" / ".db-cache"))

    from jaxlimb.irregular.database import DatabaseOptions, cached_database

    cam = camera()
    rows: list[dict] = []
    if args.merge:
        import json

        for f in args.merge:
            rows += json.loads(Path(f).read_text())["rows"]
    for ib, (name, (mesh, pole)) in enumerate(bodies(args.quick).items()):
        if args.merge is not None or (args.bodies and name not in args.bodies):
            continue
        rng = np.random.default_rng([args.seed, ib])  # per body: a subset run reproduces its views
        t0 = time.perf_counter()
        db = cached_database(mesh, DatabaseOptions(step_deg=3.0, pole_axis=pole), progress=False)
        print(f"{name}: database {len(db)} templates ({time.perf_counter() - t0:.1f} s)", flush=True)
        for mode, phases in (("unknown", (0, 30, 60)), ("known", (0, 30, 60, 90))):
            for ph in phases:
                dists = (3.0, 10.0)
                for k in range(1 if args.quick else args.views):
                    df = dists[(k + ph // 30) % 2] if args.quick else dists[k % 2]
                    off = bool((k + ph // 30) % 2)
                    img, truth, R, t, sun = make_view(mesh, cam, ph, df, off, args.noise, rng)
                    row = {"body": name, "mode": mode, "phase": ph, "distance_x_long_axis": df, "off_center": off}
                    row.update(run_case(db, cam, img, truth, R, t, sun, mode))
                    if args.baseline and mode == "unknown":
                        row["before"] = run_baseline(db, cam, img, truth, sun)
                    rows.append(row)
                    print("  ", {k2: (round(v, 4) if isinstance(v, float) else v) for k2, v in row.items()}, flush=True)
    report = []
    for mode in ("unknown", "known"):
        sel = [r for r in rows if r["mode"] == mode]
        title = "Attitude unknown, Sun known" if mode == "unknown" else "Attitude known (render-and-register)"
        report.append(table(f"{title}: by phase", rows_by(sel, "phase")))
        report.append(table(f"{title}: by body", rows_by(sel, "body")))
    before = [{**r["before"], "phase": r["phase"], "body": r["body"]} for r in rows if "before" in r]
    if before:
        after = [r for r in rows if "before" in r]
        report.append(table("After, on the same frames as the baseline: by phase", rows_by(after, "phase")))
        report.append(table("Before (template match + soft-silhouette refinement, unchecked): by phase", rows_by(before, "phase")))
    text = "\n".join(report)
    print(text)
    from _common import environment

    from jaxlimb._io import write_json_atomic

    env = environment()
    write_json_atomic(Path(args.out), {"environment": env, "args": vars(args), "rows": rows, "report": text})
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    sys.exit(main())
