"""``jaxlimb los``: model-based line of sight of an irregular body (Wu et al.).

Sub-commands::

    jaxlimb los build-db MESH --step-deg 3 --out DB.npz [--pole-axis z] [--template-size 512] [--json]
    jaxlimb los locate IMAGE (--db DB.npz | --mesh MESH) --camera CAMERA.json [--hints HINTS.json]
                       [--no-refine] [--step-deg 3] [--pole-axis z] [--json]

``locate --mesh`` builds the template database once and caches it by mesh hash
and settings in ``$JAXLIMB_CACHE`` (default ``~/.cache/jaxlimb``); later calls find it
by the mesh file's content hash without reading the mesh again.

Output of ``locate --json`` (:func:`jaxlimb.irregular.locate.locate_los`)::

    {"status": "ok", "center_rc": [r, c], "los_camera": [x, y, z], "checked": true,
     "mode": "known-attitude" | "template-search", "covariance": {"center_rc": 2x2},
     "range_km", "R_body_to_camera", "quality": {"residual_excess_frac", "iou", ...},
     "template": {"index", "alpha_deg", "beta_deg"}, "iterations", "locate_seconds", "mesh_hash"}

``--no-refine`` prints the unchecked template match of Wu et al. (``"checked": false``).
A frame the shape model does not explain, or explains with two poses whose centres
differ, is a typed failure (exit 3, checks ``poor_match`` / ``ambiguous_match``).

Errors follow the contract of :mod:`jaxlimb.cli` (exit 2 unusable input, 3 failed check).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from .._io import exclusive_output, write_json_atomic
from .._validate import Range, arg_number, input_file, output_file
from ..errors import ConfigError, DatabaseError, ImageContentError, MeshError, NoBodyError
from . import emit_json, show_progress
from ._batch import add_batch_arguments, is_many, run_frames

#: ``--step-deg``: below 0.5 deg a database has > 250 000 views (> 10 min to build); above 60 no ring is left.
STEP_DEG_RANGE = Range(0.5, 60.0)
TEMPLATE_SIZE_RANGE = Range(32, 4096)


def register(subparsers: Any) -> None:
    p = subparsers.add_parser("los", help="model-based line of sight of an irregular body (Wu et al.)",
                              description="Line of sight of an irregular body from its shape model (Wu et al.): "
                              "build-db renders a template database of views; locate matches a frame against it "
                              "(and, with the attitude known, registers a render of the model) and reports the image "
                              "of the body centre, the line of sight and the range.")
    sub = p.add_subparsers(dest="los_command", metavar="SUBCOMMAND", parser_class=type(p))
    sub.required = True

    b = sub.add_parser("build-db", help="build a template database from a shape model",
                       description="Render the shape model (OBJ, PLY, STL, OFF) from views over the sphere and store "
                       "their silhouettes and features in one versioned database file (written atomically).")
    b.add_argument("mesh", metavar="MESH", help="shape model (.obj, .stl, .ply or a v/f .tab plate table)")
    b.add_argument("--out", required=True, metavar="DB", help="output database file (.npz)")
    _add_db_options(b)
    b.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    b.set_defaults(func=run_build, needs_jax=False)

    q = sub.add_parser("locate", help="locate the image of the body centre and the line of sight",
                       description="Match the frame's silhouette against the database (or a shape model, --mesh) and "
                       "report the image of the body centre, the line of sight and its covariance.  Exit 0 on "
                       "success, 2 for unusable input, 3 when a check fails.")
    q.add_argument("image", metavar="IMAGE", nargs="+", help="grey image (PNG/TIFF/FITS); several files, a "
                   "directory, a quoted glob or @LIST.txt: one JSON line per frame (see --out)")
    src = q.add_mutually_exclusive_group(required=True)
    src.add_argument("--db", metavar="DB", help="template database built by `los build-db`")
    src.add_argument("--mesh", metavar="MESH", help="shape model; the database is built once and cached")
    q.add_argument("--camera", required=True, metavar="CAMERA", help="camera JSON file")
    q.add_argument(
        "--hints",
        metavar="HINTS",
        help="hints JSON (uses `sun_dir_camera`, `R_body_to_camera` (attitude known: render-and-register), `range_prior_km`)",
    )
    q.add_argument("--no-refine", action="store_true", help="the template match of Wu et al. alone: no registration, no checks")
    _add_db_options(q)
    q.add_argument("--json", action="store_true", help="print the result as one JSON object")
    add_batch_arguments(q)
    q.set_defaults(func=run_locate, needs_jax=False)  # numpy + OpenCV only: no JAX start-up


def _add_db_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--step-deg", type=arg_number(STEP_DEG_RANGE), default=3.0,
                   help=f"view-sphere sampling step, deg {STEP_DEG_RANGE} (default 3)")
    p.add_argument("--pole-axis", choices=("x", "y", "z"), default="z", help="mesh axis used as the sampling pole")
    p.add_argument("--template-size", type=arg_number(TEMPLATE_SIZE_RANGE, integer=True), default=512,
                   help=f"template image side, px, integer {TEMPLATE_SIZE_RANGE} (default 512)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (as --quiet)")


def _db_options(args: argparse.Namespace) -> Any:
    from ..irregular.database import DatabaseOptions

    return DatabaseOptions(step_deg=args.step_deg, pole_axis=args.pole_axis, template_size_px=args.template_size)


def run_build(args: argparse.Namespace) -> int:
    from ..irregular.database import build_database, save_database
    from ..irregular.mesh import load_mesh

    opts = _db_options(args)
    input_file(args.mesh, "MESH", error=MeshError)
    target = output_file(args.out, "--out", suffixes=(".npz",), error=ConfigError)  # before any work
    mesh = load_mesh(args.mesh)
    with exclusive_output(target):  # a second build of the same --out is refused; stale temporaries removed
        t0 = time.perf_counter()
        db = build_database(mesh, opts, progress=show_progress(args))
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
        emit_json(summary)
    else:
        print(f"wrote {out} ({len(db)} templates, {dt:.1f} s)")
    return 0


def _read_image(path: str) -> np.ndarray:
    """The frame as float64 (a constant frame is read: it is a frame without a body, exit 3 as for `locate`)."""
    from ..imaging.io import load_image

    img, _ = load_image(path, reject_constant=False)
    return img


def _read_hints(path: str | None) -> Any:
    from ..imaging import Hints

    return Hints.from_json(path) if path is not None else Hints()


def _locate_unchecked(image: np.ndarray, db: Any, camera: Any) -> dict[str, Any]:
    """``--no-refine``: the template match of Wu et al. alone (Eq. 15-25), without the checks."""
    from ..irregular.matching import MatchOptions, locate_center

    res = locate_center(image, db, camera, MatchOptions())
    j = res.template_index
    return {
        "center_rc": [float(v) for v in res.center_rc],
        "checked": False,
        "template": {
            "index": int(j),
            "alpha_deg": math.degrees(float(db.alpha[j])),
            "beta_deg": math.degrees(float(db.beta[j])),
            "rotation_deg": math.degrees(res.theta),
            "scale": res.scale,
        },
        "match_distance": res.match_distance,
        "figure_center_rc": [float(v) for v in res.figure_center_rc],
        "brightness_center_rc": [float(v) for v in res.brightness_center_rc],
    }


def _locate_checked(image: np.ndarray, db: Any, camera: Any, hints: Any) -> dict[str, Any]:
    """The checked line of sight of :func:`jaxlimb.irregular.locate.locate_los` as a JSON dict."""
    from ..irregular.locate import locate_los

    sun = None if hints.sun_dir_camera is None else np.asarray(hints.sun_dir_camera, dtype=float)
    R = None if hints.R_body_to_camera is None else np.asarray(hints.R_body_to_camera, dtype=float)
    res = locate_los(image, db, camera, sun, R, hints.range_prior_km)
    fit = res.fit
    out: dict[str, Any] = {
        "center_rc": [float(v) for v in fit.center_rc],
        "checked": True,
        "mode": res.mode.value,
        "covariance": {"center_rc": fit.covariance_rc.tolist()},
        "range_km": fit.range_km,
        "R_body_to_camera": fit.R_body_to_camera.tolist(),
        "quality": {
            "residual_excess_frac": fit.excess_frac,
            "iou": fit.iou,
            "rms_residual": fit.rms_residual,
            "noise_sigma": fit.noise_sigma,
            "ncc": fit.ncc,
            "hypotheses_tried": res.n_tried,
            "hypotheses_accepted": res.n_accepted,
            "runner_up_excess_frac": res.runner_up_excess,
        },
        "iterations": fit.iterations,
    }
    if res.template_index is not None:
        j = res.template_index
        out["template"] = {"index": int(j), "alpha_deg": math.degrees(float(db.alpha[j])), "beta_deg": math.degrees(float(db.beta[j]))}
    return out


def run_locate(args: argparse.Namespace) -> int:
    # the database/mesh file is checked before any frame is read (and long before a database build)
    if args.db is not None:
        input_file(args.db, "--db", error=DatabaseError)
    else:
        input_file(args.mesh, "--mesh", error=MeshError)
    images = list(args.image)
    if is_many(images, args):  # many frames: JSON Lines, one per frame (cli/_batch.py)
        memo: dict[str, Any] = {}  # the camera and the database, loaded once for every frame
        return run_frames(images, args, _read_image, lambda path, image: _locate_one(args, path, image, memo))
    args.image = images[0]
    out = _locate_one(args, args.image, _read_image(args.image), {})
    if args.json:
        emit_json(out)
    else:
        c, los = out["center_rc"], out["los_camera"]
        print(
            f"body centre (row, col) = ({c[0]:.3f}, {c[1]:.3f})  LOS = [{los[0]:.6f}, {los[1]:.6f}, {los[2]:.6f}]"
            f"  ({out.get('mode', 'unchecked template match')})",
            file=sys.stdout,
        )
    return 0


def _database_for_mesh_file(path: str, options: Any, progress: bool) -> Any:
    """The cached template database of a shape-model file (:func:`jaxlimb.irregular.database.cached_database`).

    Which cached database a file resolved to is kept under the SHA-256 of its bytes, of the mesh loader
    (``irregular/mesh.py``) and of the settings, so that a later call loads that database without reading the
    mesh again (importing trimesh and reading the mesh cost a ``locate --mesh`` process about 0.7 s CPU).
    The database is verified as on any load (its stored mesh, hash and settings).
    """
    from ..irregular import mesh as mesh_module
    from ..irregular.database import cache_dir, cache_path, cached_database, load_database

    key = hashlib.sha256(Path(path).read_bytes())
    key.update(Path(mesh_module.__file__).read_bytes())
    key.update(options.to_json().encode())
    index = cache_dir() / f"los-mesh-file-{key.hexdigest()[:32]}.json"
    try:
        rec = json.loads(index.read_text())
        return load_database(cache_dir() / rec["database"], expected_mesh_hash=rec["mesh_hash"], expected_options=options)
    except (OSError, ValueError, KeyError, TypeError, DatabaseError):
        pass  # no record, or its database is gone or fails verification: load the mesh
    mesh = mesh_module.load_mesh(path)
    db = cached_database(mesh, options, progress=progress)
    try:
        write_json_atomic(index, {"database": cache_path(mesh, options).name, "mesh_hash": db.mesh_hash})
    except OSError:
        pass  # an unwritable cache: the mesh is read again next time
    return db


def _locate_one(args: argparse.Namespace, path: str, image: np.ndarray, memo: dict[str, Any]) -> dict[str, Any]:
    """The ``--json`` object of one frame; ``memo`` keeps the camera, hints and database between frames."""
    from ..geometry.camera import Camera
    from ..irregular.database import load_database

    if "camera" not in memo:
        memo["camera"] = Camera.from_json(args.camera)
        memo["hints"] = _read_hints(args.hints)
    camera, hints = memo["camera"], memo["hints"]
    if image.shape != camera.shape:
        raise ImageContentError(f"image {path!r} has shape {image.shape}, the camera expects {camera.shape}")
    if float(image.max()) == float(image.min()):  # before any database load or build
        raise NoBodyError(f"image {path!r} is constant (every pixel = {float(image.min()):g}): no body")
    if "db" not in memo:
        if args.db is not None:
            memo["db"] = load_database(args.db)
        else:
            memo["db"] = _database_for_mesh_file(args.mesh, _db_options(args), progress=show_progress(args))
    db = memo["db"]
    t0 = time.perf_counter()
    body = _locate_unchecked(image, db, camera) if args.no_refine else _locate_checked(image, db, camera, hints)
    center = np.asarray(body["center_rc"], dtype=float)
    los = camera.los(center)
    return {
        "status": "ok",
        **body,
        "los_camera": [float(v) for v in los],
        "locate_seconds": round(time.perf_counter() - t0, 4),
        "mesh_hash": db.mesh_hash,
    }


__all__ = ["register", "run_build", "run_locate"]
