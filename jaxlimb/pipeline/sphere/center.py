r"""Stage "body-centre mapping" of :func:`jaxlimb.pipeline.locate`: fitted limb parameters -> image of the
body centre, radius, line of sight, range, and the Jacobian of that map (for the covariance stage).

The map is exact for a sphere (:func:`jaxlimb.geometry.sphere_image.sphere_from_ellipse_center`, equivalent to
:func:`jaxlimb.geometry.navigation.sphere_from_ellipse`): the limb of a sphere off the optical axis is an
ellipse whose centre is not the image of the body centre.  ``radius_px`` is then the on-axis-equivalent
radius ``f tan(alpha) = b^2/a`` and ``range_km = R / sin(alpha)``.  With lens distortion the fit is in
ideal (pinhole) pixels and the body-centre image is distorted back (:meth:`Frame.to_observed`).  The
Jacobian is by central differences (:func:`jaxlimb.analysis.crlb.numerical_jacobian`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...geometry.camera import Camera
from ...geometry.navigation import sphere_from_ellipse
from ...geometry.sphere_image import sphere_from_ellipse_center
from ...numerics import numerical_jacobian
from ..result import EllipseResult
from ..stages import BodyCenter, Frame

#: The names of the body-centre outputs of a round body.
ROUND_OUTPUTS = ("center_r", "center_c", "radius")


def _los(cam: Camera | None, center_rc) -> tuple[float, float, float] | None:
    return None if cam is None else tuple(float(v) for v in cam.los(np.asarray(center_rc, float)))


def circle_center(frame: Frame, center_rc, radius_px: float, params: tuple[str, str, str] = ("r0", "c0", "a"),
                  range_from_radius: bool = False) -> BodyCenter:
    """No body-centre correction: the fitted circle's centre (the disc of the Sun, a frame without camera).

    Parameters
    ----------
    frame : Frame
        Camera (line of sight, range) and body radius, when known.
    center_rc : (float, float)
        Fitted circle centre ``(row, col)`` (px).
    radius_px : float
        Fitted radius (px).
    params : (str, str, str)
        The fit's names of the centre and radius (the identity map's parameters).
    range_from_radius : bool
        Report the range ``R / sin(atan(radius / f))`` (the Sun's orthographic disc; camera and radius known).

    Returns
    -------
    BodyCenter
        Outputs ``center_r, center_c, radius`` with an identity Jacobian.
    """
    rng = None
    if range_from_radius and frame.cam is not None and frame.body_radius_km is not None:
        rng = float(frame.body_radius_km / math.sin(math.atan(radius_px / frame.cam.focal_px)))
    c = (float(center_rc[0]), float(center_rc[1]))
    return BodyCenter(c, float(radius_px), None, _los(frame.cam, c), rng, ROUND_OUTPUTS, params, np.eye(3))


def sphere_center(frame: Frame, x0: np.ndarray, params: tuple[str, str, str]) -> BodyCenter:
    """A sphere's limb ellipse of centre ``x0[:2]`` and semi-axis ``x0[2]`` (ideal px) -> body centre (exact).

    Parameters
    ----------
    frame : Frame
        Needs a camera; ``body_radius_km`` gives the range.
    x0 : np.ndarray (3,)
        ``(r0, c0, a)``: the fitted limb ellipse's centre and semi-major axis in ideal (pinhole) pixels.
    params : (str, str, str)
        The fit's names of those three parameters.

    Returns
    -------
    BodyCenter
        Observed body-centre image, on-axis-equivalent radius ``b^2/a`` (px), LOS, range ``R / sin(alpha)`` (km),
        the central-difference Jacobian, the limb ellipse in ``extras``.
    """
    pin = frame.pin
    assert pin is not None

    def out(x: np.ndarray) -> np.ndarray:
        s = sphere_from_ellipse_center(pin.focal_px, pin.principal_point_rc, (x[0], x[1]), x[2])
        bc = frame.to_observed(s.body_center_rc)
        return np.array([bc[0], bc[1], s.radius_equivalent_px])

    sph = sphere_from_ellipse_center(pin.focal_px, pin.principal_point_rc, (x0[0], x0[1]), x0[2])
    rng = None if frame.body_radius_km is None else float(frame.body_radius_km / math.sin(sph.alpha_rad))
    extras = {"limb_ellipse": {"center_rc": list(frame.to_observed(sph.ellipse_center_rc)),
                               "semi_axes_px": [sph.a, sph.b], "angle_rad": sph.angle_rad}}
    return BodyCenter(frame.to_observed(sph.body_center_rc), sph.radius_equivalent_px, None,
                      tuple(float(v) for v in sph.los), rng, ROUND_OUTPUTS, params,
                      numerical_jacobian(out, np.asarray(x0, float)), extras=extras)


def _ellipse_axes(a: float, rho: float, theta: float) -> tuple[float, float, float]:
    """``(a, rho, theta)`` with ``a >= b``: a fit may swap the axes."""
    if rho > 1.0:
        return a * rho, 1.0 / rho, theta + math.pi / 2
    return a, rho, theta


def _body_from_ellipse(pin: Camera, d: dict[str, float]) -> tuple[float, float]:
    """Body-centre image (ideal px) of a free ellipse ``(r0, c0, a, rho, theta)`` of a sphere (exact)."""

    a, rho, _ = _ellipse_axes(d["a"], d["rho"], 0.0)
    u, _ = sphere_from_ellipse(pin, (d["r0"], d["c0"]), (a, max(a * rho, 1e-9)), 1.0)
    bc = pin.project(u)
    return (float(bc[0]), float(bc[1]))


def free_ellipse_center(frame: Frame, fp: Any, free: tuple[str, ...]) -> BodyCenter:
    """The free elliptical sigmoid (``model="ellipse"``): the ellipse as fitted; with a camera the body
    centre of the sphere whose limb it is (exact), its line of sight and range.

    Parameters
    ----------
    frame : Frame
    fp : EllipseParams
        The fitted ESF (``r0, c0, a, theta, rho``; ideal pixels).
    free : tuple of str
        The fit's free parameters.

    Returns
    -------
    BodyCenter
        Outputs ``center_r, center_c, a, rho, theta`` and the ellipse (``a >= b``; observed pixels).
    """
    geo = tuple(n for n in ("r0", "c0", "a", "theta", "rho") if n in free)
    full = {n: float(getattr(fp, n)) for n in ("r0", "c0", "a", "theta", "rho")}
    a_, rho_, th_ = _ellipse_axes(full["a"], full["rho"], full["theta"])
    ellipse = EllipseResult(center_rc=frame.to_observed((full["r0"], full["c0"])), semi_axes_px=(a_, a_ * rho_),
                            angle_rad=float(th_ % math.pi))
    pin = frame.pin if frame.use_camera else None

    def out(x: np.ndarray) -> np.ndarray:
        d = {**full, **dict(zip(geo, x))}
        c = _body_from_ellipse(pin, d) if pin is not None else (d["r0"], d["c0"])
        return np.array([c[0], c[1], d["a"], d["rho"], d["theta"]])

    x0 = np.array([full[n] for n in geo])
    los = rng = None
    center = ellipse.center_rc
    if pin is not None:
        bc = _body_from_ellipse(pin, full)
        center = frame.to_observed(bc)
        los = tuple(float(v) for v in pin.los(np.array(bc)))
        if frame.body_radius_km is not None:
            b_ = a_ * rho_
            rng = float(frame.body_radius_km / math.sin(math.atan(b_ * b_ / (a_ * pin.focal_px))))
    return BodyCenter(center, None, ellipse, los, rng, ("center_r", "center_c", "a", "rho", "theta"), geo,
                      numerical_jacobian(out, x0))


__all__ = ["ROUND_OUTPUTS", "circle_center", "free_ellipse_center", "sphere_center"]
