"""Benchmark of the model-based line of sight of irregular bodies (Wu et al., issue 5).

Measures, on rendered images with exact truth (``jaxlimb.render.mesh``):

* database build time at the paper's step (3 deg, 6962 views) for Thebe (5040
  faces) and Phobos (49152 faces);
* query time: match + similarity transform (``locate_in_mask``), and the
  segmentation of the image separately;
* accuracy of the body-centre image: template matching (Wu et al. + guards),
  matching + local densification, + soft-silhouette refinement, against the
  figure centre (FC) and brightness centre (BC) baselines; versus the angle to
  the nearest template (the paper's Fig. 9 shape) and versus phase 0/30/60 deg.

Run::

    .venv/bin/python benchmarks/irregular_los.py            # full (~15-30 min on 2 busy cores)
    .venv/bin/python benchmarks/irregular_los.py --quick    # a few minutes

Writes ``benchmarks/results/irregular_los.json`` (or ``--out``).
"""

from __future__ import annotations

from jaxlimb._data import shared_data_dir
import argparse
import json
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

MESHES = shared_data_dir() / "meshes"
RESULTS = Path(__file__).resolve().parent / "results" / "irregular_los.json"


def _git_sha() -> str | None:
    from _common import environment

    return environment()["git_sha"]


def _versions() -> dict[str, str]:
    import cv2
    import jax
    import optimistix
    import trimesh

    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "jax": jax.__version__,
        "optimistix": optimistix.__version__,
        "opencv": cv2.__version__,
        "trimesh": trimesh.__version__,
    }


def _sun(t: np.ndarray, phase_deg: float, rng: np.random.Generator) -> np.ndarray | None:
    if phase_deg == 0:
        return None
    tv = -t / np.linalg.norm(t)
    az = rng.uniform(0, 2 * math.pi)
    ax = np.cross(tv, [math.cos(az), math.sin(az), 0.0])
    ax /= np.linalg.norm(ax)
    ph = math.radians(phase_deg)
    return tv * math.cos(ph) + np.cross(ax, tv) * math.sin(ph)


def _median(x: list[float]) -> float | None:
    x = [v for v in x if v is not None and np.isfinite(v)]
    return float(np.median(x)) if x else None


