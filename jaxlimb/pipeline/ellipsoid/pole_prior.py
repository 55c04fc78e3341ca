r"""The body centre of a spheroid whose pole is unknown, marginalised over the poles a Sun-declination bound allows.

With ``R_body_to_camera`` unknown the limb cone does not sign the centre offset: a spheroid and its mirror image in the
plane of the cone axis and the cone's major axis have the same limb, with body centres ``+-gamma_off`` apart
(:mod:`jaxlimb.pipeline.ellipsoid`, "Free ellipse").  By default the cone axis is returned and the unknown offset carried
as a uniform error.  For a body whose equator the Sun never leaves by more than ``delta_max`` (the Earth: the
obliquity, 23.44 deg), a known Sun direction ``s`` restricts the pole ``p`` to ``|s . p| <= sin(delta_max)``, which
often excludes one of the mirror poles (``EllipsoidOptions.sun_declination_max_deg``).

How (:func:`marginal_center`): poles on an even grid of the sphere (:func:`sphere_grid`) inside that band; for each,
the limb cone of the spheroid placed at the free fit's position (:func:`spheroid_cones`: ``M = (Aq)(Aq)^T - (q^T A q -
1) A``, ``A = I/a^2 + (1/c^2 - 1/a^2) p p^T``, Eq. 2 of Mortari et al. 2016 in the camera frame), its flattening
vector ``g = (1 - b'/a') (cos 2psi, sin 2psi)`` (``psi`` the major axis about the cone axis) and the body-centre
direction that puts its cone axis on the observed one (``2 v_obs - v_k``, first order in the ~1e-4 rad offset).  Each
pole is weighted by the free fit's likelihood of its ``g`` (Gaussian, covariance from the fit's ``r0, c0, a, rho,
theta`` covariance plus ``(G_FLOOR_FRAC f)^2`` per component: the free shape's errors on ``benchmarks/families.py``'s
far Earths were 1-3 of its sigmas); the answer is the weighted mean of the centres' images, its covariance their
weighted scatter.
"""

from __future__ import annotations

import math

import numpy as np

from ...geometry.camera import Camera
from ...geometry.earth_cone import cone_eigen, image_ellipse_cone
from ...numerics import numerical_jacobian

G_FLOOR_FRAC = 0.25
"""Per-component sigma added to the fitted flattening vector's, in units of the flattening (module docstring)."""

N_POLES = 4096
"""Poles on the sphere grid (half of them distinct: ``p`` and ``-p`` are the same spheroid)."""

FREE_ELLIPSE = ("r0", "c0", "a", "rho", "theta")
"""The free ellipse's parameters, in the order of the covariance :func:`marginal_center` takes."""
_STEPS = np.array([1e-3, 1e-3, 1e-3, 1e-6, 1e-5])


