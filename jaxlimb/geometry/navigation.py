"""Observer position from a body-centre line of sight and range, with its covariance.

Steps 6-7 of the flowchart of Mortari, D'Souza & Zanetti, "Image Processing of
Illuminated Ellipsoid" (§II, ``/work/shared/papers/mortari-dsouza-zanetti-illuminated-ellipsoid.md``)
and §7.1 of the Aerospace 2015 Moon paper (``aerospace-2015-moon-gradient-ransac-csf.md``)::

    r_om = D u_c                      (observer -> body, camera frame)
    r_o  = r_m - C_ci^T r_om          (observer position, ICRF/J2000)

Linear covariance propagation
-----------------------------
Error sources (independent, zero mean):

* LOS: either a 2x2 pixel covariance of the centre ``(row, col)`` (mapped through the
  camera's LOS Jacobian ``G = du/d(row, col)``, distortion included) or a 2x2 angular
  covariance (rad^2) in the tangent basis ``(e1, e2)`` of :func:`tangent_basis`;
* range: ``sigma_range_km``;
* attitude: rotation-vector error ``dphi`` in the camera frame (``C_est = (I - [dphi x]) C_ci``),
  3x3 covariance or an isotropic per-axis sigma;
* body ephemeris: optional 3x3 covariance of ``r_m`` (km^2, inertial).

First-order perturbation of ``r_o = r_m - C^T D u``::

    d r_o = d r_m - C^T (dD u + D du) - dC^T D u
    dC^T = C^T [dphi x]   =>   - dC^T D u = - C^T (dphi x D u) = C^T [D u x] dphi

so ``P = P_m + C^T (sigma_D^2 u u^T + D^2 G P_px G^T + [r_om x] P_phi [r_om x]^T) C``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import GeometryError
from .attitude import rotation_vector_to_dcm, skew, validate_dcm


def _unit(v: np.ndarray, name: str) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise GeometryError(f"`{name}` must be a finite 3-vector, got {np.asarray(v).tolist()}")
    n = float(np.linalg.norm(v))
    if n < 1e-300:
        raise GeometryError(f"`{name}` must be non-zero")
    return v / n


def tangent_basis(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal ``(e1, e2)`` perpendicular to unit ``u``.

    ``e1`` is the camera ``+x`` axis (toward +col) made perpendicular to ``u``; ``e2 = u x e1``
    (toward +row for a LOS near the boresight).  Angular LOS covariances are expressed in it.
    """
    u = _unit(u, "u")
    ref = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = ref - (ref @ u) * u
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(u, e1)


def observer_position(r_body_km: np.ndarray, C_ci: np.ndarray, los_camera: np.ndarray, range_km: float) -> np.ndarray:
    """``r_o = r_m - C_ci^T (D u_c)`` (Mortari et al. §II step 7).

    Parameters
    ----------
    r_body_km
        Body-centre position ``r_m`` (km, ICRF/J2000, any origin; the result has the same origin).
    C_ci
        Inertial -> camera DCM (validated, :class:`AttitudeError` if not a rotation).
    los_camera
        Direction to the body centre in the camera frame (normalised here).
    range_km
        Observer-to-body-centre distance ``D`` (> 0).
    """
    C = validate_dcm(C_ci)
    u = _unit(los_camera, "los_camera")
    if not (np.isfinite(range_km) and range_km > 0):
        raise GeometryError(f"`range_km` must be finite and > 0, got {range_km!r}")
    rm = np.asarray(r_body_km, dtype=float)
    if rm.shape != (3,) or not np.all(np.isfinite(rm)):
        raise GeometryError(f"`r_body_km` must be a finite 3-vector, got {rm.tolist()}")
    return rm - C.T @ (range_km * u)


