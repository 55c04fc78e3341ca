"""Every answer of the irregular-body line of sight on a fixed set of frames, for comparing two checkouts.

The frames are those of ``benchmarks/irregular_los.py`` (own renders) and, with ``--independent``,
of ``benchmarks/irregular_independent.py`` (ray-traced), ``--views`` per body, mode and phase, for
the bodies of ``--bodies``.  Each frame is located by :func:`jaxlimb.irregular.locate.locate_los`
(attitude unknown at 0/30/60 deg, known at 0/30/60/90 deg); the attitude-unknown own frames also by
the template match of Wu et al. and its soft-silhouette refinement (``--refine``).  Every number is
written (centre, covariance, line of sight, range, attitude, quality, or the typed failure); ``--compare``
prints the largest difference of each between two such files.

Run::

    .venv/bin/python benchmarks/irregular_answers.py --independent /tmp/irr_frames --refine --out /tmp/a.json
    .venv/bin/python benchmarks/irregular_answers.py --compare /tmp/a.json /tmp/b.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def _los_answer(db, cam, img, R, t, sun, mode: str) -> dict:
    """Every number of :func:`locate_los` (or the typed failure)."""
    from jaxlimb.errors import JaxlimbError
    from jaxlimb.irregular.locate import locate_los

    t0 = time.perf_counter()
    try:
        res = locate_los(img, db, cam, sun, R if mode == "known" else None, float(np.linalg.norm(t)) * 1.05)
    except JaxlimbError as e:
        return {"failure": f"{e.check}: {e}", "seconds": time.perf_counter() - t0}
    f = res.fit
    return {
        "center_rc": f.center_rc.tolist(), "covariance_rc": f.covariance_rc.tolist(), "los_camera": f.los_camera.tolist(),
        "range_km": f.range_km, "R_body_to_camera": f.R_body_to_camera.tolist(), "excess_frac": f.excess_frac, "iou": f.iou,
        "ncc": f.ncc, "iterations": f.iterations, "template_index": res.template_index, "n_tried": res.n_tried,
        "n_accepted": res.n_accepted, "runner_up_excess": res.runner_up_excess, "seconds": time.perf_counter() - t0,
    }  # fmt: skip


def _refine_answer(db, cam, img, sun) -> dict:
    """The template match of Wu et al. and the soft-silhouette refinement."""
    from jaxlimb.errors import JaxlimbError
    from jaxlimb.irregular.matching import locate_center
    from jaxlimb.irregular.refine import refine_center

    try:
        m = locate_center(img, db, cam)
        out = {"match_rc": m.center_rc.tolist(), "match_template": m.template_index}
        r = refine_center(img, db, cam, m, sun_dir_camera=sun)
        return {**out, "refined_rc": r.center_rc.tolist(), "refined_R": r.R_body_to_camera.tolist(), "refined_t": r.t_camera.tolist()}
    except JaxlimbError as e:
        return {"failure": f"{e.check}: {e}"}


def own_rows(args, cam) -> list[dict]:
    from irregular_los import bodies, make_view

    from jaxlimb.irregular.database import DatabaseOptions, cached_database

    rows = []
    for ib, (name, (mesh, pole)) in enumerate(bodies(False).items()):
        if name not in args.bodies:
            continue
        rng = np.random.default_rng([args.seed, ib])  # as irregular_los.py: per body
        db = cached_database(mesh, DatabaseOptions(step_deg=3.0, pole_axis=pole), progress=False)
        for mode, phases in (("unknown", (0, 30, 60)), ("known", (0, 30, 60, 90))):
            for ph in phases:
                for k in range(args.views):
                    df, off = (3.0, 10.0)[k % 2], bool((k + ph // 30) % 2)
                    img, _truth, R, t, sun = make_view(mesh, cam, ph, df, off, 2.0, rng)
                    row = {"key": f"own/{name}/{mode}/{ph}/{k}", **_los_answer(db, cam, img, R, t, sun, mode)}
                    if args.refine and mode == "unknown":
                        row["refine"] = _refine_answer(db, cam, img, sun)
                    rows.append(row)
                    print(row["key"], row.get("center_rc", row.get("failure")), flush=True)
    return rows


def independent_rows(args, cam) -> list[dict]:
    from irregular_independent import render_frames, view_plan, bodies

    from jaxlimb.irregular.database import DatabaseOptions, cached_database
    from jaxlimb.render.independent.geometry import Pinhole

    pin = Pinhole.from_camera(cam)
    rows = []
    for ib, (name, (model, VF, pole)) in enumerate(bodies(False).items()):
        if name not in args.bodies:
            continue
        rng = np.random.default_rng([args.seed, ib])
        db = cached_database(model, DatabaseOptions(step_deg=3.0, pole_axis=pole), progress=False)
        for iv, (mode, ph, dist, off) in enumerate(view_plan(argparse.Namespace(views=args.views))):
            key = f"{name.replace(':', '_')}_{iv}_s{args.seed}"
            img, own, _truth, R, t, sun, _meta = render_frames(name, model, VF, cam, pin, ph, dist, off, rng, args.independent, key)
            row = {"key": f"independent/{name}/{mode}/{ph}/{iv}", **_los_answer(db, cam, img, R, t, sun, mode)}
            rows.append(row)
            print(row["key"], row.get("center_rc", row.get("failure")), flush=True)
    return rows


def _flat(v) -> np.ndarray | None:  # type: ignore[no-untyped-def]
    return None if v is None or isinstance(v, str) else np.asarray(v, dtype=float).ravel()


def compare(a_path: str, b_path: str, tol: float) -> int:
    """Largest absolute difference of every numeric answer between two files; 1 if any exceeds ``tol``."""
    a = {r["key"]: r for r in json.loads(Path(a_path).read_text())["rows"]}
    b = {r["key"]: r for r in json.loads(Path(b_path).read_text())["rows"]}
    worst: dict[str, tuple[float, str]] = {}
    bad = 0
    for key in sorted(set(a) | set(b)):
        if key not in a or key not in b:
            print(f"{key}: only in {'the first' if key in a else 'the second'}")
            bad += 1
            continue
        ra, rb = dict(a[key]), dict(b[key])
        ra.update({f"refine.{k}": v for k, v in ra.pop("refine", {}).items()})
        rb.update({f"refine.{k}": v for k, v in rb.pop("refine", {}).items()})
        for q in sorted((set(ra) | set(rb)) - {"key", "seconds"}):
            va, vb = ra.get(q), rb.get(q)
            if isinstance(va, str) or isinstance(vb, str) or va is None or vb is None:
                if va != vb:
                    print(f"{key} {q}: {va!r} != {vb!r}")
                    bad += 1
                continue
            d = float(np.max(np.abs(_flat(va) - _flat(vb))))  # type: ignore[operator]
            if d > worst.get(q, (-1.0, ""))[0]:
                worst[q] = (d, key)
            bad += d > tol
    for q, (d, key) in sorted(worst.items()):
        print(f"{q:22s} max |diff| {d:.3g}  ({key})")
    print(f"{len(a)} / {len(b)} frames; {bad} differences above {tol:g}")
    return int(bad > 0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bodies", nargs="*", default=["thebe", "phobos", "eros"])
    ap.add_argument("--views", type=int, default=1, help="views per body, mode and phase")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--refine", action="store_true", help="also the template match and soft-silhouette refinement")
    ap.add_argument("--independent", type=Path, metavar="DIR", help="also the ray-traced frames (kept in DIR)")
    ap.add_argument("--out", default="irregular_answers.json")
    ap.add_argument("--compare", nargs=2, metavar="JSON", help="compare two earlier outputs instead")
    ap.add_argument("--tol", type=float, default=1e-9)
    args = ap.parse_args(argv)
    if args.compare:
        return compare(*args.compare, args.tol)
    os.environ.setdefault("JAXLIMB_CACHE", str(Path(__file__).resolve().parent / "results" / ".db-cache"))
    from irregular_los import camera

    from jaxlimb._io import write_json_atomic

    cam = camera()
    t0 = time.perf_counter()
    rows = own_rows(args, cam) + (independent_rows(args, cam) if args.independent else [])
    write_json_atomic(Path(args.out), {"args": {k: str(v) for k, v in vars(args).items()}, "wall_s": time.perf_counter() - t0, "rows": rows})
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