def sphere_grid(n: int = N_POLES) -> np.ndarray:
    """``n`` unit vectors spread evenly over the sphere (Fibonacci lattice).

    Parameters
    ----------
    n : int
        Number of points.

    Returns
    -------
    np.ndarray (n, 3)
        Unit vectors.
    """
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = math.pi * (3.0 - math.sqrt(5.0)) * k
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def cone_flattening(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flattening vectors ``g = (1 - b'/a') (cos 2psi, sin 2psi)`` and unit axes of limb cones (module docstring);
    ``psi`` is the major axis' angle from the camera's ``x`` axis projected on the plane normal to the cone axis.

    Parameters
    ----------
    M : np.ndarray (..., 3, 3)
        Limb cones in the camera frame, positive on the rays that hit the body (eigenvalues ``(-, -, +)``;
        :func:`jaxlimb.geometry.earth_cone.cone_eigen`).

    Returns
    -------
    g : np.ndarray (..., 2)
        The flattening vectors.
    axis : np.ndarray (..., 3)
        The cones' unit axes (``z > 0``).
    """
    _, axis, a_, b_, V = cone_eigen(M)
    return _flattening(axis, a_, b_, V[..., :, 1]), axis


def _flattening(axis: np.ndarray, a_, b_, major: np.ndarray) -> np.ndarray:
    """``g = (1 - b'/a') (cos 2psi, sin 2psi)`` of cones with unit ``axis``, sines ``a' >= b'`` and ``major`` axis."""
    e1 = np.array([1.0, 0.0, 0.0]) - axis[..., :1] * axis
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(axis, e1)
    psi = np.arctan2(np.sum(major * e2, axis=-1), np.sum(major * e1, axis=-1))
    return (1.0 - np.asarray(b_) / np.asarray(a_))[..., None] * np.stack([np.cos(2.0 * psi), np.sin(2.0 * psi)], axis=-1)


def ellipse_flattening(camera: Camera, ell: tuple) -> np.ndarray:
    """``g`` of the limb cone of an image ellipse (:func:`jaxlimb.geometry.earth_cone.image_ellipse_cone`).

    Parameters
    ----------
    camera : Camera
        The pinhole camera.
    ell : tuple
        The image ellipse ``((r0, c0), (a, b), theta)`` (px, rad).

    Returns
    -------
    np.ndarray (2,)
        The flattening vector ``(1 - b'/a') (cos 2psi, sin 2psi)``.
    """
    cone = image_ellipse_cone(camera, *ell)
    return _flattening(cone.axis, *cone.semi_axes, cone.major_dir)


def spheroid_cones(q: np.ndarray, poles: np.ndarray, equatorial_km: float, polar_km: float) -> np.ndarray:
    """Limb cones of a spheroid of radii ``(a, a, c)`` with each of several poles: ``M = (Aq)(Aq)^T - (q^T A q - 1) A``,
    ``A = I/a^2 + (1/c^2 - 1/a^2) p p^T`` (Eq. 2 of Mortari et al. 2016 in the camera frame).

    Parameters
    ----------
    q : np.ndarray (3,)
        The body centre (km, camera frame).
    poles : np.ndarray (n, 3)
        Unit pole directions (camera frame).
    equatorial_km, polar_km : float
        The radii ``a`` and ``c`` (km; the limb's height included).

    Returns
    -------
    np.ndarray (n, 3, 3)
        The cones' matrices.
    """
    al, be = 1.0 / equatorial_km**2, 1.0 / polar_km**2 - 1.0 / equatorial_km**2
    A = al * np.eye(3)[None] + be * poles[:, :, None] * poles[:, None, :]
    Aq = A @ q
    qAq = Aq @ q
    return Aq[:, :, None] * Aq[:, None, :] - (qAq - 1.0)[:, None, None] * A


def _g_likelihood(camera: Camera, params, cov_geo: np.ndarray, flattening: float):  # type: ignore[no-untyped-def]
    """The fitted ``g`` and the inverse of its covariance (module docstring)."""
    x0 = np.array([float(getattr(params, n)) for n in FREE_ELLIPSE])

    def g_of(x: np.ndarray) -> np.ndarray:
        r0, c0, a, rho, th = (float(v) for v in x)
        return ellipse_flattening(camera, ((r0, c0), (a, a * rho), th))

    H = numerical_jacobian(g_of, x0, _STEPS)
    S = H @ cov_geo @ H.T + (G_FLOOR_FRAC * flattening) ** 2 * np.eye(2)
    return g_of(x0), np.linalg.inv(S)


def marginal_center(camera: Camera, params, cov_geo: np.ndarray, q: np.ndarray, sun_dir_camera, sin_dmax: float,
                    equatorial_km: float, polar_km: float) -> tuple[np.ndarray, np.ndarray, dict] | None:
    """The body centre's image and its covariance marginalised over the poles allowed by ``|s . p| <= sin_dmax``
    (module docstring).

    Parameters
    ----------
    camera : Camera
        The pinhole camera.
    params : EllipseParams or a profile's parameters
        The free fit (``r0, c0, a, rho, theta``, px and rad).
    cov_geo : np.ndarray (5, 5)
        Their covariance, in the order of :data:`FREE_ELLIPSE`.
    q : np.ndarray (3,)
        The body centre of the free fit (km, camera frame).
    sun_dir_camera : array_like (3,)
        Direction from the body toward the Sun (camera frame, any length).
    sin_dmax : float
        Sine of the largest solar declination on the body.
    equatorial_km, polar_km : float
        The limb spheroid's radii (km).

    Returns
    -------
    tuple or None
        ``(mean, cov, report)``: the centre's image ``(row, col)`` ``(2,)`` (px), its covariance ``(2, 2)`` (px^2),
        and ``{"n_poles", "effective_poles", "chi2_min"}``; ``None`` when no pole of the grid is allowed or none
        is likely.
    """
    f = 1.0 - polar_km / equatorial_km
    s = np.asarray(sun_dir_camera, float)
    s = s / np.linalg.norm(s)
    poles = sphere_grid()
    poles = poles[np.abs(poles @ s) <= sin_dmax]
    if poles.shape[0] == 0:
        return None
    g_fit, S_inv = _g_likelihood(camera, params, cov_geo, f)
    g, axes = cone_flattening(spheroid_cones(np.asarray(q, float), poles, equatorial_km, polar_km))
    d = g - g_fit
    chi2 = np.einsum("ni,ij,nj->n", d, S_inv, d)
    w = np.exp(-0.5 * (chi2 - chi2.min()))
    if not np.isfinite(w).all() or w.sum() <= 0:
        return None
    w /= w.sum()
    v_obs = np.asarray(q, float) / np.linalg.norm(q)
    u = 2.0 * v_obs[None, :] - axes
    c = camera.project(u)
    mean = w @ c
    cov = (c - mean).T @ ((c - mean) * w[:, None])
    return mean, cov, {"n_poles": int(poles.shape[0]), "effective_poles": float(1.0 / np.sum(w * w)),
                       "chi2_min": float(chi2.min())}


__all__ = ["FREE_ELLIPSE", "G_FLOOR_FRAC", "N_POLES", "cone_flattening", "ellipse_flattening", "marginal_center",
           "sphere_grid", "spheroid_cones"]