def _cov(P: np.ndarray | None, shape: tuple[int, int], name: str) -> np.ndarray:
    if P is None:
        return np.zeros(shape)
    P = np.asarray(P, dtype=float)
    if P.ndim == 0:
        return float(P) ** 2 * np.eye(shape[0])  # isotropic sigma given
    if P.shape != shape or not np.all(np.isfinite(P)):
        raise GeometryError(f"`{name}` must be a finite {shape} covariance, got shape {P.shape}")
    if not np.allclose(P, P.T, rtol=1e-9, atol=1e-300) or np.min(np.linalg.eigvalsh(0.5 * (P + P.T))) < -1e-12 * max(
        1.0, float(np.max(np.abs(P)))
    ):
        raise GeometryError(f"`{name}` must be symmetric positive semi-definite")
    return 0.5 * (P + P.T)


@dataclass(frozen=True)
class NavigationSolution:
    """Observer position and its first-order covariance.

    Attributes
    ----------
    position_km
        ``r_o`` (ICRF/J2000, same origin as the body position).
    covariance_km2
        Total 3x3 covariance.
    contributions_km2
        The separate terms ``{"los", "range", "attitude", "body"}`` (sum = ``covariance_km2``).
    """

    position_km: np.ndarray
    covariance_km2: np.ndarray
    contributions_km2: dict

    @property
    def sigma_km(self) -> np.ndarray:
        """Square roots of the diagonal of the covariance."""
        return np.sqrt(np.diag(self.covariance_km2))


def navigate(
    r_body_km: np.ndarray,
    C_ci: np.ndarray,
    los_camera: np.ndarray,
    range_km: float,
    *,
    sigma_range_km: float = 0.0,
    los_cov_rad2: np.ndarray | None = None,
    los_cov_px2: np.ndarray | None = None,
    camera=None,
    center_rc: np.ndarray | None = None,
    attitude_cov_rad2: np.ndarray | float | None = None,
    body_cov_km2: np.ndarray | None = None,
) -> NavigationSolution:
    """Observer position and its linearly propagated covariance (module docstring).

    Parameters
    ----------
    r_body_km, C_ci, los_camera, range_km
        As :func:`observer_position`.
    sigma_range_km
        Range standard deviation (km).
    los_cov_rad2
        2x2 LOS covariance (rad^2) in the :func:`tangent_basis` of ``los_camera``.
    los_cov_px2, camera, center_rc
        Alternatively a 2x2 pixel covariance of the centre ``(row, col)``; needs ``camera``
        and ``center_rc`` (the pixel whose LOS is ``los_camera``; if omitted it is computed
        with ``camera.project``).  Exclusive with ``los_cov_rad2``.
    attitude_cov_rad2
        3x3 covariance of the attitude rotation-vector error (camera frame, rad^2), or a scalar
        per-axis standard deviation (rad) for an isotropic error.
    body_cov_km2
        3x3 covariance of the body ephemeris (km^2).
    """
    r_o = observer_position(r_body_km, C_ci, los_camera, range_km)
    C = np.asarray(C_ci, dtype=float)
    u = _unit(los_camera, "los_camera")
    if not (np.isfinite(sigma_range_km) and sigma_range_km >= 0):
        raise GeometryError(f"`sigma_range_km` must be finite and >= 0, got {sigma_range_km!r}")
    P_u = _unit_los_cov(u, los_cov_rad2, los_cov_px2, camera, center_rc)
    r_om = range_km * u
    Ct = C.T
    P_los = Ct @ (range_km**2 * P_u) @ C
    P_rng = Ct @ (sigma_range_km**2 * np.outer(u, u)) @ C
    S = skew(r_om)
    P_att = Ct @ S @ _cov(attitude_cov_rad2, (3, 3), "attitude_cov_rad2") @ S.T @ C
    P_body = _cov(body_cov_km2, (3, 3), "body_cov_km2")
    parts = {"los": P_los, "range": P_rng, "attitude": P_att, "body": P_body}
    P = P_los + P_rng + P_att + P_body
    return NavigationSolution(position_km=r_o, covariance_km2=0.5 * (P + P.T), contributions_km2=parts)


