r"""Earth centre offset and range iteration (Mortari, D'Souza & Zanetti, §IV, Figs. 2-4).

The Earth is the oblate spheroid ``x^2/Re^2 + y^2/Re^2 + z^2/Rp^2 = 1`` (WGS-84,
``Re = 6378.137``, ``Rp = 6356.752`` km) grown by an atmosphere height ``h`` (both radii +h:
the limb seen by the camera is the top of the bright atmosphere, docs/design.md).  Frames: any
frame whose ``z`` axis is the spin axis ``pole`` (default ``[0, 0, 1]`` of J2000: the true pole
of date is ~0.36 deg away in 2026 by precession; pass ``pole`` for better).  ``p`` is the
observer position relative to the Earth centre (km).

Quantities (paper, §IV)
-----------------------
* **Tangent slopes** in the observer's meridian plane (coordinates ``rho = sqrt(x^2 + y^2)``,
  ``z``): the lines ``z = m (rho - rho_p) + z_p`` tangent to ``rho^2/Re^2 + z^2/Rp^2 = 1``::

      m_{1,2} = [rho_p z_p ± sqrt(rho_p^2 Rp^2 + z_p^2 Re^2 - Re^2 Rp^2)] / (rho_p^2 - Re^2)

  (a line ``z = m rho + k`` is tangent iff ``k^2 = Re^2 m^2 + Rp^2``; substituting
  ``k = z_p - m rho_p`` gives the quadratic ``m^2 (rho_p^2 - Re^2) - 2 m rho_p z_p + z_p^2 - Rp^2 = 0``).
  Verified by :func:`tangent_slopes`; singular when ``rho_p = Re`` (a vertical tangent), so
  :func:`meridian_limb_angle` uses the tangent points instead (affine map to the unit circle).
* **Predicted angle** ``dtheta_hat`` between the two tangent lines (from ``p_k``).
* **Measured angle** ``dtheta_tilde = 2 asin(b')`` (``b'`` = the observed ellipse's minor
  semi-axis on the unit sphere, Eq. 8).  For a spheroid the meridian plane is a symmetry
  plane of the limb cone, contains its axis and its minor axis, so at the true position
  ``dtheta_hat = dtheta_tilde`` *exactly* (tested).
* **Range update.**  The paper writes ``Delta p = -R cos(dtheta/2) / (2 sin^2(dtheta/2)) (dtheta_hat - dtheta_tilde)``.
  For a sphere ``dtheta = 2 asin(R/p)``, so
  ``d dtheta/dp = -2R / (p^2 sqrt(1 - R^2/p^2)) = -2 sin^2(dtheta/2) / (R cos(dtheta/2))`` and the
  Newton step that zeroes ``dtheta_hat(p) - dtheta_tilde`` is
  ``Delta p = -(dtheta_hat - dtheta_tilde) / (d dtheta/dp) = +R cos(dtheta/2)/(2 sin^2(dtheta/2)) (dtheta_hat - dtheta_tilde)``.
  **The magnitude of the paper's factor is exactly the sphere's Newton step, but its sign is
  wrong**: it contradicts the paper's own sentence ("if ``dtheta_hat > dtheta_tilde`` the estimated
  distance is too short") and makes the iteration diverge (``tests/geometry/test_earth.py``).
  We use the ``+`` sign (``sign="paper"`` reproduces the printed one).  For the spheroid the
  step is Newton's with an approximate derivative (``R`` = ``Re`` or ``Rp``), so convergence
  is linear with a tiny ratio (~flattening x geometry).
* **Centre offset** ``gamma_off``: the angle between the cone axis ``v_c = C_ie [0, 0, 1]`` (the
  direction the observed ellipse is centred on) and the body-centre direction ``-p_hat``; the
  correction is a rotation of ``v_c`` by ``gamma_off`` about ``e = unit(v_c x pole)``,
  orthogonal to ``v_c`` and to the spin axis.  Sign (as the paper's Fig. 3): ``gamma_off > 0``
  for northern observers, for whom the cone axis is turned toward the equator (``-pole``) and
  the rotation by ``+gamma_off`` about ``e`` turns it back toward ``+pole``.

Iteration (Fig. 2): from ``p_0 = E{p}``: compute the cone at ``p_k`` -> ``gamma_off(p_k)``;
rotate the measured cone-axis direction by it -> ``p_hat_k = -u``; ``dtheta_hat`` at
``|p_k| p_hat_k``; stop if ``|dtheta_hat - dtheta_tilde| < eps``; else
``p_{k+1} = (|p_k| + Delta p_k) p_hat_k``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ..errors import GeometryError
from .ellipsoid import limb_cone

EARTH_EQUATORIAL_KM = 6378.137
EARTH_POLAR_KM = 6356.752
GEO_RADIUS_KM = 42_164.0
MOON_DISTANCE_KM = 384_400.0
ARCSEC = math.pi / (180.0 * 3600.0)


def _radii(equatorial_km: float, polar_km: float, atmosphere_km: float) -> tuple[float, float]:
    for nm, v in (("equatorial_km", equatorial_km), ("polar_km", polar_km)):
        if not (isinstance(v, (int, float, np.floating)) and math.isfinite(v) and v > 0):
            raise GeometryError(f"`{nm}` must be a finite radius > 0 km, got {v!r}")
    if not (math.isfinite(atmosphere_km) and atmosphere_km > -min(equatorial_km, polar_km)):
        raise GeometryError(f"`atmosphere_km` must be finite and > -{min(equatorial_km, polar_km)} km, got {atmosphere_km!r}")
    return equatorial_km + atmosphere_km, polar_km + atmosphere_km


def _check_outside(rho_p: float, z_p: float, Re: float, Rp: float) -> float:
    g = (rho_p / Re) ** 2 + (z_p / Rp) ** 2
    if not g > 1.0:
        raise GeometryError(
            f"observer must be outside the (atmosphere-grown) spheroid: (rho/Re)^2 + (z/Rp)^2 = {g:.6g} <= 1 "
            f"for rho = {rho_p:.3f} km, z = {z_p:.3f} km, Re = {Re} km, Rp = {Rp} km"
        )
    return g


def _pole_frame(pole) -> np.ndarray:
    """Rotation T (rows = new axes) with T @ pole = z."""
    z = np.asarray(pole, dtype=float)
    if z.shape != (3,) or not np.all(np.isfinite(z)) or np.linalg.norm(z) == 0:
        raise GeometryError(f"`pole` must be a finite non-zero 3-vector, got {np.asarray(pole).tolist()}")
    z = z / np.linalg.norm(z)
    ref = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = ref - (ref @ z) * z
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z])


def meridian_coordinates(p_km, pole=(0.0, 0.0, 1.0)) -> tuple[float, float]:
    """``(rho_p, z_p)`` of the observer in its meridian plane."""
    p = _pole_frame(pole) @ np.asarray(p_km, dtype=float)
    return float(math.hypot(p[0], p[1])), float(p[2])


def tangent_slopes(rho_p: float, z_p: float, Re: float, Rp: float) -> tuple[float, float]:
    """The paper's slopes ``m_{1,2}`` of the two tangent lines (module docstring).

    Raises
    ------
    GeometryError
        Observer inside the ellipse, or ``rho_p = Re`` (a vertical tangent: infinite slope).
    """
    _check_outside(rho_p, z_p, Re, Rp)
    den = rho_p**2 - Re**2
    if abs(den) < 1e-12 * Re**2:
        raise GeometryError(f"tangent slope is infinite for rho_p = Re = {Re} km; use meridian_limb_angle")
    disc = math.sqrt(rho_p**2 * Rp**2 + z_p**2 * Re**2 - Re**2 * Rp**2)
    return (rho_p * z_p + disc) / den, (rho_p * z_p - disc) / den


def limb_angle_from_slopes(m1: float, m2: float) -> float:
    """Acute angle (rad) between two lines of slopes ``m1, m2``: ``atan(|(m1 - m2)/(1 + m1 m2)|)``.

    The angle between two *lines* is defined modulo pi (``dtheta`` or ``pi - dtheta``): the
    slopes alone cannot tell which.  The limb angle is the acute one whenever the observer
    is farther than ``sqrt(2) Re`` (``dtheta < 90 deg``; beyond LEO).  ``atan2(|m1-m2|, 1+m1 m2)``
    picks the wrong one when the two tangent lines straddle the vertical (observer near the
    polar axis, ``1 + m1 m2 < 0``) -- tested.  :func:`meridian_limb_angle` has no ambiguity.
    """
    return math.atan(abs(m1 - m2) / abs(1.0 + m1 * m2)) if 1.0 + m1 * m2 != 0 else math.pi / 2


def meridian_tangent_directions(rho_p: float, z_p: float, Re: float, Rp: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions ``(d_rho, d_z)`` from the observer to the two meridian tangent points.

    Map ``(rho, z) -> (rho/Re, z/Rp)``: the ellipse becomes the unit circle, tangency is
    preserved, and the tangent points from ``P'`` are at polar angles ``phi0 ± acos(1/|P'|)``.
    """
    _check_outside(rho_p, z_p, Re, Rp)
    P = np.array([rho_p / Re, z_p / Rp])
    r = float(np.linalg.norm(P))
    phi0 = math.atan2(P[1], P[0])
    da = math.acos(1.0 / r)
    out = []
    for phi in (phi0 + da, phi0 - da):
        T = np.array([Re * math.cos(phi), Rp * math.sin(phi)])
        d = T - np.array([rho_p, z_p])
        out.append(d / np.linalg.norm(d))
    return out[0], out[1]


