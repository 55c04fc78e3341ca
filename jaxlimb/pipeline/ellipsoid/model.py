"""What the ellipsoid strategy knows of its body (:class:`EllipsoidModel`: options, spheroid, orientation, free or
predicted shape) and the map from a fitted image ellipse to the observer's position (Mortari et al. 2016, §IV)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ...errors import ConfigError, ConvergenceError, GeometryError, LimbInputError
from ...fitting import solver_from_name
from ...geometry.camera import Camera
from ...geometry.bodies import BODY_TABLE
from ...geometry.earth import EARTH_EQUATORIAL_KM, EARTH_POLAR_KM
from ...geometry.earth_cone import earth_position_from_ellipse
from ...geometry.ellipsoid import check_rotation, image_conic
from ...geometry.hints import Hints
from ..options import EllipsoidOptions
from ..stages import Frame


#: Fits (edge and profile) with ``rho, theta`` predicted from the latest position, at most ...
MAX_REFITS = 3
#: ... until the newly predicted ellipse differs from the fitted one by less than this (px, at the semi-major axis).
REFIT_TOL_PX = 2e-3


@dataclass(frozen=True)
class EllipsoidModel:
    """What the ellipsoid strategy knows of the body: its options, the spheroid (equatorial and polar radii, the
    limb's height above them), its orientation ``R`` (body-fixed -> camera, ``None``: unknown) and whether the
    ellipse's shape is fitted (``free``) or predicted from the limb cone."""

    eo: EllipsoidOptions
    equatorial_km: float
    polar_km: float
    atmosphere_km: float
    R: np.ndarray | None
    free: bool

    @classmethod
    def for_frame(cls, frame: Frame) -> "EllipsoidModel":
        """Validate what the ellipsoid needs (camera, spheroid radii, rotation) and refuse what it cannot honour.

        Parameters
        ----------
        frame : Frame
            The validated inputs; the hints default to the Earth's (WGS-84, no attitude).

        Returns
        -------
        EllipsoidModel
            The body; its ellipse is free when ``R_body_to_camera`` is unknown or ``model="ellipse"``.

        Raises
        ------
        ConfigError
            No camera, ``estimate_k=False`` or the limb-darkened profile.
        GeometryError
            The body is not a spheroid (``body_radii_km[0] != body_radii_km[1]``).
        """
        opt, h = frame.opt, frame.hints
        if frame.cam is None:
            raise ConfigError("the ellipsoid strategy (a spheroid: the Earth, a giant planet) needs a camera (`camera`; "
                              "the CLI's --camera): it measures the range")
        if not opt.estimate_k:
            raise ConfigError("estimate_k = False (the papers' fixed-k sphere setting) is not available for the "
                              "ellipsoid: its edge model estimates the kernel with the interior ramp")
        if opt.profile == "limb-darkened":
            raise ConfigError("profile = 'limb-darkened' is the disc strategy's (the Sun), not the ellipsoid's")
        eo = opt.ellipsoid_options
        h = h if h is not None else earth_hints()
        Re, Rp, atm = spheroid(h)
        R = None if h.R_body_to_camera is None else check_rotation(np.asarray(h.R_body_to_camera), "R_body_to_camera",
                                                                   tol=1e-6)
        return cls(eo, Re, Rp, atm, R, opt.model == "ellipse" or R is None)


    @property
    def radii_limb(self) -> np.ndarray:
        a, c, h = self.equatorial_km, self.polar_km, self.atmosphere_km
        return np.array([a + h, a + h, c + h])

    @property
    def pole(self) -> np.ndarray | None:
        return None if (self.free or self.R is None) else self.R[:, 2]

    def solver(self, frame: Frame):  # noqa: ANN201
        """The chosen solver object, ``None`` for the default (``lm``).

        Parameters
        ----------
        frame : Frame
            The frame whose options name the solver.

        Returns
        -------
        solver or None
            The solver of :func:`~jaxlimb.fitting.solver_from_name`, or ``None``.
        """
        return None if frame.opt.solver == "lm" else solver_from_name(frame.opt.solver)

    def predicted_shape(self, cam: Camera, center_km: np.ndarray) -> tuple[float, float]:
        """``(rho, theta)`` of the limb spheroid's image ellipse with its centre at ``center_km`` (camera frame):
        the limb cone and its image conic (Mortari et al. 2016 Eq. 2-9,
        :func:`~jaxlimb.geometry.ellipsoid.image_conic`).

        Parameters
        ----------
        cam : Camera
            The pinhole camera.
        center_km : np.ndarray (3,)
            The body centre (km, camera frame).

        Returns
        -------
        rho : float
            Axis ratio ``b / a`` of the image ellipse.
        theta : float
            Orientation of its major axis (rad).
        """
        ic = image_conic(cam, self.radii_limb, center_km, self.R)
        return float(ic.rho), float(ic.angle_rad)


def earth_hints(h: Any = None) -> Any:
    """Hints that name the Earth.

    Parameters
    ----------
    h : Hints or None
        Hints to complete (``None``: none given).

    Returns
    -------
    Hints
        ``h`` with ``body="earth"``, or hints holding only that.
    """

    return Hints(body="earth") if h is None else replace(h, body="earth")


def as_ellipse(P: Any) -> tuple:
    """The fitted ellipse ``((r0, c0), (a, b), theta)`` with ``a >= b``, ``theta`` in ``[0, pi)``.

    Parameters
    ----------
    P : EllipseParams or a profile's parameters
        Fitted parameters with ``r0, c0, a, rho, theta`` (px, rad).

    Returns
    -------
    tuple
        ``((r0, c0), (a, b), theta)`` (px, rad).

    Raises
    ------
    ConvergenceError
        ``a`` or ``rho`` not positive.
    """
    a, rho, th = float(P.a), float(P.rho), float(P.theta)
    if a <= 0 or rho <= 0:
        raise ConvergenceError(f"the elliptical edge fit gave a non-physical ellipse: a = {a}, rho = {rho}")
    b = rho * a
    if b > a:  # a free fit may swap the axes: keep a >= b, theta along a
        a, b, th = b, a, th + math.pi / 2
    return ((float(P.r0), float(P.c0)), (a, b), th % math.pi)


def position(body: EllipsoidModel, cam: Camera, fitted: tuple, p0: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
    """The observer position from a fitted ellipse (range iteration, Mortari et al. 2016 §IV, Fig. 2,
    :func:`~jaxlimb.geometry.earth_cone.earth_position_from_ellipse`); no convergence is a failed check.

    Parameters
    ----------
    body : EllipsoidModel
        The spheroid, limb height and pole (``None`` when free: ``p = -(Re + h) / a' v_c``).
    cam : Camera
        The pinhole camera.
    fitted : tuple
        The ellipse ``((r0, c0), (a, b), theta)`` (px, rad).
    p0 : np.ndarray (3,)
        Start of the iteration (km, camera frame).

    Returns
    -------
    p : np.ndarray (3,)
        Observer minus body centre (km, camera frame).
    info : dict
        ``iterations``, ``converged``, ``gamma_off_rad``, ``a_prime``, ``b_prime`` and the cone.

    Raises
    ------
    ConvergenceError
        The iteration does not converge or the ellipse gives no limb cone.
    """
    try:
        return earth_position_from_ellipse(
            cam, *fitted, p0, pole_camera=body.pole, equatorial_km=body.equatorial_km, polar_km=body.polar_km,
            atmosphere_km=body.atmosphere_km)
    except ConvergenceError:
        raise
    except LimbInputError as e:  # a bad ellipse (no limb cone): not a measurement of this body
        raise ConvergenceError(f"the fitted ellipse does not give a position: {e}") from None


# =============================================================================== ellipse -> position
def spheroid(hints: Hints) -> tuple[float, float, float]:
    """The spheroid the hints name.

    Parameters
    ----------
    hints : Hints
        ``body_radii_km`` (default: the named body's, :data:`~jaxlimb.geometry.bodies.BODY_TABLE`, else WGS-84) and
        ``atmosphere_km`` (default 0: the limb height is the Earth's clouds or haze only when the hints say so).

    Returns
    -------
    tuple of float
        ``(equatorial_km, polar_km, atmosphere_km)``.

    Raises
    ------
    GeometryError
        The first two radii differ (not a spheroid).
    """
    radii = hints.body_radii_km
    if radii is None and hints.body is not None and hints.body in BODY_TABLE:
        radii = BODY_TABLE[hints.body].radii_km
    if radii is None:
        radii = (EARTH_EQUATORIAL_KM, EARTH_EQUATORIAL_KM, EARTH_POLAR_KM)
    a, b, c = (float(v) for v in radii)
    if abs(a - b) > 1e-9 * a:
        raise GeometryError(
            f"the ellipsoid strategy needs a spheroid with body_radii_km[0] == body_radii_km[1], got {list(radii)}"
        )
    h = float(hints.atmosphere_km or 0.0)
    return a, c, h


__all__ = ["EllipsoidModel", "as_ellipse", "earth_hints", "position", "spheroid"]
