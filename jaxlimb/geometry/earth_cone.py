r"""An image ellipse of the Earth (any spheroid) -> its cone of rays -> the observer's position.

Mortari, D'Souza & Zanetti, "Image Processing of Illuminated Ellipsoid" (J. Spacecraft and Rockets 53(3), 2016,
doi:10.2514/1.A33342), §III-IV: the fitted image ellipse is lifted back to its cone
``M_c \propto -K^T C K`` (:func:`image_ellipse_cone`); the eigenvector of the positive eigenvalue is the measured
cone axis ``v_c`` (the "ellipse-centre direction" of §IV) and ``b' = \sqrt{\lambda_3 / (\lambda_3 + |\lambda_2|)}``
(Eq. 8 written with eigenvalues).  With the pole known the range iteration of Fig. 2
(:func:`jaxlimb.geometry.earth.earth_range_iteration`) gives the position; without it the cone's major sine ``a'``
equals ``(Re + h)/|p|`` to 8.5e-5 (the equatorial diameter perpendicular to the meridian plane is always seen
whole), so ``p = -(Re + h)/a' v_c`` and the centre offset ``gamma_off`` cannot be signed (the spheroid seen from
latitude ``+phi`` and its mirror give the same cone): :func:`max_gamma_off` bounds it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ConfigError, ConvergenceError, GeometryError
from .camera import Camera
from .conic import ellipse_to_conic
from .earth import EARTH_EQUATORIAL_KM, EARTH_POLAR_KM, earth_range_iteration, gamma_off


@dataclass(frozen=True)
class EarthCone:
    """The limb cone of a measured image ellipse (camera frame), Eq. (3)-(8).

    Attributes
    ----------
    axis
        Unit cone axis ``v_c`` (camera frame, ``z > 0``): the "ellipse-centre direction".
    semi_axes
        ``(a', b')``, ``a' >= b'``: sines of the cone's half-angles (Eq. 8).
    major_dir, minor_dir
        Unit eigenvectors ``w_1``, ``w_2`` (camera frame) of the major and minor half-angles.
    """

    axis: np.ndarray
    semi_axes: tuple[float, float]
    major_dir: np.ndarray
    minor_dir: np.ndarray


def image_ellipse_cone(camera: Camera, center_rc, semi_axes_px, angle_rad: float) -> EarthCone:
    r"""Lift an image ellipse to its cone of rays and analyse it (Eq. 3-8).

    A pixel ``h = [col, row, 1]`` on the conic ``h^T C h = 0`` (negative inside) has the ray
    ``d = K^{-1} h``, so the rays satisfy ``d^T (K^T C K) d = 0``; ``M_c = -K^T C K`` is positive
    on rays that hit the body, with eigenvalues of signs ``(-, -, +)`` (§III-A).  Sorting the
    negative ones by magnitude, ``a' = (1 + |\lambda_1|/\lambda_3)^{-1/2}``,
    ``b' = (1 + |\lambda_2|/\lambda_3)^{-1/2}`` (Eq. 8 with ``\xi_i = |\lambda_i|^{-1/2}``).

    Raises
    ------
    GeometryError
        Not an ellipse, or an eigen-structure other than ``(-, -, +)``.
    ConfigError
        A camera with lens distortion (the limb is then not a conic in the image).
    """
    if camera.has_distortion:
        raise ConfigError(
            "the Earth pipeline fits the limb as an image ellipse and needs a pinhole camera; "
            f"got distortion (k1, k2, k3, p1, p2) = {camera.distortion}"
        )
    C = ellipse_to_conic(center_rc, semi_axes_px, angle_rad)
    K = camera.K
    lam, axis, a_, b_, V = cone_eigen(-(K.T @ C @ K))
    if not (lam[0] < 0 and lam[1] < 0 and lam[2] > 0):
        raise GeometryError(f"image ellipse does not define a limb cone: eigenvalues {lam.tolist()} (need -, -, +)")
    return EarthCone(axis=axis, semi_axes=(float(a_), float(b_)), major_dir=V[:, 1].copy(), minor_dir=V[:, 0].copy())


def cone_eigen(M: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eigen-analysis (Eq. 8) of limb cones ``M`` ``(..., 3, 3)``, positive on the rays that hit the body: the
    ascending eigenvalues, the unit axis (``z > 0``), the sines ``a' >= b'`` of the half-angles and the eigenvectors
    (columns; ``[..., :, 1]`` the major direction, ``[..., :, 0]`` the minor one).  Signs are not checked."""
    lam, V = np.linalg.eigh(0.5 * (M + np.swapaxes(M, -1, -2)))
    axis = V[..., :, 2] * np.where(V[..., 2, 2] > 0, 1.0, -1.0)[..., None]
    # lam ascending: lam[0] is the most negative (minor half-angle), lam[1] the major one
    with np.errstate(invalid="ignore", divide="ignore"):  # not a cone (lam[2] <= 0): NaN, refused by the callers
        a_ = 1.0 / np.sqrt(1.0 + np.abs(lam[..., 1]) / lam[..., 2])
        b_ = 1.0 / np.sqrt(1.0 + np.abs(lam[..., 0]) / lam[..., 2])
    return lam, axis, a_, b_, V