def meridian_limb_angle(rho_p: float, z_p: float, Re: float, Rp: float) -> float:
    """``dtheta_hat``: angle between the two tangent lines in the meridian plane (rad)."""
    d1, d2 = meridian_tangent_directions(rho_p, z_p, Re, Rp)
    return math.atan2(abs(d1[0] * d2[1] - d1[1] * d2[0]), float(d1 @ d2))


def limb_angle_from_b_prime(b_prime: float) -> float:
    """``dtheta_tilde = 2 asin(b')`` (``sin(dtheta_tilde/2) = b'``)."""
    if not (math.isfinite(b_prime) and 0 < b_prime < 1):
        raise GeometryError(f"`b_prime` must be in (0, 1) (sine of the minor half-angle), got {b_prime!r}")
    return 2.0 * math.asin(b_prime)


def delta_p(
    dtheta_hat: float,
    dtheta_tilde: float,
    R: float,
    dtheta: float | None = None,
    sign: Literal["corrected", "paper"] = "corrected",
) -> float:
    """Range update ``Delta p = ± R cos(dtheta/2) / (2 sin^2(dtheta/2)) (dtheta_hat - dtheta_tilde)``.

    ``sign="corrected"`` (default, ``+``) is Newton's step for a sphere; ``"paper"`` is the
    printed ``-`` sign (diverges; module docstring).  ``dtheta`` defaults to ``dtheta_tilde``.
    """
    if sign not in ("corrected", "paper"):
        raise GeometryError(f"`sign` must be 'corrected' or 'paper', got {sign!r}")
    th = dtheta_tilde if dtheta is None else dtheta
    k = R * math.cos(th / 2) / (2.0 * math.sin(th / 2) ** 2)
    s = 1.0 if sign == "corrected" else -1.0
    return s * k * (dtheta_hat - dtheta_tilde)


