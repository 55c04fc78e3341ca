"""Which part of a ray-traced scene moves the attitude-known centre: one factor changed at a time.

The scenes are those of ``benchmarks/irregular_independent.py`` (same seed): its random draws are replayed
(every view rendered again in order, since the sensor's Poisson draws consume the generator by the image's
content) and each frame is checked against ``--cache`` when given.  Each attitude-known scene is then
rendered again (ray jitter and noise seed 7) with one factor changed, and registered
(:func:`jaxlimb.irregular.locate.locate_los` with ``R_body_to_camera``):

``full`` (unchanged), ``noise2`` (seed 8: another noise and jitter draw), ``no_albedo`` (uniform albedo),
``gauss_psf`` (a Gaussian PSF of 0.8 px), ``no_shadows`` (no cast shadows), ``ls_law`` (Lommel-Seeliger, no
surge), ``flat_normals`` (facet normals), ``all_off`` (uniform albedo, Gaussian PSF, no shadows, LS).

Run::

    .venv/bin/python benchmarks/irregular_known_ablation.py --cache /tmp/irr_cache3 --out /tmp/ablation.json

(32 scenes x 8 variants, about 15 min on 2 cores.)
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def variants() -> dict:
    from jaxlimb.render.independent.optics import Psf, PsfKind
    from jaxlimb.render.independent.surface import Photometry, Reflectance

    gauss, ls = Psf(kind=PsfKind.GAUSSIAN, sigma=0.8), Photometry(law=Reflectance.LOMMEL_SEELIGER_SURGE, B0=0.0)
    return {
        "full": lambda s: s, "noise2": lambda s: s, "no_albedo": lambda s: replace(s, albedo_depth=0.0),
        "gauss_psf": lambda s: replace(s, psf=gauss), "no_shadows": lambda s: replace(s, shadows=False),
        "ls_law": lambda s: replace(s, photometry=ls), "flat_normals": lambda s: replace(s, smooth_normals=False),
        "all_off": lambda s: replace(s, albedo_depth=0.0, psf=gauss, shadows=False, photometry=ls),
    }


def known_scenes(cam, pin, seed: int, cache: Path | None, only) -> dict:
    """``(body, phase) -> (model, MeshScene)`` of the attitude-known views (module docstring)."""
    from irregular_independent import draw_scene, view_plan, bodies

    from jaxlimb.render.independent.mesh_rays import render_mesh_frame

    out = {}
    for ib, (name, (model, VF, _)) in enumerate(bodies(False).items()):
        if only and name not in only:
            continue
        rng = np.random.default_rng([seed, ib])
        for iv, (mode, ph, dist, off) in enumerate(view_plan(argparse.Namespace(views=1))):
            scene, _meta = draw_scene(VF[0], VF[1], model.max_radius, cam, ph, dist, off, rng)
            img, _truth = render_mesh_frame(scene, pin, rng)
            rng.integers(1 << 30)  # the own render's seed
            f = None if cache is None else cache / f"{name.replace(':', '_')}_{iv}_s{seed}_v3.pkl"
            if f is not None and f.exists() and not np.array_equal(pickle.loads(f.read_bytes())[0], img):
                raise RuntimeError(f"replay of {name} view {iv} differs from {f}")
            if mode == "known":
                out[(name, ph)] = (model, scene)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bodies", nargs="*")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--cache", type=Path, default=None, help="frames of irregular_independent.py to check the replay against")
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    os.environ.setdefault("JAXLIMB_CACHE", str(Path(__file__).resolve().parent / "results" / ".db-cache"))
    from irregular_los import camera

    from jaxlimb.errors import JaxlimbError
    from jaxlimb.irregular.register import register_known_attitude
    from jaxlimb.render.independent.geometry import Pinhole
    from jaxlimb.render.independent.mesh_rays import render_mesh_frame

    cam = camera()
    pin = Pinhole.from_camera(cam)
    rows = []
    for (name, ph), (model, scene) in known_scenes(cam, pin, args.seed, args.cache, args.bodies).items():
        for v, change in variants().items():
            img, truth = render_mesh_frame(change(scene), pin, np.random.default_rng(8 if v == "noise2" else 7))
            row = {"body": name, "phase": ph, "law": scene.photometry.law.value, "psf": scene.psf.kind.value, "variant": v}
            try:  # as locate_los in the attitude-known mode
                fit = register_known_attitude(img.astype(float), model, cam, scene.R_body_to_camera, scene.sun_dir_camera,
                                              float(np.linalg.norm(scene.t_camera_km)) * 1.05)
                row["err_px"] = float(np.linalg.norm(fit.center_rc - truth))
            except JaxlimbError as e:
                row["failure"] = f"{e.check}: {e}"[:200]
            rows.append(row)
            print(row, flush=True)
    table = {v: {str(ph): float(np.median([r["err_px"] for r in rows if r["variant"] == v and r["phase"] == ph and "err_px" in r] or [np.nan]))
                 for ph in (0, 30, 60, 90)} for v in variants()}
    print(json.dumps(table, indent=1))
    Path(args.out).write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()}, "median_by_phase": table, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
