r"""``jaxlimb navigate IMAGE``: the observer position (J2000) and its covariance from one image.

Steps 1-7 of the flowchart of Mortari, D'Souza & Zanetti (§II): the limb measurement of the
body (:func:`jaxlimb.pipeline.locate`: the sphere strategy for the Moon, the ellipsoid for the Earth) gives
the body-centre line of sight ``u_c`` and range ``D`` in the camera frame; the attitude ``C_ci``
(inertial -> camera) and the body's ephemeris ``r_b`` (DE421, offline) give::

    r_o = r_b - C_ci^T (D u_c)                       (geocentric ICRF/J2000, km)

Covariance: the measurement's covariance of ``(center_r, center_c, X)`` -- ``X`` = the
on-axis-equivalent radius ``f tan(alpha)`` (Moon) or the range (Earth) -- mapped through the
central-difference Jacobian of ``(center, X) -> D u_c`` (:func:`camera.los`, distortion
included), rotated by ``C_ci^T``; plus the attitude term ``C^T [r_om x] P_phi [r_om x]^T C`` of
:func:`jaxlimb.geometry.navigation.navigate` when ``--attitude-sigma-arcsec`` is given.

Attitude (``--attitude``): a JSON file or inline JSON, one of

* ``{"quaternion": [q1, q2, q3, q4], "order": "xyzw"}`` -- **scalar-last by default**
  (``"order": "wxyz"`` for scalar-first); Shuster's attitude matrix ``A(q)`` is used as
  ``C_ci`` (:mod:`jaxlimb.geometry.attitude`); a bare list of 4 numbers is a scalar-last quaternion;
* ``{"C_ci": [[...], [...], [...]]}`` (or ``"dcm"``), or a bare 3x3 list: the DCM taking
  inertial (ICRF/J2000) vectors to the camera frame.

Earth: when the hints carry no ``R_body_to_camera`` it is built from the attitude and the
Earth's orientation at the epoch (``C_ci R_itrs^T``, skyfield's ITRS frame with its built-in
time scale: precession, nutation, Earth rotation; nothing downloaded), so the known-orientation
route (``rho``, ``theta`` fixed, ``gamma_off`` signed) is used.

Errors follow :mod:`jaxlimb.cli` (exit 2: unreadable/invalid inputs, non-orthonormal attitude,
epoch outside the ephemeris, missing ephemeris file, impossible geometry; exit 3: a failed check).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from typing import Any

import numpy as np

from .._validate import Range, arg_number
from ..errors import CheckFailed, ConfigError, SaturationWarning, UsageError
from ..geometry.camera import Camera
from ..geometry.hints import Hints
from . import emit_json, warnings_to_stderr
from ._inputs import add_center_tolerance, locate_options_given, read_hints
from ._navigate_spice import run_spice
from ._observer import observer_position, parse_attitude

_ATT_SIGMA = Range(0.0, 648_000.0)  # arcsec: 0 to 180 deg


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "navigate",
        help="observer position (J2000) and covariance from an image of the Moon or the Earth",
        description="Locate the body in IMAGE, then combine its line of sight and range with the camera "
        "attitude and the DE421 ephemeris (offline) into the observer position, geocentric ICRF/J2000 (km), "
        "with its first-order covariance.  Exit 0 on success, 2 for unusable input, 3 when a check fails.",
    )
    p.add_argument("image", metavar="IMAGE", help="image file (PNG, TIFF, FITS; VICAR/PDS with --kernels)")
    p.add_argument("--camera", metavar="CAMERA.json", help="camera file (docs/design.md); required without --kernels")
    p.add_argument("--epoch", metavar="T",
                   help="epoch of the image: ISO 8601 UTC (e.g. 2026-03-01T12:00:00Z) or a TDB Julian date; "
                   "required without --kernels")
    p.add_argument("--attitude", metavar="Q|DCM",
                   help='JSON file or inline JSON: {"quaternion": [q1,q2,q3,q4], "order": "xyzw"} '
                   '(scalar-last default) or {"C_ci": 3x3} (inertial -> camera); required without --kernels')
    p.add_argument("--body", default=None,
                   help="the body: moon or earth (default: the hints' body, else moon); with --kernels any body "
                   "SPICE knows (default: the label's TARGET_NAME)")
    p.add_argument("--kernels", metavar="KERNEL", nargs="+", default=None,
                   help="SPICE meta-kernel or kernel files (never downloaded), as for `jaxlimb locate`: camera, image "
                   "time, attitude (CK), Sun, range and orientation from the label; the position is the observer's "
                   "relative to the body, J2000, beside SPICE's")
    p.add_argument("--instrument", metavar="NAME", default=None,
                   help="SPICE instrument with --kernels (default: the label's INSTRUMENT_ID)")
    p.add_argument("--hints", metavar="HINTS.json", help="navigation prior (docs/design.md hints)")
    p.add_argument("--attitude-sigma-arcsec", type=arg_number(_ATT_SIGMA), default=0.0, dest="attitude_sigma_arcsec",
                   help=f"per-axis 1-sigma attitude error added to the covariance, arcsec {_ATT_SIGMA} (default 0)")
    p.add_argument("--ephemeris", metavar="BSP", default=None,
                   help="JPL kernel (.bsp) or its directory (default: DE421 from skyfield-data)")
    add_center_tolerance(p)
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


# ----------------------------------------------------------------------------- core
def earth_rotation_icrf_to_itrs(epoch: Any, ephemeris_path: str | None = None) -> np.ndarray:
    """Rotation ICRF -> ITRS (Earth-fixed, pole = z) at ``epoch`` (skyfield built-in time scale)."""
    from skyfield.framelib import itrs

    from ..geometry.ephemeris import load_ephemeris

    t = load_ephemeris(ephemeris_path).time(epoch)
    return np.asarray(itrs.rotation_at(t), dtype=float)


def sun_direction_camera(body: str, epoch: Any, C_ci: np.ndarray, ephemeris_path: str | None = None) -> np.ndarray:
    """Unit vector from ``body`` toward the Sun in the camera frame, ``C_ci unit(r_sun - r_body)``
    (geocentric ICRF positions of the ephemeris; the observer's parallax is below 1e-3 rad)."""
    from ..geometry.ephemeris import body_position

    r_body = np.zeros(3) if body == "earth" else body_position(body, epoch, "earth", path=ephemeris_path)
    r_sun = body_position("sun", epoch, "earth", path=ephemeris_path)
    u = np.asarray(C_ci, float) @ (r_sun - r_body)
    return u / np.linalg.norm(u)


def navigate_measurement(body: str, meas, camera, C_ci: np.ndarray, epoch: Any, *,  # noqa: ANN001
                         attitude_sigma_rad: float = 0.0, ephemeris_path: str | None = None) -> dict[str, Any]:
    """Observer position (geocentric ICRF, km) and covariance from a limb measurement: the ``--json`` object of
    ``jaxlimb navigate`` (module docstring; :func:`~jaxlimb.cli._observer.observer_position`)."""
    from ..geometry.ephemeris import body_position

    if meas.los_camera is None or meas.range_km is None:  # (before the ephemeris is read)
        raise CheckFailed("the limb measurement has no line of sight / range (camera or body size unknown)")
    r_body = np.zeros(3) if body == "earth" else body_position("moon", epoch, "earth", path=ephemeris_path)
    sol = observer_position(body, meas, camera, C_ci, r_body, attitude_sigma_rad)
    return {"status": "ok", "body": body, "epoch": epoch if isinstance(epoch, str) else float(epoch),
            "frame": "ICRF/J2000, geocentric (km)", **sol, "body_position_km": [float(v) for v in r_body]}


def locate_body(body: str, image: np.ndarray, camera, hints, options: dict | None = None) -> Any:
    """The limb measurement: :func:`jaxlimb.pipeline.locate` (the hints' body picks the strategy: the
    Earth's ellipsoid, the Moon's sphere), with the ``LocateOptions`` fields ``options`` sets."""
    from ..pipeline import LocateOptions, locate

    return locate(image, camera, replace(hints, body=body) if hints.body != body else hints,
                  LocateOptions(**options) if options else None)


def run(args: argparse.Namespace) -> int:
    from ..geometry.ephemeris import clear_cache

    try:
        return _run(args)
    finally:
        clear_cache()  # close the kernel file: no ResourceWarning at exit


def _run(args: argparse.Namespace) -> int:
    if args.kernels:
        return run_spice(args)
    missing = [f"--{n}" for n in ("camera", "epoch", "attitude") if getattr(args, n) is None]
    if missing:
        raise UsageError(f"navigate needs {', '.join(missing)} (or --kernels with a labelled frame)")
    if args.body is not None and args.body not in ("moon", "earth"):
        raise UsageError(f"--body must be moon or earth without --kernels, got {args.body!r}")
    from ..geometry.ephemeris import load_ephemeris
    from ..imaging import ColourImageWarning, load_image

    camera = Camera.from_json(args.camera)
    C_ci, att_kind = parse_attitude(args.attitude)
    # epoch: ISO string or a TDB Julian date; checked against the kernel span before any image work
    epoch: Any = args.epoch
    try:
        epoch = float(epoch)
    except ValueError:
        pass
    eph = load_ephemeris(args.ephemeris)
    eph.time(epoch)
    body = args.body
    if body is None:
        hb = Hints.from_json(args.hints).body if args.hints is not None else None
        body = hb if hb in ("moon", "earth") else "moon"
    hints = read_hints(args.hints, body)
    if hints.sun_dir_camera is None:
        # the Sun's direction from the body, in the camera frame, from the ephemeris and the
        # attitude: it selects the lit limb and enables the physical limb profile
        hints = replace(hints, sun_dir_camera=sun_direction_camera(body, epoch, C_ci, args.ephemeris).tolist())
    if body == "earth" and hints.R_body_to_camera is None:
        R = C_ci @ earth_rotation_icrf_to_itrs(epoch, args.ephemeris).T
        hints = replace(hints, R_body_to_camera=R.tolist())
    with warnings_to_stderr(ColourImageWarning):
        image, _info = load_image(args.image, reject_constant=False)
    if (camera.rows, camera.cols) != tuple(image.shape[:2]):
        raise ConfigError(f"camera size {camera.rows}x{camera.cols} does not match the image size {image.shape[0]}x{image.shape[1]}")
    with warnings_to_stderr(SaturationWarning):
        meas = locate_body(body, image, camera, hints, locate_options_given(args))
    out = navigate_measurement(
        body, meas, camera, C_ci, epoch,
        attitude_sigma_rad=math.radians(args.attitude_sigma_arcsec / 3600.0), ephemeris_path=args.ephemeris,
    )
    out["attitude"] = att_kind
    if args.json:
        emit_json(out)
    else:
        pos, sig = out["position_km"], out["sigma_km"]
        print(f"body {body}, epoch {args.epoch}, attitude from {att_kind}")
        print("position (ICRF/J2000, geocentric): " + " ".join(f"{v:.3f}" for v in pos) + " km")
        print("1-sigma:                           " + " ".join(f"{v:.3f}" for v in sig) + " km")
        print(f"range {out['range_km']:.3f} km, centre (row, col) {out['center_rc'][0]:.4f} {out['center_rc'][1]:.4f} px")
    return 0