def _unit_los_cov(u: np.ndarray, los_cov_rad2: np.ndarray | None, los_cov_px2: np.ndarray | None, camera,
                  center_rc: np.ndarray | None) -> np.ndarray:
    """3x3 covariance of the unit LOS ``u`` (camera frame) from :func:`navigate`'s ``los_cov_rad2`` or
    ``los_cov_px2`` (validated)."""
    if los_cov_rad2 is not None and los_cov_px2 is not None:
        raise GeometryError("give either `los_cov_rad2` or `los_cov_px2`, not both")
    if los_cov_px2 is not None:
        if camera is None:
            raise GeometryError("`los_cov_px2` needs `camera`")
        rc = camera.project(u) if center_rc is None else np.asarray(center_rc, dtype=float)
        G = camera.los_jacobian(rc)
        return G @ _cov(los_cov_px2, (2, 2), "los_cov_px2") @ G.T
    e1, e2 = tangent_basis(u)
    E = np.stack([e1, e2], axis=1)
    return E @ _cov(los_cov_rad2, (2, 2), "los_cov_rad2") @ E.T


def monte_carlo_navigation(
    r_body_km: np.ndarray,
    C_ci: np.ndarray,
    los_camera: np.ndarray,
    range_km: float,
    *,
    n_trials: int,
    seed: int,
    sigma_range_km: float = 0.0,
    los_cov_rad2: np.ndarray | None = None,
    los_cov_px2: np.ndarray | None = None,
    camera=None,
    attitude_cov_rad2: np.ndarray | float | None = None,
    body_cov_km2: np.ndarray | None = None,
) -> np.ndarray:
    """Sample observer positions with the *nonlinear* model (``n_trials x 3``).

    Each trial draws the errors of :func:`navigate` and applies them exactly: the pixel is
    perturbed and re-mapped to a LOS through the camera (distortion included), the LOS
    angle errors rotate the vector exactly, the attitude error is applied as the exact
    rotation ``C_est = A(dphi) C_ci``.  Used to check the linear covariance.
    """
    rng = np.random.default_rng(seed)
    C = validate_dcm(C_ci)
    u = _unit(los_camera, "los_camera")
    rm = np.asarray(r_body_km, dtype=float)
    Pa = _cov(attitude_cov_rad2, (3, 3), "attitude_cov_rad2")
    Pb = _cov(body_cov_km2, (3, 3), "body_cov_km2")
    out = np.empty((n_trials, 3))
    if los_cov_px2 is not None:
        rc0 = camera.project(u)
        Lp = np.linalg.cholesky(_cov(los_cov_px2, (2, 2), "los_cov_px2") + 1e-300 * np.eye(2))
    else:
        e1, e2 = tangent_basis(u)
        Lr = np.linalg.cholesky(_cov(los_cov_rad2, (2, 2), "los_cov_rad2") + 1e-300 * np.eye(2))
    La = np.linalg.cholesky(Pa + 1e-300 * np.eye(3))
    Lb = np.linalg.cholesky(Pb + 1e-300 * np.eye(3))
    for k in range(n_trials):
        if los_cov_px2 is not None:
            uk = camera.los(rc0 + Lp @ rng.standard_normal(2))
        else:
            a, b = Lr @ rng.standard_normal(2)
            ang = np.hypot(a, b)
            if ang > 0:
                axis_dir = (a * e1 + b * e2) / ang
                uk = np.cos(ang) * u + np.sin(ang) * axis_dir
            else:
                uk = u
        Dk = range_km + sigma_range_km * rng.standard_normal()
        Ck = rotation_vector_to_dcm(La @ rng.standard_normal(3)) @ C
        out[k] = observer_position(rm + Lb @ rng.standard_normal(3), Ck, uk, Dk)
    return out


