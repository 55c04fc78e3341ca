r"""Error propagation of §7.1 of the Aerospace 2015 Moon paper (Eq. 36-39, Fig. 18).

Source: the Aerospace 2015 (vol. 2) Moon image-processing paper (gradient, RANSAC, circular
sigmoid), ``/work/shared/papers/aerospace-2015-moon-gradient-ransac-csf.md``.
Notation: ``f`` focal length and ``d`` pixel pitch (same unit), ``f_px = f/d``; ``R`` body
radius; ``D`` range; ``r`` apparent radius (px).

Eq. 36  ``r = (f/d) R / sqrt(D^2 - R^2)``  (= ``f_px tan(asin(R/D))``, exact on the boresight)
Eq. 37  ``sigma_r = |dr/dD| sigma_D = f_px D R / (D^2 - R^2)^{3/2} sigma_D``
Eq. 38  ``sigma_D = (D^2 - R^2)^{3/2} / (f_px D R) sigma_r``  (first-order inverse of Eq. 37)
Eq. 39  ``sigma_c = f_px sigma_theta / cos^2(theta)``  (radial image error of the centre at
        angle ``theta`` from the boresight for an attitude error ``sigma_theta``)

Checks against the paper (each shown by a test in ``tests/analysis/test_error_propagation.py``)
-------------------------------------------------------------------------------------------
1. Eq. 36-38 are right (derivative checked against Monte Carlo of the exact model), but
   only to first order: when ``sigma_r / r`` is not small (Moon near 350 000 km, ``r`` ≈ 36 px
   on the 16 mm camera) the true range scatter exceeds Eq. 38 and the inverse is biased
   long by ≈ ``D (sigma_r/r)^2``; :func:`monte_carlo_range_sigma` measures it.
2. "``r ~ N(r̄, sigma_r û)``, ``û`` uniformly distributed in the unit sphere ... ``sigma_D =
   sigma_r``": with ``û`` uniform on the unit sphere the range (radial) component has standard
   deviation ``sigma_r/sqrt(3)`` (``sigma_r sqrt(3/5)/sqrt(3) = sigma_r/sqrt(5)`` inside the unit
   ball), not ``sigma_r``.  ``sigma_D = sigma_r`` holds for an isotropic Gaussian with per-axis
   ``sigma_r`` (:func:`range_sigma_from_position_sigma`).
3. Eq. 39 gives only the radial component.  The tangential component is
   ``f_px sigma_theta / cos(theta)`` (smaller off-axis, equal on the boresight), so the centre
   error is not isotropic: :func:`center_covariance_from_attitude` gives the 2x2 covariance.
4. Eq. 39 is printed with ``sigma_q / q̄`` and the attitude as ``q ~ N(q̄, 2 sigma_q û)``.  The
   small rotation angle is twice the quaternion vector-part error: a per-axis quaternion
   error ``sigma_q`` is an angle error ``sigma_theta = 2 sigma_q``
   (:func:`angle_sigma_from_quaternion_sigma`); reading Eq. 39 with ``sigma_q`` itself
   underestimates ``sigma_c`` by 2.  We use the rotation-angle sigma throughout.
5. The text lists Fig. 18's distances as 50 000, 150 000, 250 000 "and 35 000" km; the regular
   spacing says 350 000 km (a typo) -- :func:`figure18_data` uses 350 000 km.
6. The paper's ``R_m = 1737.5`` km; docs/design.md fixes 1737.4 km (0.006 % -- negligible).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import GeometryError
from ..geometry.attitude import rotation_vector_to_dcm
from ..geometry.camera import Camera

MOON_RADIUS_KM = 1737.4
FIG18_DISTANCES_KM = (50_000.0, 150_000.0, 250_000.0, 350_000.0)


def _fpx(camera: Camera | None) -> float:
    return (camera or Camera()).focal_px


def _check_range(D, R) -> np.ndarray:
    D = np.asarray(D, dtype=float)
    if not (np.isfinite(R) and R > 0):
        raise GeometryError(f"`body_radius_km` must be finite and > 0, got {R!r}")
    if np.any(~np.isfinite(D)) or np.any(D <= R):
        raise GeometryError(f"`range_km` must be finite and > body radius {R} km (observer outside), got {D.tolist()}")
    return D


def radius_px(range_km, camera: Camera | None = None, body_radius_km: float = MOON_RADIUS_KM):
    """Eq. 36: apparent radius ``r = f_px R / sqrt(D^2 - R^2)`` (px) on the boresight.

    Parameters
    ----------
    range_km : float or np.ndarray
        Range ``D`` from the camera to the body centre (km), greater than ``body_radius_km``.
    camera : Camera, optional
        Gives ``f_px`` (focal length over pixel pitch); default ``Camera()``, the papers' 16 mm / 2.2 um.
    body_radius_km : float
        Radius ``R`` of the spherical body (km); default the Moon's.

    Returns
    -------
    float or np.ndarray
        Apparent radius ``r`` (px), the shape of ``range_km``.

    Raises
    ------
    GeometryError
        ``range_km`` not finite or not beyond the body radius.
    """
    D = _check_range(range_km, body_radius_km)
    return _fpx(camera) * body_radius_km / np.sqrt(D**2 - body_radius_km**2)


def range_from_radius(radius, camera: Camera | None = None, body_radius_km: float = MOON_RADIUS_KM):
    """Inverse of Eq. 36: ``D = R sqrt(1 + f_px^2 / r^2)`` (= ``R / sin(atan(r/f_px))``).

    Parameters
    ----------
    radius : float or np.ndarray
        Apparent radius ``r`` (px), > 0.
    camera : Camera, optional
        Gives ``f_px``; default ``Camera()``.
    body_radius_km : float
        Radius ``R`` of the spherical body (km).

    Returns
    -------
    float or np.ndarray
        Range ``D`` to the body centre (km), the shape of ``radius``.
    """
    r = np.asarray(radius, dtype=float)
    if np.any(~np.isfinite(r)) or np.any(r <= 0):
        raise GeometryError(f"`radius` must be finite and > 0 px, got {r.tolist()}")
    return body_radius_km * np.sqrt(1.0 + (_fpx(camera) / r) ** 2)


def radius_sigma_from_range_sigma(range_km, sigma_range_km, camera: Camera | None = None, body_radius_km: float = MOON_RADIUS_KM):
    """Eq. 37: ``sigma_r = f_px D R / (D^2 - R^2)^{3/2} sigma_D`` (px).

    Parameters
    ----------
    range_km : float or np.ndarray
        Range ``D`` to the body centre (km).
    sigma_range_km : float or np.ndarray
        Range standard deviation ``sigma_D`` (km); broadcast against ``range_km``.
    camera : Camera, optional
        Gives ``f_px``; default ``Camera()``.
    body_radius_km : float
        Radius ``R`` of the spherical body (km).

    Returns
    -------
    float or np.ndarray
        Apparent-radius standard deviation ``sigma_r`` (px), to first order.
    """
    D = _check_range(range_km, body_radius_km)
    R = body_radius_km
    return _fpx(camera) * D * R / (D**2 - R**2) ** 1.5 * np.asarray(sigma_range_km, dtype=float)


def range_sigma_from_radius_sigma(range_km, sigma_radius_px, camera: Camera | None = None, body_radius_km: float = MOON_RADIUS_KM):
    """Eq. 38: ``sigma_D = (D^2 - R^2)^{3/2} / (f_px D R) sigma_r`` (km), first order.

    Parameters
    ----------
    range_km : float or np.ndarray
        Range ``D`` to the body centre (km).
    sigma_radius_px : float or np.ndarray
        Apparent-radius standard deviation ``sigma_r`` (px); broadcast against ``range_km``.
    camera : Camera, optional
        Gives ``f_px``; default ``Camera()``.
    body_radius_km : float
        Radius ``R`` of the spherical body (km).

    Returns
    -------
    float or np.ndarray
        Range standard deviation ``sigma_D`` (km); :func:`monte_carlo_range_sigma` shows where first order
        falls short.
    """
    D = _check_range(range_km, body_radius_km)
    R = body_radius_km
    return (D**2 - R**2) ** 1.5 / (_fpx(camera) * D * R) * np.asarray(sigma_radius_px, dtype=float)


def center_sigma_from_attitude(theta_rad, sigma_angle_rad, camera: Camera | None = None):
    """Eq. 39 (radial): ``sigma_c = f_px sigma_theta / cos^2(theta)`` (px).

    Parameters
    ----------
    theta_rad : float or np.ndarray
        Angle of the body centre from the boresight (radians), in ``(-pi/2, pi/2)``.
    sigma_angle_rad : float or np.ndarray
        Per-axis rotation-angle error of the attitude (radians); for a quaternion sigma use
        :func:`angle_sigma_from_quaternion_sigma`.
    camera : Camera, optional
        Gives ``f_px``; default ``Camera()``.

    Returns
    -------
    float or np.ndarray
        Radial standard deviation of the centre in the image (px); the tangential one is
        ``f_px sigma / cos(theta)`` (:func:`center_covariance_from_attitude`).
    """
    th = np.asarray(theta_rad, dtype=float)
    if np.any(np.abs(th) >= np.pi / 2):
        raise GeometryError(f"`theta_rad` must be in (-pi/2, pi/2) (in front of the camera), got {th.tolist()}")
    return _fpx(camera) * np.asarray(sigma_angle_rad, dtype=float) / np.cos(th) ** 2


def center_covariance_from_attitude(theta_rad: float, sigma_angle_rad: float, camera: Camera | None = None) -> np.ndarray:
    """2x2 (radial, tangential) image covariance (px^2) of the centre for an isotropic attitude error.

    Derivation: LOS ``u = (sin t, 0, cos t)`` (radial = x).  A rotation ``dphi`` moves it by
    ``dphi x u``: about y (perpendicular to boresight and LOS) changes ``t`` -> radial
    ``f dphi_y / cos^2 t``; about z moves it tangentially by ``f tan(t) dphi_z``; about x moves
    ``y/z`` by ``dphi_x`` -> tangential ``f dphi_x``.  Hence ``var_tan = f^2 s^2 (1 + tan^2 t)``.

    Parameters
    ----------
    theta_rad : float
        Angle of the body centre from the boresight (radians).
    sigma_angle_rad : float
        Per-axis rotation-angle error of the attitude (radians).
    camera : Camera, optional
        Gives ``f_px``; default ``Camera()``.

    Returns
    -------
    np.ndarray (2, 2)
        Diagonal covariance (px^2): radial ``(f_px s / cos^2 t)^2`` (Eq. 39), tangential ``(f_px s / cos t)^2``.
    """
    f = _fpx(camera)
    c = np.cos(float(theta_rad))
    return np.diag([(f * sigma_angle_rad / c**2) ** 2, (f * sigma_angle_rad / c) ** 2])


def angle_sigma_from_quaternion_sigma(sigma_q: float) -> float:
    """Per-axis rotation-angle sigma of a per-axis quaternion vector-part sigma: ``2 sigma_q``.

    Parameters
    ----------
    sigma_q : float
        Standard deviation of each component of the quaternion's vector part (check 4 of the module docstring).

    Returns
    -------
    float
        Rotation-angle standard deviation (radians), ``2 sigma_q``.
    """
    return 2.0 * float(sigma_q)


def range_sigma_from_position_sigma(sigma_position_km: float, model: str = "gaussian") -> float:
    """Range sigma implied by an isotropic position error (see check 2 of the module docstring).

    Parameters
    ----------
    sigma_position_km : float
        Scale ``sigma`` of the position error (km).
    model : {"gaussian", "sphere", "ball"}
        ``"gaussian"``: per-axis standard deviation ``sigma``; ``"sphere"``: ``sigma * û`` with ``û`` uniform on
        the unit sphere; ``"ball"``: ``û`` uniform in the unit ball.

    Returns
    -------
    float
        Range standard deviation (km): ``sigma``, ``sigma/sqrt(3)`` or ``sigma/sqrt(5)``.

    Raises
    ------
    GeometryError
        An unknown ``model``.
    """
    s = float(sigma_position_km)
    if model == "gaussian":
        return s
    if model == "sphere":
        return s / np.sqrt(3.0)
    if model == "ball":
        return s / np.sqrt(5.0)
    raise GeometryError(f"`model` must be 'gaussian', 'sphere' or 'ball', got {model!r}")


@dataclass(frozen=True)
class Figure18:
    """Data of Fig. 18 of the 2015 paper: ``sigma_D[i, j]`` (km) for ``distances_km[i]``, ``sigma_r_px[j]``."""

    distances_km: np.ndarray
    sigma_r_px: np.ndarray
    sigma_D_km: np.ndarray
    radius_px: np.ndarray
    focal_px: float
    body_radius_km: float


def figure18_data(
    sigma_r_px=np.linspace(0.0, 1.0, 21),
    distances_km=FIG18_DISTANCES_KM,
    camera: Camera | None = None,
    body_radius_km: float = MOON_RADIUS_KM,
) -> Figure18:
    """Eq. 38 on a grid: Moon-distance error vs radius error for the four distances of Fig. 18.

    Also usable as "sigma_D vs distance for a given sigma_r" by passing a dense
    ``distances_km`` and a single ``sigma_r_px``.

    Parameters
    ----------
    sigma_r_px : np.ndarray (m,)
        Apparent-radius standard deviations (px), finite and >= 0.
    distances_km : sequence of float (k,)
        Ranges to the Moon centre (km); default 50 000 to 350 000 km (module docstring, check 5).
    camera : Camera, optional
        Gives ``f_px``; default ``Camera()``, the papers' 16 mm / 2.2 um.
    body_radius_km : float
        Radius of the spherical body (km).

    Returns
    -------
    Figure18
        ``sigma_D_km`` of shape ``(k, m)``, with the apparent radius at each distance.
    """
    D = _check_range(np.atleast_1d(distances_km), body_radius_km)
    s = np.atleast_1d(np.asarray(sigma_r_px, dtype=float))
    if np.any(s < 0) or np.any(~np.isfinite(s)):
        raise GeometryError(f"`sigma_r_px` must be finite and >= 0, got {s.tolist()}")
    sig = range_sigma_from_radius_sigma(D[:, None], s[None, :], camera, body_radius_km)
    return Figure18(
        distances_km=D,
        sigma_r_px=s,
        sigma_D_km=sig,
        radius_px=radius_px(D, camera, body_radius_km),
        focal_px=_fpx(camera),
        body_radius_km=body_radius_km,
    )


@dataclass(frozen=True)
class RangeMonteCarlo:
    """Monte Carlo of the exact model ``D = R sqrt(1 + f^2/r^2)`` with ``r = r(D) + N(0, sigma_r)``."""

    std_km: float
    bias_km: float
    linear_sigma_km: float
    n_trials: int


def monte_carlo_range_sigma(
    range_km: float,
    sigma_radius_px: float,
    n_trials: int = 20_000,
    seed: int = 0,
    camera: Camera | None = None,
    body_radius_km: float = MOON_RADIUS_KM,
) -> RangeMonteCarlo:
    """Sample the apparent radius, invert Eq. 36 exactly, compare to Eq. 38.

    Parameters
    ----------
    range_km : float
        True range to the body centre (km).
    sigma_radius_px : float
        Standard deviation of the Gaussian error added to the exact apparent radius (px).
    n_trials : int
        Number of samples.
    seed : int
        Seed of ``numpy.random.default_rng``.
    camera : Camera, optional
        Gives ``f_px``; default ``Camera()``.
    body_radius_km : float
        Radius of the spherical body (km).

    Returns
    -------
    RangeMonteCarlo
        Sample standard deviation and bias of the inverted range (km) beside the Eq. 38 sigma.

    Raises
    ------
    GeometryError
        A drawn radius is not positive (``sigma_radius_px`` too large for this range).
    """
    rng = np.random.default_rng(seed)
    r0 = float(radius_px(range_km, camera, body_radius_km))
    r = r0 + sigma_radius_px * rng.standard_normal(n_trials)
    if np.any(r <= 0):
        raise GeometryError(f"sigma_radius_px {sigma_radius_px} too large for r = {r0:.3f} px: negative radii drawn")
    D = range_from_radius(r, camera, body_radius_km)
    return RangeMonteCarlo(
        std_km=float(np.std(D, ddof=1)),
        bias_km=float(np.mean(D) - range_km),
        linear_sigma_km=float(range_sigma_from_radius_sigma(range_km, sigma_radius_px, camera, body_radius_km)),
        n_trials=n_trials,
    )


def monte_carlo_center_attitude(
    theta_rad: float, sigma_angle_rad: float, n_trials: int = 20_000, seed: int = 0, camera: Camera | None = None
) -> np.ndarray:
    """Sample exact small rotations (per-axis ``sigma``) and project the rotated LOS (check of Eq. 39).

    Parameters
    ----------
    theta_rad : float
        Angle of the body centre from the boresight (radians), radial along camera ``+x``.
    sigma_angle_rad : float
        Per-axis standard deviation of the rotation vector (radians).
    n_trials : int
        Number of sampled rotations.
    seed : int
        Seed of ``numpy.random.default_rng``.
    camera : Camera, optional
        Gives ``f_px``; default ``Camera()``.

    Returns
    -------
    np.ndarray (n_trials, 2)
        (radial, tangential) image displacements of the centre (px).
    """

    cam = camera or Camera()
    rng = np.random.default_rng(seed)
    u = np.array([np.sin(theta_rad), 0.0, np.cos(theta_rad)])
    f = cam.focal_px
    x0 = f * u[0] / u[2]
    out = np.empty((n_trials, 2))
    for k in range(n_trials):
        v = rotation_vector_to_dcm(sigma_angle_rad * rng.standard_normal(3)) @ u
        out[k] = (f * v[0] / v[2] - x0, f * v[1] / v[2])
    return out


__all__ = [
    "FIG18_DISTANCES_KM",
    "Figure18",
    "MOON_RADIUS_KM",
    "RangeMonteCarlo",
    "angle_sigma_from_quaternion_sigma",
    "center_covariance_from_attitude",
    "center_sigma_from_attitude",
    "figure18_data",
    "monte_carlo_center_attitude",
    "monte_carlo_range_sigma",
    "radius_px",
    "radius_sigma_from_range_sigma",
    "range_from_radius",
    "range_sigma_from_position_sigma",
    "range_sigma_from_radius_sigma",
]
