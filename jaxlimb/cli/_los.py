"""``jaxlimb los``: model-based line of sight of an irregular body (Wu et al.).

Sub-commands::

    jaxlimb los build-db MESH --step-deg 3 --out DB.npz [--pole-axis z] [--template-size 512] [--json]
    jaxlimb los locate IMAGE (--db DB.npz | --mesh MESH) --camera CAMERA.json [--hints HINTS.json]
                       [--no-refine] [--step-deg 3] [--pole-axis z] [--json]

``locate --mesh`` builds the template database once and caches it by mesh hash
and settings in ``$JAXLIMB_CACHE`` (default ``~/.cache/jaxlimb``).

Output of ``locate --json``::

    {"status": "ok", "center_rc": [r, c], "los_camera": [x, y, z],
     "template": {"index", "alpha_deg", "beta_deg", "rotation_deg", "scale"},
     "match_distance": SE, "match_center_rc": [r, c], "refined": bool,
     "figure_center_rc": [r, c], "brightness_center_rc": [r, c], ...}

Errors follow the contract of :mod:`jaxlimb.cli` (exit 2 unusable input, 3 failed check).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from typing import Any

import numpy as np

from .._validate import Range, arg_number, input_file, output_file
from ..errors import ConfigError, DatabaseError, ImageContentError, MeshError

#: ``--step-deg``: below 0.5 deg a database has > 250 000 views (> 10 min to build); above 60 no ring is left.
STEP_DEG_RANGE = Range(0.5, 60.0)
TEMPLATE_SIZE_RANGE = Range(32, 4096)


def register(subparsers: Any) -> None:
    p = subparsers.add_parser("los", help="model-based line of sight of an irregular body (Wu et al.)")
    sub = p.add_subparsers(dest="los_command", metavar="SUBCOMMAND", parser_class=type(p))
    sub.required = True

    b = sub.add_parser("build-db", help="build a template database from a shape model")
    b.add_argument("mesh", metavar="MESH", help="shape model (.obj, .stl, .ply or a v/f .tab plate table)")
    b.add_argument("--out", required=True, metavar="DB", help="output database file (.npz)")
    _add_db_options(b)
    b.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    b.set_defaults(func=run_build)

    q = sub.add_parser("locate", help="locate the image of the body centre and the line of sight")
    q.add_argument("image", metavar="IMAGE", help="grey image (PNG/TIFF/FITS)")
    src = q.add_mutually_exclusive_group(required=True)
    src.add_argument("--db", metavar="DB", help="template database built by `los build-db`")
    src.add_argument("--mesh", metavar="MESH", help="shape model; the database is built once and cached")
    q.add_argument("--camera", required=True, metavar="CAMERA", help="camera JSON file")
    q.add_argument("--hints", metavar="HINTS", help="hints JSON (uses `sun_dir_camera`)")
    q.add_argument("--no-refine", action="store_true", help="skip the soft-silhouette refinement")
    _add_db_options(q)
    q.add_argument("--json", action="store_true", help="print the result as one JSON object")
    q.set_defaults(func=run_locate)


def _add_db_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--step-deg", type=arg_number(STEP_DEG_RANGE), default=3.0,
                   help=f"view-sphere sampling step, deg {STEP_DEG_RANGE} (default 3)")
    p.add_argument("--pole-axis", choices=("x", "y", "z"), default="z", help="mesh axis used as the sampling pole")
    p.add_argument("--template-size", type=arg_number(TEMPLATE_SIZE_RANGE, integer=True), default=512,
                   help=f"template image side, px, integer {TEMPLATE_SIZE_RANGE} (default 512)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _db_options(args: argparse.Namespace) -> Any:
    from ..irregular.database import DatabaseOptions

    return DatabaseOptions(step_deg=args.step_deg, pole_axis=args.pole_axis, template_size_px=args.template_size)


def run_build(args: argparse.Namespace) -> int:
    from .._io import exclusive_output
    from ..irregular.database import build_database, save_database
    from ..irregular.mesh import load_mesh

    opts = _db_options(args)
    input_file(args.mesh, "MESH", error=MeshError)
    target = output_file(args.out, "--out", suffixes=(".npz",), error=ConfigError)  # before any work
    mesh = load_mesh(args.mesh)
    with exclusive_output(target):  # a second build of the same --out is refused; stale temporaries removed
        t0 = time.perf_counter()
        db = build_database(mesh, opts, progress=not args.no_progress)
        dt = time.perf_counter() - t0
        out = save_database(db, target)
    summary = {
        "status": "ok",
        "database": str(out),
        "n_templates": len(db),
        "mesh_hash": db.mesh_hash,
        "mesh_repairs": list(mesh.repairs),
        "settings": json.loads(opts.to_json()),
        "build_seconds": round(dt, 3),
    }
    if args.json:
        from . import emit_json

        emit_json(summary)
    else:
        print(f"wrote {out} ({len(db)} templates, {dt:.1f} s)")
    return 0


def _read_image(path: str) -> np.ndarray:
    """The frame as float64; an all-black (constant) frame is a frame without a body (exit 3, as `locate`)."""
    from ..errors import NoBodyError
    from ..imaging.io import load_image

    img, _ = load_image(path, reject_constant=False)
    if float(img.max()) == float(img.min()):
        raise NoBodyError(f"image {path!r} is constant (every pixel = {float(img.min()):g}): no body")
    return img


def _sun_dir(path: str | None) -> np.ndarray | None:
    """``sun_dir_camera`` of the hints file (validated by :class:`~jaxlimb.imaging.Hints`), or None."""
    from ..imaging import Hints

    if path is None:
        return None
    s = Hints.from_json(path).sun_dir_camera
    return None if s is None else np.asarray(s, dtype=float)


def run_locate(args: argparse.Namespace) -> int:
    from ..geometry.camera import Camera
    from ..irregular.database import cached_database, load_database
    from ..irregular.matching import MatchOptions, locate_centre
    from ..irregular.mesh import load_mesh

    # every input is checked before the (possibly long) database load/build
    if args.db is not None:
        input_file(args.db, "--db", error=DatabaseError)
    else:
        input_file(args.mesh, "--mesh", error=MeshError)
    camera = Camera.from_json(args.camera)
    sun = _sun_dir(args.hints)
    image = _read_image(args.image)
    if image.shape != camera.shape:
        raise ImageContentError(f"image {args.image!r} has shape {image.shape}, the camera expects {camera.shape}")
    if args.db is not None:
        db = load_database(args.db)
    else:
        mesh = load_mesh(args.mesh)
        db = cached_database(mesh, _db_options(args), progress=not args.no_progress)
    t0 = time.perf_counter()
    res = locate_centre(image, db, camera, MatchOptions())
    t_match = time.perf_counter() - t0
    centre = res.centre_rc
    refined = False
    extra: dict[str, Any] = {}
    if not args.no_refine:
        from ..irregular.refine import refine_centre

        t1 = time.perf_counter()
        ref = refine_centre(image, db, camera, res, sun_dir_camera=sun)
        extra["refine_seconds"] = round(time.perf_counter() - t1, 4)
        extra["refine"] = {"iterations": ref.iterations, "rms_residual": ref.rms_residual, "k": ref.k}
        centre = ref.centre_rc
        refined = True
    los = camera.los(centre)
    j = res.template_index
    out = {
        "status": "ok",
        "center_rc": [float(centre[0]), float(centre[1])],
        "los_camera": [float(v) for v in los],
        "template": {
            "index": int(j),
            "alpha_deg": math.degrees(float(db.alpha[j])),
            "beta_deg": math.degrees(float(db.beta[j])),
            "rotation_deg": math.degrees(res.theta),
            "scale": res.scale,
        },
        "match_distance": res.match_distance,
        "match_center_rc": [float(v) for v in res.centre_rc],
        "refined": refined,
        "figure_center_rc": [float(v) for v in res.figure_centre_rc],
        "brightness_center_rc": [float(v) for v in res.brightness_centre_rc],
        "contour_mean_px": res.contour_mean_px,
        "match_seconds": round(t_match, 4),
        "mesh_hash": db.mesh_hash,
        **extra,
    }
    if args.json:
        from . import emit_json

        emit_json(out)
    else:
        print(
            f"body centre (row, col) = ({centre[0]:.3f}, {centre[1]:.3f})  LOS = [{los[0]:.6f}, {los[1]:.6f}, {los[2]:.6f}]"
            f"  template {j}  match distance {res.match_distance:.4g}",
            file=sys.stdout,
        )
    return 0


__all__ = ["register", "run_build", "run_locate"]
