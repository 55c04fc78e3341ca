"""The irregular-body line of sight on frames it does not assume: own vs independent renders.

Every view is rendered twice from the same geometry:

* ``own``: :mod:`jaxlimb.render.mesh` (painter's algorithm, flat facets, Lommel-Seeliger, no cast
  shadows, Gaussian noise), the family ``benchmarks/irregular_los.py`` measures;
* ``independent``: :mod:`jaxlimb.render.independent.mesh_rays` (Embree ray casting, smooth normals,
  cast shadows, a random law of Hapke / Minnaert / Lommel-Seeliger with surge / lunar-Lambert,
  variegated albedo 15-35 %, a random PSF of Gaussian / Airy / defocus / motion, photon + read noise,
  8 or 12 bits, stars and hot pixels in one frame of three).

Bodies: Thebe, Eros, Phobos (``../shared/data``), the three generated families of
:mod:`jaxlimb.irregular.shapes`, and two cratered bodies (:func:`~jaxlimb.render.independent.mesh_rays.cratered_body`)
no part of the pipeline was developed on.  ``cratered-coarse`` renders the cratered body from a
4x finer mesh than the shape model the pipeline is given (the model is coarser than the body).
Camera 1024^2, focal 1500 px, 3x and 10x the long axis, every other view off-centre, random
attitude (off any template grid).  Modes of :func:`jaxlimb.irregular.locate.locate_los`:
``unknown`` (Sun known, attitude unknown; phases 0/30/60) and ``known`` (``R_body_to_camera``
known; phases 0/30/60/90).  Error = distance of ``center_rc`` to the image of the mesh origin.

Run::

    .venv/bin/python benchmarks/irregular_independent.py --views 1 --cache /tmp/irr_ind   # 9 bodies x 7 = 63 views

Writes ``benchmarks/results/irregular_independent.json`` (or ``--out``).
"""

from __future__ import annotations

import argparse
import os
import pickle
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

RESULTS = Path(__file__).resolve().parent / "results" / "irregular_independent.json"
RENDER_VERSION = 4  # 2: own renders cast shadows; 3: own renders with exact facet coverage (render.mesh._exact_edges); 4: independent renders jittered per pixel (mesh_rays._rays)
LAWS = ("hapke", "minnaert", "lommel-seeliger-surge", "lunar-lambert")
PSFS = ("gaussian", "airy", "defocus", "motion")


def bodies(quick: bool) -> dict:
    """name -> (mesh given to the pipeline, (V, F) rendered, pole axis of the database)."""
    from irregular_los import bodies as shared_bodies

    from jaxlimb.irregular.mesh import validate_mesh
    from jaxlimb.render.independent.mesh_rays import cratered_body

    out = {k: (m, (m.vertices, m.faces), pole) for k, (m, pole) in shared_bodies(quick).items()}
    for name, seed in (("cratered-a", 101), ("cratered-coarse", 202)):
        V, F = cratered_body(seed, subdivisions=4)
        model = validate_mesh(V, F, source=name)
        out[f"new:{name}"] = (model, cratered_body(seed, subdivisions=6) if "coarse" in name else (V, F), "z")
    return out


def draw_scene(V, F, max_radius: float, cam, phase_deg: float, dist: float, off: bool, rng):
    from irregular_los import view_geometry

    from jaxlimb.render.independent.mesh_rays import MeshScene
    from jaxlimb.render.independent.optics import Psf, PsfKind
    from jaxlimb.render.independent.sensor import SensorSpec
    from jaxlimb.render.independent.surface import Photometry, Reflectance

    R, t, sun = view_geometry(max_radius, cam, phase_deg, dist, off, rng)
    law, psf_kind = str(rng.choice(LAWS)), str(rng.choice(PSFS))
    bits = 8 if rng.uniform() < 0.4 else 12
    busy = rng.uniform() < 1 / 3
    phot = Photometry(law=Reflectance(law), minnaert_k=float(rng.uniform(0.55, 0.95)), w=float(rng.uniform(0.15, 0.35)),
                      b=float(rng.uniform(0.2, 0.4)), B0=float(rng.uniform(0.5, 1.5)), h=float(rng.uniform(0.03, 0.1)))
    psf = Psf(kind=PsfKind(psf_kind), sigma=float(rng.uniform(0.6, 1.2)) if psf_kind == "gaussian" else float(rng.uniform(0.5, 0.8)),
              r_zero=float(rng.uniform(1.2, 2.0)), r_disc=float(rng.uniform(0.8, 1.8)), length=float(rng.uniform(1.5, 3.5)),
              angle_deg=float(rng.uniform(0, 180)))
    gain = 20000.0 / (2**bits - 1)
    spec = SensorSpec(bits=bits, read_noise_dn=12.0 / gain, background_dn=40.0 / gain, n_stars=30 if busy else 0,
                      star_flux_dn=(20.0 * (2**bits - 1) / 255, 400.0 * (2**bits - 1) / 255), n_hot=20 if busy else 0)
    meta = {"law": law, "psf": psf_kind, "bits": bits, "stars_hot": bool(busy)}
    scene = MeshScene(V, F, R, t, sun, phot, float(rng.uniform(0.15, 0.35)), int(rng.integers(1 << 30)), psf, spec)
    return scene, meta