# ----------------------------------------------------------------------------- sphere image -> LOS, range
def _radial_frame(camera, center_rc: np.ndarray) -> tuple[float, float]:
    if camera.has_distortion:
        raise GeometryError(
            "sphere_from_ellipse/sphere_from_circle need pinhole image geometry: undistort the limb "
            "points (camera.undistort) and refit, or use horizon navigation on the undistorted LOS"
        )
    r0, c0 = camera.principal_point_rc
    rc = np.asarray(center_rc, dtype=float)
    return float(np.hypot(rc[0] - r0, rc[1] - c0)), float(np.arctan2(rc[0] - r0, rc[1] - c0))


def _theta_from_center(rho_c_over_f: float, sin_alpha: float) -> float:
    # ellipse centre at rho0/f = t / (1 - s^2 (1 + t^2)), t = tan(theta)  (camera.sphere_image_ellipse)
    # positive root of k s^2 t^2 + t - k (1 - s^2) = 0 in the cancellation-free form
    k, s2 = rho_c_over_f, sin_alpha**2
    t = 2.0 * k * (1.0 - s2) / (1.0 + np.sqrt(1.0 + 4.0 * k * k * s2 * (1.0 - s2)))
    return float(np.arctan(t))


def _los(camera, theta: float, phi: float) -> np.ndarray:
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def sphere_from_ellipse(camera, center_rc, semi_axes_px, body_radius_km: float) -> tuple[np.ndarray, float]:
    """Exact body-centre LOS and range of a sphere from its (pinhole) image ellipse.

    Inverts :func:`jaxlimb.geometry.camera.sphere_image_ellipse`: ``tan(alpha) = b^2/(a f)``,
    ``D = R/sin(alpha)``; with ``t = tan(theta)`` and ``s = sin(alpha)`` the ellipse centre
    is at ``rho_0 = f t / (1 - s^2 (1 + t^2))`` from the principal point (along the radial
    direction), so ``k s^2 t^2 + t - k (1 - s^2) = 0`` with ``k = rho_0 / f``, positive root.
    The image of the body centre is *not* the ellipse centre: it lies ``f t`` from the
    principal point, ``f t s^2 (1 + t^2)/(1 - s^2 (1 + t^2))`` closer (2 px at 12.5 deg off-axis
    for the Moon at 50 000 km on the default camera).

    Returns ``(los_camera, range_km)``.
    """
    a, b = (float(v) for v in semi_axes_px)
    if not (np.isfinite(a) and np.isfinite(b) and b > 0 and a >= b * (1 - 1e-9)):
        raise GeometryError(f"`semi_axes_px` must satisfy a >= b > 0, got {semi_axes_px!r}")
    if not (np.isfinite(body_radius_km) and body_radius_km > 0):
        raise GeometryError(f"`body_radius_km` must be finite and > 0, got {body_radius_km!r}")
    rho_c, phi = _radial_frame(camera, center_rc)
    f = camera.focal_px
    alpha = float(np.arctan(b * b / (a * f)))
    theta = _theta_from_center(rho_c / f, np.sin(alpha))
    return _los(camera, theta, phi), body_radius_km / np.sin(alpha)


