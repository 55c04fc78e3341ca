r"""``jaxlimb navigate IMAGE --kernels META``: the observer position from a labelled mission frame and SPICE.

The same SPICE hints as ``jaxlimb locate --kernels`` (:mod:`jaxlimb.geometry.spice`: the camera from the
IK, the image time from the label, the predicted limb, the Sun direction, the range and the body's
orientation), the same measurement (:func:`jaxlimb.pipeline.locate`, the validity mask respected), then
Mortari, D'Souza & Zanetti's step 7 with the body at the origin:

.. math:: r_o = -\,C^\top (D\,u_c)

``C`` the J2000 -> camera rotation (the reconstructed pointing of the CK, or ``--attitude``), ``u_c`` and
``D`` the measured line of sight and range.  The covariance maps the measurement's
``(center_r, center_c, radius)`` covariance through the Jacobian of ``(centre, radius) -> D u_c``
(:func:`jaxlimb.cli._navigate._measurement_map`), plus the attitude term of
:func:`jaxlimb.geometry.navigation.navigate` for ``--attitude-sigma-arcsec``.  Reported beside SPICE's
observer position (their difference is the pointing and range error of the prediction), and the
measured - predicted pointing of ``locate``.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

import numpy as np


def observer_solution(meas, camera, C_ci: np.ndarray, attitude_sigma_rad: float = 0.0) -> dict[str, Any]:
    """Observer position relative to the body (frame of ``C_ci``, km), its covariance and parts."""
    from ..numerics import numerical_jacobian
    from ..errors import CheckFailed
    from ..geometry.navigation import navigate
    from ._navigate import _measurement_map

    if meas.los_camera is None or meas.range_km is None:
        raise CheckFailed("the limb measurement has no line of sight / range (camera or body size unknown)")
    names, fn = _measurement_map("body", camera, meas)
    x0 = np.array([meas.center_rc[0], meas.center_rc[1], meas.radius_px], float)
    P = np.array([[meas.covariance[a][b] for b in names] for a in names])
    G = numerical_jacobian(fn, x0, np.array([1e-3, 1e-3, 1e-3]))
    r_om = fn(x0)
    D = float(np.linalg.norm(r_om))
    sol = navigate(np.zeros(3), C_ci, r_om / D, D, attitude_cov_rad2=attitude_sigma_rad if attitude_sigma_rad > 0 else None)
    C = np.asarray(C_ci, float)
    P_meas = C.T @ G @ P @ G.T @ C
    Ptot = P_meas + sol.contributions_km2["attitude"]
    Ptot = 0.5 * (Ptot + Ptot.T)

    def m(a):
        return [[float(v) for v in row] for row in a]

    return {
        "position_km": [float(v) for v in sol.position_km], "covariance_km2": m(Ptot),
        "sigma_km": [float(math.sqrt(max(Ptot[i, i], 0.0))) for i in range(3)], "range_km": D,
        "los_camera": [float(v) for v in r_om / D], "center_rc": [float(v) for v in meas.center_rc],
        "covariance_parts_km2": {"measurement": m(P_meas), "attitude": m(sol.contributions_km2["attitude"])},
    }


def run_spice(args: argparse.Namespace) -> int:
    """``navigate --kernels`` (module docstring)."""
    from ..errors import ConfigError, SaturationWarning, UsageError
    from ..geometry.camera import Camera
    from ..pipeline import locate
    from . import emit_json, warnings_to_stderr
    from ._locate import _read, _read_hints, _spice, _spice_report
    from ._navigate import parse_attitude

    if args.epoch is not None:
        raise UsageError("--epoch is read from the label with --kernels (the image time); leave it out")
    frame = _read(args.image)
    geom = _spice(args, frame.meta)
    camera = Camera.from_json(args.camera) if args.camera is not None else geom.camera
    if (camera.rows, camera.cols) != tuple(frame.data.shape[:2]):
        raise ConfigError(f"camera size {camera.rows}x{camera.cols} does not match the image size "
                          f"{frame.data.shape[0]}x{frame.data.shape[1]}")
    body = (args.body or geom.target).lower()
    hints = _read_hints(args.hints, body, base=geom.hints())
    if args.attitude is not None:
        C_ci, att_kind = parse_attitude(args.attitude)
    else:
        C_ci, att_kind = np.asarray(geom.C_camera_from_j2000, float), f"SPICE CK ({geom.instrument})"
    with warnings_to_stderr(SaturationWarning):
        meas = locate(frame.data, camera, hints, None, mask=frame.mask_or_none)
    sol = observer_solution(meas, camera, C_ci, math.radians(args.attitude_sigma_arcsec / 3600.0))
    spice = _spice_report(geom, meas)
    ref = np.asarray(geom.observer_j2000_km, float)
    diff = np.asarray(sol["position_km"]) - ref
    out = {"status": "ok", "body": body, "epoch": geom.utc, "frame": f"J2000, relative to the centre of {geom.target} (km)",
           **sol, "attitude": att_kind, "spice_observer_km": [float(v) for v in ref],
           "minus_spice_km": [float(v) for v in diff], "minus_spice_norm_km": float(np.linalg.norm(diff)),
           "spice": spice}
    if args.json:
        emit_json(out)
    else:
        pos, sig = out["position_km"], out["sigma_km"]
        print(f"body {body}, image time {geom.utc}, attitude from {att_kind}")
        print(f"position ({out['frame']}): " + " ".join(f"{v:.3f}" for v in pos) + " km")
        print("1-sigma: " + " ".join(f"{v:.3f}" for v in sig) + " km")
        print("minus SPICE: " + " ".join(f"{v:.3f}" for v in diff) + f" km (|d| {out['minus_spice_norm_km']:.3f} km)")
        d = spice["measured_minus_predicted"]
        print(f"measured - predicted centre: {d['delta_rc_px'][0]:+.2f} {d['delta_rc_px'][1]:+.2f} px")
    return 0


__all__ = ["observer_solution", "run_spice"]
