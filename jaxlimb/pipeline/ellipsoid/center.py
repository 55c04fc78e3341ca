"""The ellipsoid's body-centre mapping: the range iteration from the final fit's ellipse, its central-difference
Jacobian, and with a free ellipse the unsigned centre offset (or the Sun's declination bound on the pole) as model
error."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ...geometry.camera import Camera
from ...geometry.earth_cone import max_gamma_off
from ...numerics import numerical_jacobian
from ..result import EllipseResult
from ..stages import BodyCenter, Frame, RefineResult
from .model import EllipsoidModel, as_ellipse, position
from .pole_prior import FREE_ELLIPSE, marginal_center


def ellipsoid_center(body: EllipsoidModel, frame: Frame, final: RefineResult) -> BodyCenter:
    """Stage "body-centre mapping" of the ellipsoid: the range iteration (Mortari et al. 2016 §IV, Fig. 2) from the
    final fit's ellipse and its central-difference Jacobian; outputs ``center_r, center_c, range_km, a`` (and
    ``rho, theta`` when free).  With a free ellipse the unsigned centre offset is a model error
    (:func:`unsigned_offset_cov`), or the centre is marginalised over the poles the Sun's declination bound allows.

    Parameters
    ----------
    body : EllipsoidModel
        The spheroid, its orientation and whether the ellipse is free.
    frame : Frame
        The frame: camera (required) and hints.
    final : RefineResult
        The final fit (edge or profile), whose ``r0, c0, a, rho, theta`` give the limb ellipse.

    Returns
    -------
    BodyCenter
        The body centre's image ``(row, col)`` (px), the limb ellipse, the line of sight (camera frame), the range
        (km), the Jacobian of the outputs by the fit's geometric parameters, the model-error covariance (free
        ellipse) and the ``gamma_off``, ``a'``, ``b'`` of the cone in ``extras``.
    """
    cam, P = frame.cam, final.fit.params
    fitted = as_ellipse(P)
    p, info = position(body, cam, fitted, frame_position_start(final, body, cam, fitted))
    geo = ("r0", "c0", "a") + (("rho", "theta") if body.free else ())
    outputs = ("center_r", "center_c", "range_km") + geo[2:]

    def g(x: np.ndarray) -> np.ndarray:
        q = P.replace(**dict(zip(geo, (float(v) for v in x))))
        pp, _ = position(body, cam, as_ellipse(q), p)
        rc = cam.project(-pp)
        return np.concatenate([[rc[0], rc[1], np.linalg.norm(pp)], x[2:]])

    x0 = np.array([float(getattr(P, n)) for n in geo])
    G = numerical_jacobian(g, x0, np.array([1e-3, 1e-3, 1e-3, 1e-5, 1e-4][: len(geo)]))
    rng = float(np.linalg.norm(p))
    model_cov, goff = None, 0.0
    center, los, pole_report = cam.project(-p), -p / rng, None
    if body.free:
        model_cov, goff = unsigned_offset_cov(cam, fitted, rng, body.equatorial_km, body.polar_km, body.atmosphere_km,
                                              len(outputs))
        marg = _pole_marginal(body, frame, final, p)
        if marg is not None:
            center, model_cov[:2, :2], pole_report = marg
            los = cam.los(np.asarray(center, float))
    (c, (a, b), th) = fitted
    model = {"LimbProfileParams": "lunar_limb", "GlowProfileParams": "lunar_limb_glow", "AnisoProfileParams": "lunar_limb_aniso",
             "EllipseRampParams": "ellipse_ramp"}.get(type(P).__name__, "ellipse")
    extras = {"model": model, "ellipse_center_rc": list(c), "rho": b / a, "theta_rad": th, "gamma_off_rad": float(info["gamma_off_rad"]),
              "gamma_off_unsigned_model_rad": goff, "a_prime": info["a_prime"], "b_prime": info["b_prime"]}
    if pole_report is not None:
        extras["pole_prior"] = pole_report
    return BodyCenter(tuple(float(v) for v in center), None,
                      EllipseResult(center_rc=c, semi_axes_px=(a, b), angle_rad=th), tuple(float(v) for v in los),
                      rng, outputs, geo, G, model_cov, extras)


def _pole_marginal(body: EllipsoidModel, frame: Frame, final: RefineResult, p: np.ndarray) -> tuple | None:
    """The free ellipse's body centre marginalised over the poles the Sun's declination bound allows
    (``EllipsoidOptions.sun_declination_max_deg``, :func:`jaxlimb.pipeline.ellipsoid.pole_prior.marginal_center`): its image,
    covariance and a report; ``None`` when the option is off, the pole is known, the Sun unknown or no pole fits."""

    dmax, sun = body.eo.sun_declination_max_deg, frame.hints.sun_dir_camera
    free = list(final.fit.free)
    if dmax is None or body.R is not None or sun is None or not all(n in free for n in FREE_ELLIPSE):
        return None
    idx = [free.index(n) for n in FREE_ELLIPSE]
    C = np.asarray(final.fit.covariance, float)[np.ix_(idx, idx)]
    Re, Rp = body.radii_limb[0], body.radii_limb[2]
    out = marginal_center(frame.cam, final.fit.params, C, -p, sun, math.sin(math.radians(dmax)), Re, Rp)
    if out is None:
        return None
    mean, cov, rep = out
    return mean, cov, {**rep, "sun_declination_max_deg": float(dmax)}


def frame_position_start(final: RefineResult, body: EllipsoidModel, cam: Camera, fitted: tuple) -> np.ndarray:
    """The range iteration's start: the free-ellipse position of ``fitted`` (``(Re + h) / a'`` along the cone axis).

    Parameters
    ----------
    final : RefineResult
        The final fit (unused).
    body : EllipsoidModel
        The spheroid and limb height.
    cam : Camera
        The pinhole camera.
    fitted : tuple
        The ellipse ``((r0, c0), (a, b), theta)`` (px, rad).

    Returns
    -------
    np.ndarray (3,)
        Observer minus body centre (km, camera frame).
    """
    free = replace(body, R=None, free=True)
    return position(free, cam, fitted, np.zeros(3))[0]


def unsigned_offset_cov(camera: Camera, fitted: tuple, range_km: float, equatorial_km: float, polar_km: float,
                        atmosphere_km: float, n_out: int) -> tuple[np.ndarray, float]:
    """The free ellipse's unsigned centre offset as a model error: a uniform error ``+-gamma_off`` along the
    image of the polar axis, ``var = gamma_off^2 / 3`` px^2, in every direction (the fitted ellipse's minor axis
    is no measure of that axis: ``a - b`` is ~0.3 % of ``a``), with ``gamma_off`` its largest value over the
    observer's latitude (:func:`~jaxlimb.geometry.earth_cone.max_gamma_off`).  The latitude is not taken from the
    fitted axis ratio: on a lit arc that ratio is not measured well enough and comes out near 1 (pole-on, no offset).

    Parameters
    ----------
    camera : Camera
        The camera (``focal_px`` converts the angle to px).
    fitted : tuple
        The fitted ellipse (unused: the bound does not depend on its shape).
    range_km : float
        The range to the body centre (km).
    equatorial_km, polar_km : float
        The spheroid's radii (km).
    atmosphere_km : float
        The limb's height above the surface (km).
    n_out : int
        The number of outputs of the body-centre map.

    Returns
    -------
    cov : np.ndarray (n_out, n_out)
        Zero but for its ``center_r, center_c`` block (px^2).
    gamma_off : float
        The bound on the offset angle (rad).
    """
    del fitted  # the bound does not depend on the fitted shape (docstring)
    goff = max_gamma_off(range_km, equatorial_km, polar_km, atmosphere_km)
    s_px = goff * camera.focal_px
    out = np.zeros((n_out, n_out))
    out[:2, :2] = (s_px**2 / 3.0) * np.eye(2)
    return out, goff


__all__ = ["ellipsoid_center", "frame_position_start", "unsigned_offset_cov"]
