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
import json
import math
from typing import Any

import numpy as np

from .._validate import Range, arg_number

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
    p.add_argument("--camera", metavar="CAMERA.json", help="camera file (DESIGN.md); required without --kernels")
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
    p.add_argument("--hints", metavar="HINTS.json", help="navigation prior (DESIGN.md hints)")
    p.add_argument("--attitude-sigma-arcsec", type=arg_number(_ATT_SIGMA), default=0.0, dest="attitude_sigma_arcsec",
                   help=f"per-axis 1-sigma attitude error added to the covariance, arcsec {_ATT_SIGMA} (default 0)")
    p.add_argument("--ephemeris", metavar="BSP", default=None,
                   help="JPL kernel (.bsp) or its directory (default: DE421 from skyfield-data)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


# ----------------------------------------------------------------------------- attitude
def parse_attitude(text: str) -> tuple[np.ndarray, str]:
    """``C_ci`` from the ``--attitude`` argument (module docstring); returns ``(C_ci, description)``.

    Raises
    ------
    ConfigError
        Unreadable file / invalid JSON / unknown layout.
    AttitudeError
        Not a unit quaternion or not a proper orthonormal matrix (tolerance 1e-6).
    """
    from ..errors import ConfigError
    from ..geometry.attitude import quat_to_dcm, validate_dcm

    from .._io import read_json_file
    from .._validate import real_array

    src = text.strip()
    if src.startswith("{") or src.startswith("["):
        try:
            obj = json.loads(src)
        except json.JSONDecodeError as e:
            raise ConfigError(f"--attitude is not valid JSON: {e.msg} at line {e.lineno}") from None
    else:
        obj = read_json_file(src, "--attitude file")
    order = "xyzw"
    if isinstance(obj, dict):
        keys = {k.lower(): k for k in obj}
        if "order" in keys:
            order = obj[keys["order"]]
            if order not in ("xyzw", "wxyz"):
                raise ConfigError(f"--attitude `order` must be 'xyzw' (scalar-last) or 'wxyz' (scalar-first), got {order!r}")
        for name in ("quaternion", "q"):
            if name in keys:
                obj = obj[keys[name]]
                break
        else:
            for name in ("c_ci", "dcm"):
                if name in keys:
                    obj = obj[keys[name]]
                    break
            else:
                raise ConfigError(f"--attitude object needs a `quaternion` or a `C_ci` key, got keys {sorted(obj)}")
    a = real_array(obj, "--attitude")  # numbers only: `true` or "0" is not a quaternion component
    if a.shape == (4,):
        return quat_to_dcm(a, order=order), f"quaternion ({order})"
    if a.shape == (3, 3):
        return validate_dcm(a, name="C_ci"), "C_ci"
    raise ConfigError(f"--attitude must be a quaternion (4 numbers) or a 3x3 C_ci, got shape {a.shape}")


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


def _measurement_map(body: str, camera, meas) -> tuple[list[str], Any]:
    """Names of the measured quantities and ``x -> r_om`` (camera frame, km)."""
    from ..errors import ConfigError

    cov = meas.covariance
    if body == "earth":
        names = ["center_r", "center_c", "range_km"]

        def fn(x: np.ndarray) -> np.ndarray:
            return x[2] * camera.los(x[:2])

        return names, fn
    names = ["center_r", "center_c", "radius"]
    if not all(n in cov for n in names):
        raise ConfigError(f"the Moon measurement has no covariance of {names} (got {sorted(cov)})")
    R_km = meas.range_km * math.sin(math.atan(float(meas.radius_px) / camera.focal_px))

    def fn_moon(x: np.ndarray) -> np.ndarray:
        D = R_km / math.sin(math.atan(x[2] / camera.focal_px))
        return D * camera.los(x[:2])

    return names, fn_moon


def navigate_measurement(
    body: str,
    meas,
    camera,
    C_ci: np.ndarray,
    epoch: Any,
    *,
    attitude_sigma_rad: float = 0.0,
    ephemeris_path: str | None = None,
) -> dict[str, Any]:
    """Observer position (geocentric ICRF, km) and covariance from a limb measurement.

    Returns the ``--json`` object of ``jaxlimb navigate`` (module docstring).
    """
    from ..errors import CheckFailed
    from ..geometry.ephemeris import body_position
    from ..geometry.navigation import navigate

    if meas.los_camera is None or meas.range_km is None:
        raise CheckFailed("the limb measurement has no line of sight / range (camera or body size unknown)")
    r_body = np.zeros(3) if body == "earth" else body_position("moon", epoch, "earth", path=ephemeris_path)
    names, fn = _measurement_map(body, camera, meas)
    x0 = np.array([meas.center_rc[0], meas.center_rc[1], meas.range_km if body == "earth" else meas.radius_px], float)
    P = np.array([[meas.covariance[a][b] for b in names] for a in names])
    from ..numerics import numerical_jacobian

    G = numerical_jacobian(fn, x0, np.array([1e-3, 1e-3, 1e-3 if body != "earth" else 1e-3 * max(1.0, x0[2] * 1e-6)]))
    r_om = fn(x0)
    D = float(np.linalg.norm(r_om))
    sol = navigate(r_body, C_ci, r_om / D, D, attitude_cov_rad2=attitude_sigma_rad if attitude_sigma_rad > 0 else None)
    C = np.asarray(C_ci, float)
    P_meas = C.T @ G @ P @ G.T @ C
    Ptot = P_meas + sol.contributions_km2["attitude"]
    Ptot = 0.5 * (Ptot + Ptot.T)
    return {
        "status": "ok",
        "body": body,
        "epoch": epoch if isinstance(epoch, str) else float(epoch),
        "frame": "ICRF/J2000, geocentric (km)",
        "position_km": [float(v) for v in sol.position_km],
        "covariance_km2": [[float(v) for v in row] for row in Ptot],
        "sigma_km": [float(math.sqrt(max(Ptot[i, i], 0.0))) for i in range(3)],
        "range_km": D,
        "los_camera": [float(v) for v in r_om / D],
        "center_rc": [float(v) for v in meas.center_rc],
        "body_position_km": [float(v) for v in r_body],
        "covariance_parts_km2": {
            "measurement": [[float(v) for v in row] for row in P_meas],
            "attitude": [[float(v) for v in row] for row in sol.contributions_km2["attitude"]],
        },
    }


def locate_body(body: str, image: np.ndarray, camera, hints) -> Any:
    """The limb measurement: :func:`jaxlimb.pipeline.locate` (the hints' body picks the strategy: the
    Earth's ellipsoid, the Moon's sphere)."""
    from dataclasses import replace

    from ..pipeline import locate

    return locate(image, camera, replace(hints, body=body) if hints.body != body else hints, None)


def run(args: argparse.Namespace) -> int:
    from ..geometry.ephemeris import clear_cache

    try:
        return _run(args)
    finally:
        clear_cache()  # close the kernel file: no ResourceWarning at exit


def _run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from ..errors import ConfigError

    if args.kernels:
        from ._navigate_spice import run_spice

        return run_spice(args)
    from ..errors import UsageError

    missing = [f"--{n}" for n in ("camera", "epoch", "attitude") if getattr(args, n) is None]
    if missing:
        raise UsageError(f"navigate needs {', '.join(missing)} (or --kernels with a labelled frame)")
    if args.body is not None and args.body not in ("moon", "earth"):
        raise UsageError(f"--body must be moon or earth without --kernels, got {args.body!r}")
    from ..geometry.camera import Camera
    from ..geometry.ephemeris import load_ephemeris
    from ..imaging import ColourImageWarning, Hints, load_image
    from . import emit_json, warnings_to_stderr
    from ._locate import _read_hints

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
    hints = _read_hints(args.hints, body)
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
    from ..errors import SaturationWarning

    with warnings_to_stderr(SaturationWarning):
        meas = locate_body(body, image, camera, hints)
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