def render_frames(name, model, VF, cam, pin, phase, dist, off, rng, cache: Path | None, key: str):
    """(independent image, own image, truth, R, t, sun, meta), from ``cache`` when there."""
    f = None if cache is None else cache / f"{key}_v{RENDER_VERSION}.pkl"
    if f is not None and f.exists():
        return pickle.loads(f.read_bytes())
    from jaxlimb.render.independent.mesh_rays import render_mesh_frame
    from jaxlimb.render.mesh import MeshRenderOptions, render_mesh

    scene, meta = draw_scene(VF[0], VF[1], model.max_radius, cam, phase, dist, off, rng)
    img, truth = render_mesh_frame(scene, pin, rng)
    own = render_mesh(model.vertices, model.faces, cam, scene.R_body_to_camera, scene.t_camera_km,
                      sun_dir_camera=scene.sun_dir_camera,
                      options=MeshRenderOptions(noise_sigma=2.0, seed=int(rng.integers(1 << 30)), albedo=200.0, background=10.0))
    out = (img, own.image, truth, scene.R_body_to_camera, scene.t_camera_km, scene.sun_dir_camera, meta)
    if f is not None:
        cache.mkdir(parents=True, exist_ok=True)
        f.write_bytes(pickle.dumps(out))
    return out


def view_plan(args):
    """(mode, phase, distance factor, off-centre) for each view of one body."""
    for mode, phases in (("unknown", (0, 30, 60)), ("known", (0, 30, 60, 90))):
        for ph in phases:
            for k in range(args.views):
                yield mode, ph, (3.0, 10.0)[(k + ph // 30) % 2], bool((k + ph // 30 + (mode == "known")) % 2)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--views", type=int, default=1, help="views per body, mode and phase")
    ap.add_argument("--quick", action="store_true", help="Phobos skipped")
    ap.add_argument("--bodies", nargs="*", help="only these bodies (names as printed)")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--cache", type=Path, default=None, help="keep rendered frames here between runs")
    ap.add_argument("--out", default=str(RESULTS))
    args = ap.parse_args(argv)
    os.environ.setdefault("JAXLIMB_CACHE", str(Path(__file__).resolve().parent / "results" / ".db-cache"))
    from irregular_los import rows_by, camera, run_case, table

    from jaxlimb.irregular.database import DatabaseOptions, cached_database
    from jaxlimb.render.independent.geometry import Pinhole

    cam = camera()
    pin = Pinhole.from_camera(cam)
    rows: list[dict] = []
    t_start = time.perf_counter()
    for ib, (name, (model, VF, pole)) in enumerate(bodies(args.quick).items()):
        if args.bodies and name not in args.bodies:
            continue
        rng = np.random.default_rng([args.seed, ib])
        db = cached_database(model, DatabaseOptions(step_deg=3.0, pole_axis=pole), progress=False)
        for iv, (mode, ph, dist, off) in enumerate(view_plan(args)):
            key = f"{name.replace(':', '_')}_{iv}_s{args.seed}"
            img, own, truth, R, t, sun, meta = render_frames(name, model, VF, cam, pin, ph, dist, off, rng, args.cache, key)
            base = {"body": name, "mode": mode, "phase": ph, "distance_x_long_axis": dist, "off_center": off, **meta}
            for fam, im in (("independent", img), ("own", own)):
                row = {**base, "family": fam, **run_case(db, cam, im, truth, R, t, sun, mode)}
                rows.append(row)
                print("  ", {k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()}, flush=True)
    report = []
    for fam in ("own", "independent"):
        for mode in ("unknown", "known"):
            sel = [r for r in rows if r["mode"] == mode and r["family"] == fam]
            title = f"{fam} renders, " + ("attitude unknown, Sun known" if mode == "unknown" else "attitude known")
            report.append(table(f"{title}: by phase", rows_by(sel, "phase")))
            if fam == "independent":
                report.append(table(f"{title}: by body", rows_by(sel, "body")))
                report.append(table(f"{title}: by law", rows_by(sel, "law")))
                report.append(table(f"{title}: by PSF", rows_by(sel, "psf")))
    text = "\n".join(report)
    print(text)
    from _common import environment

    from jaxlimb._io import write_json_atomic

    write_json_atomic(Path(args.out), {"environment": environment(), "args": {k: str(v) for k, v in vars(args).items()},
                                       "wall_s": time.perf_counter() - t_start, "rows": rows, "report": text})
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
