r"""``jaxlimb navigate IMAGE --kernels META``: the observer position from a labelled mission frame and SPICE.

The same SPICE hints as ``jaxlimb locate --kernels`` (:mod:`jaxlimb.geometry.spice`: the camera from the
IK, the image time from the label, the predicted limb, the Sun direction, the range and the body's
orientation), the same measurement (:func:`jaxlimb.pipeline.locate`, the validity mask respected), then
Mortari, D'Souza & Zanetti's step 7 with the body at the origin:

.. math:: r_o = -\,C^\top (D\,u_c)

``C`` the J2000 -> camera rotation (the reconstructed pointing of the CK, or ``--attitude``), ``u_c`` and
``D`` the measured line of sight and range.  The covariance maps the measurement's
``(center_r, center_c, radius)`` covariance through the Jacobian of ``(centre, radius) -> D u_c`` (of
``(centre, range)`` for a spheroid the ellipsoid strategy measured: :func:`jaxlimb.cli._observer.measurement_map`), plus the attitude term of
:func:`jaxlimb.geometry.navigation.navigate` for ``--attitude-sigma-arcsec``, plus the camera's scale along the
line of sight when the camera is the IK's and the IK states its focal-length uncertainty
(``INS<id>_FL_UNCERTAINTY``: the range from an apparent size scales with the focal length).  Reported beside SPICE's
observer position (their difference is the pointing and range error of the prediction), and the
measured - predicted pointing of ``locate``.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from ..errors import ConfigError, SaturationWarning, UsageError
from ..geometry.camera import Camera
from . import emit_json, warnings_to_stderr
from ._inputs import locate_options_given, read_frame_file, read_hints, spice_prediction, spice_report
from ._observer import observer_position, parse_attitude


def run_spice(args: argparse.Namespace) -> int:
    """``navigate --kernels`` (module docstring)."""
    from ..pipeline import LocateOptions, locate

    if args.epoch is not None:
        raise UsageError("--epoch is read from the label with --kernels (the image time); leave it out")
    frame = read_frame_file(args.image)
    geom = spice_prediction(args, frame.meta)
    camera = Camera.from_json(args.camera) if args.camera is not None else geom.camera
    if (camera.rows, camera.cols) != tuple(frame.data.shape[:2]):
        raise ConfigError(f"camera size {camera.rows}x{camera.cols} does not match the image size "
                          f"{frame.data.shape[0]}x{frame.data.shape[1]}")
    body = (args.body or geom.target).lower()
    hints = read_hints(args.hints, body, base=geom.hints())
    if args.attitude is not None:
        C_ci, att_kind = parse_attitude(args.attitude)
    else:
        C_ci, att_kind = np.asarray(geom.C_camera_from_j2000, float), f"SPICE CK ({geom.instrument})"
    with warnings_to_stderr(SaturationWarning):
        meas = locate(frame.data, camera, hints, LocateOptions(**locate_options_given(args)), mask=frame.mask_or_none)
    s_f = geom.focal_length_sigma_mm if args.camera is None and geom.focal_length_sigma_mm else 0.0
    sol = observer_position("body", meas, camera, C_ci, np.zeros(3), math.radians(args.attitude_sigma_arcsec / 3600.0),
                            scale_sigma_frac=s_f / camera.focal_length_mm)
    spice = spice_report(geom, meas)
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


__all__ = ["run_spice"]