def sphere_from_circle(camera, center_rc, radius_px: float, body_radius_km: float, tol: float = 1e-12) -> tuple[np.ndarray, float]:
    """Body-centre LOS and range of a sphere from a *circle* fit (centre, mean radius).

    Off-axis the sphere's image is an ellipse; a circle fitted to it returns (to first
    order in the eccentricity) the ellipse centre and the mean radius ``(a + b)/2``.  This
    solves ``(a(theta, alpha) + b(theta, alpha))/2 = radius_px`` and the ellipse-centre
    equation of :func:`sphere_from_ellipse` for ``(theta, alpha)`` (1-D Newton on ``alpha``,
    closed form for ``theta``), removing the range bias of the on-axis formula (range short
    by ≈ ``cos(theta)^1.5``: 3.6 % at the corner of the default camera) and the centre offset.
    """
    if not (np.isfinite(radius_px) and radius_px > 0):
        raise GeometryError(f"`radius_px` must be finite and > 0, got {radius_px!r}")
    if not (np.isfinite(body_radius_km) and body_radius_km > 0):
        raise GeometryError(f"`body_radius_km` must be finite and > 0, got {body_radius_km!r}")
    rho_c, phi = _radial_frame(camera, center_rc)
    f = camera.focal_px

    def mean_radius(alpha: float) -> tuple[float, float]:
        th = _theta_from_center(rho_c / f, np.sin(alpha))
        den = np.cos(th) ** 2 - np.sin(alpha) ** 2
        a = f * np.sin(alpha) * np.cos(alpha) / den
        b = f * np.sin(alpha) / np.sqrt(den)
        return 0.5 * (a + b), th

    alpha = float(np.arctan(radius_px / f))
    for _ in range(50):
        m, _th = mean_radius(alpha)
        h = 1e-7 * alpha
        dm = (mean_radius(alpha + h)[0] - mean_radius(alpha - h)[0]) / (2 * h)
        step = (m - radius_px) / dm
        alpha -= step
        if abs(step) < tol * alpha:
            break
    else:  # pragma: no cover - the map is smooth and monotonic
        if abs(mean_radius(alpha)[0] - radius_px) > 1e-9 * radius_px:
            raise GeometryError("sphere_from_circle did not converge")
    theta = mean_radius(alpha)[1]
    return _los(camera, theta, phi), body_radius_km / np.sin(alpha)


def navigate_from_circle(
    r_body_km: np.ndarray,
    C_ci: np.ndarray,
    camera,
    center_rc,
    radius_px: float,
    body_radius_km: float,
    *,
    fit_cov_px2: np.ndarray | None = None,
    attitude_cov_rad2: np.ndarray | float | None = None,
    body_cov_km2: np.ndarray | None = None,
) -> NavigationSolution:
    """Observer position from a circle fit ``(row, col, radius)`` and its 3x3 covariance.

    ``r_om = D(c, r) u(c, r)`` from :func:`sphere_from_circle`; the fit covariance (px^2, order
    ``row, col, radius``, correlations kept) is propagated with the central-difference
    Jacobian of that exact map; attitude and body terms as in :func:`navigate`.
    """
    u, D = sphere_from_circle(camera, center_rc, radius_px, body_radius_km)
    sol = navigate(r_body_km, C_ci, u, D, attitude_cov_rad2=attitude_cov_rad2, body_cov_km2=body_cov_km2)
    if fit_cov_px2 is None:
        return sol
    Pf = _cov(fit_cov_px2, (3, 3), "fit_cov_px2")
    x0 = np.array([*np.asarray(center_rc, dtype=float), float(radius_px)])
    Jm = np.empty((3, 3))
    for i in range(3):
        h = 1e-4
        xp, xm = x0.copy(), x0.copy()
        xp[i] += h
        xm[i] -= h
        up, Dp = sphere_from_circle(camera, xp[:2], xp[2], body_radius_km)
        um, Dm = sphere_from_circle(camera, xm[:2], xm[2], body_radius_km)
        Jm[:, i] = (Dp * up - Dm * um) / (2 * h)
    C = np.asarray(C_ci, dtype=float)
    P_fit = C.T @ Jm @ Pf @ Jm.T @ C
    parts = dict(sol.contributions_km2)
    parts["los"] = P_fit  # centre and radius errors together (correlated LOS + range)
    P = sum(parts.values())
    return NavigationSolution(position_km=sol.position_km, covariance_km2=0.5 * (P + P.T), contributions_km2=parts)


__all__ = [
    "NavigationSolution",
    "monte_carlo_navigation",
    "navigate",
    "navigate_from_circle",
    "observer_position",
    "sphere_from_circle",
    "sphere_from_ellipse",
    "tangent_basis",
]