def run_accuracy(db, mesh, camera, n: int, phase_deg: float, seed: int, refine: bool, pole_axis: str) -> list[dict]:
    from jaxlimb.errors import JaxlimbError
    from jaxlimb.irregular.matching import locate_centre
    from jaxlimb.irregular.refine import densify_match, refine_centre
    from jaxlimb.irregular.views import viewpoint_directions
    from jaxlimb.render.mesh import look_at_rotation, render_mesh

    rng = np.random.default_rng(seed)
    dirs = viewpoint_directions(db.alpha, db.beta, pole_axis)
    rows = []
    for _ in range(n):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        size = rng.uniform(150.0, 500.0)
        D = 2.0 * mesh.max_radius * camera.focal_px / size
        R = look_at_rotation(d, roll_rad=rng.uniform(0, 2 * math.pi))
        off = rng.uniform(-400, 400, size=2)
        t = np.array([off[1] * D / camera.focal_px, off[0] * D / camera.focal_px, D])
        sun = _sun(t, phase_deg, rng)
        out = render_mesh(mesh.vertices, mesh.faces, camera, R, t, sun_dir_camera=sun)
        # angle between the actual viewing direction (body -> camera, body frame) and the nearest template
        view = -R.T @ t / np.linalg.norm(t)
        ang = float(np.degrees(np.arccos(np.clip(dirs @ view, -1, 1)).min()))
        row = {"size_px": size, "angle_to_template_deg": ang, "phase_deg": phase_deg}
        try:
            m = locate_centre(out.image, db, camera)
            row["err_match"] = float(np.linalg.norm(m.centre_rc - out.centre_rc))
            row["err_fc"] = float(np.linalg.norm(m.figure_centre_rc - out.centre_rc))
            row["err_bc"] = float(np.linalg.norm(m.brightness_centre_rc - out.centre_rc))
            dn = densify_match(m.mask, db, camera, m)
            row["err_densified"] = float(np.linalg.norm(dn.centre_rc - out.centre_rc))
            if refine:
                t0 = time.perf_counter()
                r = refine_centre(out.image, db, camera, m, sun_dir_camera=sun)
                row["refine_s"] = time.perf_counter() - t0
                row["err_refined"] = float(np.linalg.norm(r.centre_rc - out.centre_rc))
        except JaxlimbError as e:
            row["error"] = f"{type(e).__name__}: {e}"
        rows.append(row)
        print("  " + "  ".join(f"{k}={v:.3f}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()), flush=True)
    return rows


def time_queries(db, mesh, camera, n: int, seed: int) -> dict:
    from jaxlimb.irregular.matching import MatchOptions, locate_in_mask
    from jaxlimb.irregular.silhouette import segment_body
    from jaxlimb.render.mesh import look_at_rotation, render_mesh

    rng = np.random.default_rng(seed)
    t_seg, t_q = [], []
    cache: dict = {}
    for _ in range(n):
        d = rng.normal(size=3)
        size = rng.uniform(150.0, 500.0)
        D = 2.0 * mesh.max_radius * camera.focal_px / size
        out = render_mesh(mesh.vertices, mesh.faces, camera, look_at_rotation(d, roll_rad=rng.uniform(0, 6.28)), np.array([0, 0, D]))
        t0 = time.perf_counter()
        mask, _ = segment_body(out.image)
        t1 = time.perf_counter()
        for _rep in range(3):
            t2 = time.perf_counter()
            locate_in_mask(mask, db, camera, MatchOptions(), _cache=cache)
            t_q.append(time.perf_counter() - t2)
        t_seg.append(t1 - t0)
    return {
        "n": n,
        "query_match_transform_ms_median": 1e3 * float(np.median(t_q)),
        "query_match_transform_ms_p90": 1e3 * float(np.percentile(t_q, 90)),
        "segmentation_ms_median": 1e3 * float(np.median(t_seg)),
    }


def summarise(rows: list[dict]) -> dict:
    out = {"n": len(rows), "n_failed": sum("error" in r for r in rows)}
    for k in ("err_match", "err_densified", "err_refined", "err_fc", "err_bc"):
        vals = [r[k] for r in rows if k in r]
        if vals:
            out[k + "_median_px"] = _median(vals)
            out[k + "_p90_px"] = float(np.percentile(vals, 90))
    if any("err_match" in r and "err_fc" in r for r in rows):
        out["match_better_than_fc_frac"] = float(np.mean([r["err_match"] < r["err_fc"] for r in rows if "err_match" in r]))
    return out


def by_angle(rows: list[dict]) -> list[dict]:
    edges = [0.0, 0.5, 1.0, 1.5, 2.5]
    table = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = [r for r in rows if lo <= r["angle_to_template_deg"] < hi]
        table.append({"angle_deg": f"[{lo}, {hi})", **summarise(sel)})
    return table


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer images, Phobos build skipped")
    ap.add_argument("--out", default=str(RESULTS))
    ap.add_argument("--no-refine", action="store_true")
    args = ap.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.irregular.database import DatabaseOptions, build_database
    from jaxlimb.irregular.mesh import load_mesh

    camera = Camera.default()
    result: dict = {"git_sha": _git_sha(), "versions": _versions(), "machine": platform.machine(), "quick": args.quick}
    builds = {}
    dbs = {}
    for name, path in (("thebe", MESHES / "thebe.obj"), ("phobos", MESHES / "phobos.obj")):
        if args.quick and name == "phobos":
            continue
        mesh = load_mesh(path)
        opts = DatabaseOptions(step_deg=3.0, pole_axis="y")
        t0 = time.perf_counter()
        db = build_database(mesh, opts, progress=False)
        dt = time.perf_counter() - t0
        builds[name] = {"faces": mesh.n_faces, "step_deg": 3.0, "n_templates": len(db), "build_s": dt}
        dbs[name] = (db, mesh)
        print(f"build {name}: {len(db)} templates in {dt:.1f} s", flush=True)
    result["build"] = builds

    db, mesh = dbs["thebe"]
    result["query"] = time_queries(db, mesh, camera, 5 if args.quick else 20, seed=1)
    print("query:", result["query"], flush=True)

    n0 = 8 if args.quick else 40
    nph = 3 if args.quick else 10
    refine = not args.no_refine
    acc: dict = {}
    rows0 = run_accuracy(db, mesh, camera, n0, 0.0, seed=2, refine=refine, pole_axis="y")
    acc["phase_0"] = summarise(rows0)
    acc["phase_0_by_angle_to_template"] = by_angle(rows0)
    for ph in (30.0, 60.0):
        rows = run_accuracy(db, mesh, camera, nph, ph, seed=3 + int(ph), refine=refine, pole_axis="y")
        acc[f"phase_{int(ph)}"] = summarise(rows)
        acc[f"phase_{int(ph)}_rows"] = rows
    acc["phase_0_rows"] = rows0
    result["accuracy_thebe"] = acc
    if "phobos" in dbs:
        pdb, pmesh = dbs["phobos"]
        prow = run_accuracy(pdb, pmesh, camera, 10, 0.0, seed=5, refine=refine, pole_axis="y")
        result["accuracy_phobos"] = {"phase_0": summarise(prow), "phase_0_rows": prow}

    # table
    print("\nbuild:")
    for k, v in builds.items():
        print(f"  {k:7s} {v['faces']:6d} faces  {v['n_templates']} views  {v['build_s']:7.1f} s")
    q = result["query"]
    print(f"query (match + transform): median {q['query_match_transform_ms_median']:.1f} ms, p90 {q['query_match_transform_ms_p90']:.1f} ms; segmentation {q['segmentation_ms_median']:.1f} ms")
    print("\nThebe accuracy, body-centre error (px), median / p90:")
    print(f"  {'case':12s} {'match':>14s} {'densified':>14s} {'refined':>14s} {'FC':>14s} {'BC':>14s}")

    def cell(s: dict, k: str) -> str:
        m, p = s.get(k + "_median_px"), s.get(k + "_p90_px")
        return f"{m:6.3f}/{p:6.3f}" if m is not None else f"{'-':>13s}"

    for ph in ("phase_0", "phase_30", "phase_60"):
        s = acc[ph]
        print(f"  {ph:12s} " + " ".join(cell(s, k) for k in ("err_match", "err_densified", "err_refined", "err_fc", "err_bc")))
    print("\nphase 0 vs angle to the nearest template:")
    for s in acc["phase_0_by_angle_to_template"]:
        print(f"  {s['angle_deg']:12s} n={s['n']:3d} " + " ".join(cell(s, k) for k in ("err_match", "err_densified", "err_refined", "err_fc")))
    if "accuracy_phobos" in result:
        s = result["accuracy_phobos"]["phase_0"]
        print("\nPhobos phase 0: " + " ".join(cell(s, k) for k in ("err_match", "err_densified", "err_refined", "err_fc", "err_bc")))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    from jaxlimb._io import write_json_atomic

    write_json_atomic(out, json.loads(json.dumps(result, default=float)))
    print(f"\nwrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