def rotate(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """Active right-handed rotation of ``v`` about unit ``axis`` by ``angle`` (Rodrigues)."""
    e = np.asarray(axis, dtype=float)
    e = e / np.linalg.norm(e)
    v = np.asarray(v, dtype=float)
    c, s = math.cos(angle), math.sin(angle)
    return v * c + np.cross(e, v) * s + e * (e @ v) * (1 - c)


def earth_radii(atmosphere_km: float = 0.0, equatorial_km: float = EARTH_EQUATORIAL_KM, polar_km: float = EARTH_POLAR_KM) -> np.ndarray:
    """``(Re + h, Re + h, Rp + h)``."""
    Re, Rp = _radii(equatorial_km, polar_km, atmosphere_km)
    return np.array([Re, Re, Rp])


def gamma_off(
    p_km,
    atmosphere_km: float = 0.0,
    pole=(0.0, 0.0, 1.0),
    equatorial_km: float = EARTH_EQUATORIAL_KM,
    polar_km: float = EARTH_POLAR_KM,
) -> float:
    """Signed centre offset ``gamma_off`` (rad): > 0 north of the equator (module docstring)."""
    T = _pole_frame(pole)
    p = T @ np.asarray(p_km, dtype=float)
    radii = earth_radii(atmosphere_km, equatorial_km, polar_km)
    _check_outside(math.hypot(p[0], p[1]), p[2], radii[0], radii[2])
    cone = limb_cone(radii, p)
    return math.copysign(cone.gamma_off, p[2]) if p[2] != 0 else 0.0


def center_direction(v_center, gamma_off_rad: float, pole=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Body-centre direction from the cone-axis (observed ellipse centre) direction.

    Rotation of ``v_center`` by ``gamma_off_rad`` about ``unit(v_center x pole)``.
    """
    v = np.asarray(v_center, dtype=float)
    v = v / np.linalg.norm(v)
    z = np.asarray(pole, dtype=float)
    e = np.cross(v, z / np.linalg.norm(z))
    if np.linalg.norm(e) < 1e-15:  # looking along the spin axis: no offset by symmetry
        return v
    return rotate(v, e, gamma_off_rad)


@dataclass(frozen=True)
class GammaOffSurface:
    """Fig. 3 of the paper: ``gamma_off_arcsec[i, j]`` at ``latitudes_deg[i]``, ``distances_km[j]``."""

    latitudes_deg: np.ndarray
    distances_km: np.ndarray
    gamma_off_arcsec: np.ndarray
    rho: np.ndarray  # observed axis ratio b'/a' (Eq. 9) on the same grid
    atmosphere_km: float


def gamma_off_surface(
    latitudes_deg=np.linspace(0.0, 90.0, 19),
    distances_km=np.linspace(GEO_RADIUS_KM, MOON_DISTANCE_KM, 25),
    atmosphere_km: float = 0.0,
) -> GammaOffSurface:
    """The ``gamma_off`` surface (arcsec) of Fig. 3: latitude 0-90 deg x distance GEO - Moon.

    Latitude is geocentric (the angle of ``p`` from the equatorial plane).
    """
    lat = np.asarray(latitudes_deg, dtype=float)
    dist = np.asarray(distances_km, dtype=float)
    g = np.empty((lat.size, dist.size))
    rho = np.empty_like(g)
    radii = earth_radii(atmosphere_km)
    for i, la in enumerate(np.radians(lat)):
        for j, D in enumerate(dist):
            p = D * np.array([math.cos(la), 0.0, math.sin(la)])
            g[i, j] = gamma_off(p, atmosphere_km) / ARCSEC
            rho[i, j] = limb_cone(radii, p).rho
    return GammaOffSurface(latitudes_deg=lat, distances_km=dist, gamma_off_arcsec=g, rho=rho, atmosphere_km=atmosphere_km)


@dataclass(frozen=True)
class EarthFix:
    """Result of :func:`earth_range_iteration`.

    Attributes
    ----------
    position_km
        Observer position relative to the Earth centre (input frame).
    range_km
        ``|position_km|``.
    iterations
        Number of ``Delta p`` updates applied before ``|dtheta_hat - dtheta_tilde| < eps``.
    converged
        Whether the tolerance was met within ``max_iter``.
    gamma_off_rad
        The offset used in the last pass.
    history
        Per pass: ``(range_km, dtheta_hat - dtheta_tilde [rad])``.
    """

    position_km: np.ndarray
    range_km: float
    iterations: int
    converged: bool
    gamma_off_rad: float
    history: list = field(default_factory=list)


def _iteration_inputs(v_center, p0_km, pole, Re: float, Rp: float, R: str, dtheta: str, update: str):  # type: ignore[no-untyped-def]
    """Checked prior position and unit cone axis of :func:`earth_range_iteration` (``GeometryError`` otherwise)."""
    p = np.asarray(p0_km, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise GeometryError(f"`p0_km` must be a finite 3-vector, got {np.asarray(p0_km).tolist()}")
    v = np.asarray(v_center, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)) or np.linalg.norm(v) == 0:
        raise GeometryError(f"`v_center` must be a finite non-zero 3-vector, got {np.asarray(v_center).tolist()}")
    v = v / np.linalg.norm(v)
    rho0, z0 = meridian_coordinates(p, pole)
    _check_outside(rho0, z0, Re, Rp)
    if R not in ("equatorial", "polar") or dtheta not in ("tilde", "hat") or update not in ("newton", "ratio"):
        raise GeometryError(f"bad option: R={R!r} (equatorial|polar), dtheta={dtheta!r} (tilde|hat), update={update!r} (newton|ratio)")
    return p, v


def _next_range(rng_k: float, dth_hat: float, dth_tilde: float, R_used: float, update: str, dtheta: str, sign: str) -> float:
    """One range update of Fig. 2: the paper's ``Delta p`` (Newton) or the sine ratio (module docstring)."""
    if update == "ratio":
        return rng_k * math.sin(dth_hat / 2) / math.sin(dth_tilde / 2)
    return rng_k + delta_p(dth_hat, dth_tilde, R_used, dth_hat if dtheta == "hat" else dth_tilde, sign=sign)  # type: ignore[arg-type]


def _realigned(p, v, dth_tilde: float, atmosphere_km: float, pole, radii: tuple[float, float],
               body_km: tuple[float, float]) -> tuple[float, float, np.ndarray, np.ndarray, float]:
    """The iterate ``p`` turned onto the centre direction at its range: ``(range, gamma_off, direction, p, residual
    of the limb angle)`` (``radii``: with atmosphere; ``body_km``: equatorial and polar radii without it)."""
    rng_k = float(np.linalg.norm(p))
    g = gamma_off(p, atmosphere_km, pole, *body_km)
    p_hat = -center_direction(v, g, pole)
    p = rng_k * p_hat
    rho_p, z_p = meridian_coordinates(p, pole)
    diff = meridian_limb_angle(rho_p, z_p, *radii) - dth_tilde
    return rng_k, g, p_hat, p, diff


def _outside(p: np.ndarray, new_rng: float, pole, Re: float, Rp: float) -> np.ndarray:
    """``p``, an iterate at range ``new_rng``, checked to lie outside the spheroid ``(Re, Rp)``."""
    rho_n, z_n = meridian_coordinates(p, pole)
    if (rho_n / Re) ** 2 + (z_n / Rp) ** 2 <= 1.0:
        raise GeometryError(f"range iteration stepped inside the Earth (range {new_rng:.1f} km); bad prior or measurement")
    return p


def earth_range_iteration(
    v_center, b_prime: float, p0_km, *, atmosphere_km: float = 0.0, pole=(0.0, 0.0, 1.0), eps: float = 1e-10,
    max_iter: int = 20, R: Literal["equatorial", "polar"] = "equatorial",
    sign: Literal["corrected", "paper"] = "corrected", dtheta: Literal["tilde", "hat"] = "tilde",
    update: Literal["newton", "ratio"] = "newton", equatorial_km: float = EARTH_EQUATORIAL_KM,
    polar_km: float = EARTH_POLAR_KM,
) -> EarthFix:
    """Earth range and centre-offset iteration of Fig. 2 (module docstring).

    Parameters
    ----------
    v_center
        Measured direction from the observer to the observed ellipse centre, i.e. the limb
        cone axis ``C_ci^T C_ie [0, 0, 1]`` (same frame as ``p0_km`` and ``pole``).
    b_prime
        Measured minor semi-axis of the observed ellipse on the unit sphere (Eq. 8).
    p0_km
        Prior observer position ``E{p}`` relative to the Earth centre (km).
    eps
        Tolerance on ``|dtheta_hat - dtheta_tilde|`` (rad).
    R
        Radius used in ``Delta p`` (the paper allows ``Re`` or ``Rp``, plus atmosphere).
    sign
        ``"corrected"`` (default) or the printed ``"paper"`` sign (diverges).
    dtheta
        Angle used in the ``Delta p`` factor: the measured ``dtheta_tilde`` (default) or the
        predicted ``dtheta_hat`` (the paper allows both; ``"hat"`` is Newton's derivative at
        the current iterate, quadratic for a sphere).
    update
        ``"newton"``: the paper's ``Delta p`` (with the corrected sign).  ``"ratio"``: our
        alternative ``p_{k+1} = p_k sin(dtheta_hat/2) / sin(dtheta_tilde/2)``, i.e. the exact
        sphere inversion ``p = R_eff / sin(dtheta_tilde/2)`` with the effective radius
        ``R_eff = p_k sin(dtheta_hat/2)`` that the spheroid shows from ``p_k`` (no choice of
        ``R`` needed; converges in one update for a sphere).

    Raises
    ------
    GeometryError
        Observer prior inside the spheroid, bad ``b_prime``/radii, or an iterate that falls inside.
    """
    Re, Rp = _radii(equatorial_km, polar_km, atmosphere_km)
    dth_tilde = limb_angle_from_b_prime(b_prime)
    p, v = _iteration_inputs(v_center, p0_km, pole, Re, Rp, R, dtheta, update)
    R_used = Re if R == "equatorial" else Rp
    history: list = []
    updates = 0
    g = 0.0
    for _ in range(max_iter + 1):
        rng_k, g, p_hat, p, diff = _realigned(p, v, dth_tilde, atmosphere_km, pole, (Re, Rp), (equatorial_km, polar_km))
        history.append((rng_k, diff))
        if abs(diff) < eps:
            return EarthFix(position_km=p, range_km=rng_k, iterations=updates, converged=True, gamma_off_rad=g, history=history)
        if updates == max_iter:
            break
        new_rng = _next_range(rng_k, dth_tilde + diff, dth_tilde, R_used, update, dtheta, sign)
        if not (math.isfinite(new_rng) and new_rng > 0):
            break
        p = _outside(new_rng * p_hat, new_rng, pole, Re, Rp)
        updates += 1
    return EarthFix(position_km=p, range_km=float(np.linalg.norm(p)), iterations=updates, converged=False, gamma_off_rad=g, history=history)


__all__ = [
    "ARCSEC",
    "EARTH_EQUATORIAL_KM",
    "EARTH_POLAR_KM",
    "EarthFix",
    "GEO_RADIUS_KM",
    "GammaOffSurface",
    "MOON_DISTANCE_KM",
    "center_direction",
    "delta_p",
    "earth_radii",
    "earth_range_iteration",
    "gamma_off",
    "gamma_off_surface",
    "limb_angle_from_b_prime",
    "limb_angle_from_slopes",
    "meridian_coordinates",
    "meridian_limb_angle",
    "meridian_tangent_directions",
    "rotate",
    "tangent_slopes",
]