def earth_position_from_ellipse(
    camera: Camera,
    center_rc,
    semi_axes_px,
    angle_rad: float,
    p0_camera_km,
    *,
    pole_camera=None,
    equatorial_km: float = EARTH_EQUATORIAL_KM,
    polar_km: float = EARTH_POLAR_KM,
    atmosphere_km: float = 0.0,
    eps_rad: float = 1e-13,
    max_iter: int = 20,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Observer position relative to the Earth centre (camera frame, km) from its image ellipse.

    With ``pole_camera`` (the spin axis in the camera frame, ``R_body_to_camera[:, 2]``): steps 4-5
    of the module docstring (cone, ``gamma_off``, range iteration of Fig. 2 from ``p0_camera_km``).
    Without it: the free-ellipse inversion ``p = -(Re + h)/a' v_c`` (module docstring).

    Returns
    -------
    p, info
        ``p`` (observer - Earth centre, camera frame) and ``{"iterations", "converged",
        "gamma_off_rad", "b_prime", "a_prime", "cone"}``.

    Raises
    ------
    GeometryError
        Bad ellipse, prior inside the Earth, or the iteration did not converge.
    """
    cone = image_ellipse_cone(camera, center_rc, semi_axes_px, angle_rad)
    a_, b_ = cone.semi_axes
    Re = equatorial_km + atmosphere_km
    if pole_camera is None:
        rng = Re / a_
        return -rng * cone.axis, {"iterations": 0, "converged": True, "gamma_off_rad": 0.0, "a_prime": a_, "b_prime": b_, "cone": cone}
    fix = earth_range_iteration(
        cone.axis, b_, p0_camera_km, atmosphere_km=atmosphere_km, pole=pole_camera, eps=eps_rad, max_iter=max_iter,
        equatorial_km=equatorial_km, polar_km=polar_km,
    )
    if not fix.converged:
        raise ConvergenceError(
            f"Earth range iteration did not reach |dtheta_hat - dtheta_tilde| < {eps_rad:g} rad in {max_iter} updates "
            f"(last {fix.history[-1][1]:.3g} rad)"
        )
    return fix.position_km, {
        "iterations": fix.iterations, "converged": True, "gamma_off_rad": fix.gamma_off_rad,
        "a_prime": a_, "b_prime": b_, "cone": cone,
    }


def max_gamma_off(range_km: float, equatorial_km: float, polar_km: float, atmosphere_km: float) -> float:
    """The largest unsigned offset ``|gamma_off|`` (rad, :func:`earth_gamma_off`) over the observer's latitude
    0-90 deg at ``range_km`` (2 deg grid; ~0.3 px at 40 000 km with an 8 mm / 2.2 um imager, 0.007 px at
    385 000 km with 16 mm)."""
    lats = np.radians(np.arange(0.0, 90.1, 2.0))
    return max(abs(gamma_off(range_km * np.array([math.cos(t), 0.0, math.sin(t)]), atmosphere_km,
                                   equatorial_km=equatorial_km, polar_km=polar_km)) for t in lats)


__all__ = ["EarthCone", "cone_eigen", "earth_position_from_ellipse", "image_ellipse_cone", "max_gamma_off"]
