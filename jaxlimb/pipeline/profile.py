r"""A physically based limb profile: the blurred radiance of a sunlit sphere near its limb.

Why.  A sigmoid puts its 50 % level where a *flat-topped* blurred step has it.  A real lit
limb is not flat-topped: seen from a finite range, the limb is at emission :math:`e = 90^\circ`
while the incidence there is :math:`< 90^\circ` (the view rays converge, the Sun's are
parallel), so the Lommel-Seeliger term :math:`2\mu_0/(\mu_0 + \mu)` of the lunar-Lambert law
reaches 2 in a rim a fraction of a pixel wide; and at larger phases the Lambert term dims
the limb toward the horns.  Blurred, the rim moves the sigmoid's 50 % point outward
(measured 0.03-0.13 px at zero phase, 0.2-0.3 px at 90 deg, ~0.65 px at 120 deg; see
``benchmarks/locate_accuracy.py``).  This model fits the profile itself.

Geometry (circle model, small angles).  A pixel at distance ``d`` from the centre of the
body's image, polar direction at angle :math:`\psi'` from the Sun's image direction.  With
:math:`q = d/R` (``R`` the apparent radius, px) and :math:`\alpha_0 = \arctan(R/f)` the
angular radius, the ray is at :math:`\beta = q\,\alpha_0` from the centre direction and hits
the sphere with :math:`\sin e = \sin\beta / \sin\alpha_0 \approx q`.  In the frame with ``z``
from the body toward the observer and ``x`` along the pixel's image direction, the normal
is :math:`n = (\sin(e - \beta), \cdot, \cos(e - \beta))` (the normal is turned by ``e`` from
the direction back to the observer, which is itself turned by :math:`-\beta` from ``z``),
and the Sun direction is :math:`s = (\sin\vartheta\cos\psi', \cdot, \cos\vartheta)`
(:math:`\vartheta` the phase angle), so

.. math:: \mu_0 = \cos i = \sin(e-\beta)\sin\vartheta\cos\psi' + \cos(e-\beta)\cos\vartheta,
          \qquad \mu = \cos e = \sqrt{1 - q^2}.

Radiance (lunar-Lambert, McEwen): :math:`I = L\,2\mu_0/(\mu_0+\mu) + (1-L)\,\mu_0` for
:math:`\mu_0 > 0`, 0 otherwise (``L`` fixed from the phase).

Blur.  The observed intensity is ``ymin + amp * (I H) * N_sigma`` along the radial
direction (1-D: ``R >> sigma``): with the depth :math:`u' = R - d' = v^2`,

.. math:: f(d) = y_{\min} + A \int_{v_0}^{v_1} I(R - v^2)\, N(d - R + v^2; \sigma_e)\, 2v\,dv

by 24-point Gauss-Legendre quadrature, :math:`v_{0,1} = \sqrt{\max(0, R - d \mp 6\sigma_e)}`
(the substitution removes the square-root behaviour of :math:`\mu` at the limb), and
:math:`\sigma_e^2 = \sigma^2 + 1/12` (pixel integration as a box).  Parameters
``(r0, c0, a, sigma, amp, ymin)`` are estimated; ``theta, rho`` (limb ellipse shape),
``sun_r, sun_c`` (unit image direction of the Sun), ``phase`` (rad), ``inv_f`` (1/focal px;
0 = orthographic) and ``L`` are held fixed (``fixed=PROFILE_FIXED``).  The Jacobian is ``jax.jacfwd`` of the intensity.

Off the optical axis the limb is an ellipse (``a - b`` reaches ~5 px at the corner of the
default imager for the Moon at 60 000 km): the model carries the ellipse ``(r0, c0, a, theta,
rho)``; with a camera, ``theta`` and ``rho`` are held at the values of the image of a sphere
at the current estimate and iterated, exactly as the sigmoid's body-centre correction
(:func:`jaxlimb.pipeline.refine.fit_sphere_annulus`), and ``(r0, c0, a)`` map exactly to the
body centre (:func:`jaxlimb.pipeline.sphere.sphere_from_ellipse_center`).  Without a camera
``rho = 1`` (a circle of radius ``a``).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from ..errors import GeometryError
from ..models import LimbModel, LimbParams
from .sphere import SphereImage, _a_of_alpha, _tan_theta, sphere_from_ellipse_center

_GL_X, _GL_W = np.polynomial.legendre.leggauss(24)
PROFILE_FIXED = ("theta", "rho", "sun_r", "sun_c", "phase", "inv_f", "L")


class LimbProfileParams(LimbParams):
    """Parameters of :func:`limb_profile_intensity` (module docstring).

    ``r0, c0, a, theta, rho`` are the limb ellipse as in :class:`jaxlimb.models.EllipseParams`
    (``rho = 1``: a circle of radius ``a``); ``sigma`` the Gaussian PSF (px); ``amp``, ``ymin``
    the radiance scale and the sky level; ``sun_r, sun_c, phase, inv_f, L`` fixed geometry.
    """

    r0: ArrayLike
    c0: ArrayLike
    a: ArrayLike
    theta: ArrayLike
    rho: ArrayLike
    sigma: ArrayLike
    amp: ArrayLike
    ymin: ArrayLike
    sun_r: ArrayLike
    sun_c: ArrayLike
    phase: ArrayLike
    inv_f: ArrayLike
    L: ArrayLike


def _radiance(p: LimbProfileParams, q, cpsi, alpha0):
    """Lunar-Lambert radiance at normalised distance ``q`` (``< 1``) and ``cos(psi')``."""
    q = jnp.clip(q, 0.0, 1.0)
    mu = jnp.sqrt(jnp.maximum(1.0 - q * q, 0.0))
    beta = q * alpha0
    s_em = q * jnp.cos(beta) - mu * jnp.sin(beta)  # sin(e - beta)
    c_em = mu * jnp.cos(beta) + q * jnp.sin(beta)  # cos(e - beta)
    mu0 = s_em * jnp.sin(p.phase) * cpsi + c_em * jnp.cos(p.phase)
    lit = mu0 > 0
    m0 = jnp.where(lit, mu0, 0.0)
    den = jnp.where(lit, m0 + mu, 1.0)
    return jnp.where(lit, p.L * 2.0 * m0 / den + (1.0 - p.L) * m0, 0.0)


def limb_profile_intensity(p: LimbProfileParams, rc):
    """Blurred limb radiance (module docstring) at pixels ``rc`` ``(n, 2)``.

    Along the ray from the ellipse centre through a pixel at distance ``d``, the limb is at
    ``R = rho a d / beta`` (``beta = sqrt(rho^2 x^2 + y^2)`` in the ellipse frame of
    :func:`jaxlimb.models.ellipse_coords`); the circle formulas apply with that ``R``.
    """
    rc = jnp.asarray(rc)
    dr = rc[..., 0] - p.r0
    dc = rc[..., 1] - p.c0
    ct, st = jnp.cos(p.theta), jnp.sin(p.theta)
    x = dc * ct - dr * st
    y = -dr * ct - dc * st
    d2 = dr * dr + dc * dc
    d = jnp.sqrt(jnp.where(d2 > 0, d2, 1.0))
    b2 = p.rho * p.rho * x * x + y * y
    beta = jnp.sqrt(jnp.where(b2 > 0, b2, 1.0))
    R = p.rho * p.a * d / beta
    alpha0 = jnp.arctan(p.rho * p.a * p.inv_f)
    cpsi = (dr * p.sun_r + dc * p.sun_c) / d
    se = jnp.sqrt(p.sigma * p.sigma + 1.0 / 12.0)
    v0 = jnp.sqrt(jnp.maximum(R - d - 6.0 * se, 1e-12))
    v1 = jnp.sqrt(jnp.maximum(R - d + 6.0 * se, 1e-12))
    xg = jnp.asarray(_GL_X)
    w = jnp.asarray(_GL_W)
    v = 0.5 * (v1 - v0)[..., None] * (xg + 1.0) + v0[..., None]  # (n, nodes)
    dprime = R[..., None] - v * v
    g = jnp.exp(-0.5 * ((d[..., None] - dprime) / se) ** 2) / (se * math.sqrt(2 * math.pi))
    rad = _radiance(p, dprime / R[..., None], cpsi[..., None], alpha0)
    integ = jnp.sum(w * rad * g * 2.0 * v, axis=-1) * 0.5 * (v1 - v0)
    return p.ymin + p.amp * integ


def _vec_f(theta, rc):
    return limb_profile_intensity(LimbProfileParams.from_vector(theta), rc)


_jac = jax.jacfwd(_vec_f, argnums=0)


def _profile_jac(p: LimbProfileParams, rc):
    return _jac(p.to_vector(), rc)


def _profile_cols(p: LimbProfileParams, rc):
    J = _jac(p.to_vector(), rc)
    return tuple(J[:, i] for i in range(J.shape[1]))


LIMB_PROFILE = LimbModel("lunar_limb", LimbProfileParams, limb_profile_intensity, _profile_jac, _profile_cols)
"""The physical lunar-Lambert limb profile model (circle geometry)."""


def lunar_lambert_weight(phase_rad: float, coeffs=(-0.019, 2.42e-4, -1.46e-6)) -> float:
    """McEwen's ``L(alpha)`` (alpha in degrees, clipped to [0, 1])."""
    a = math.degrees(phase_rad)
    A, B, C = coeffs
    return float(min(1.0, max(0.0, 1.0 + A * a + B * a * a + C * a**3)))


def sphere_from_circle_fit(focal_px: float, principal_point_rc, center_rc, mean_radius: float,
                           tol: float = 1e-14, max_iter: int = 60) -> SphereImage:
    """The sphere whose image ellipse has centre ``center_rc`` and mean radius ``(a + b)/2 = mean_radius``.

    1-D Newton on ``alpha`` (the centre equation gives ``theta`` in closed form), then
    :func:`~jaxlimb.pipeline.sphere.sphere_from_ellipse_center` with the matching ``a``.
    """
    f = float(focal_px)
    r0, c0 = (float(v) for v in principal_point_rc)
    k = math.hypot(float(center_rc[0]) - r0, float(center_rc[1]) - c0) / f

    def mean_ab(alpha: float) -> float:
        s = math.sin(alpha)
        th = math.atan(_tan_theta(k, s))
        den = math.cos(th) ** 2 - s * s
        return 0.5 * (s * math.cos(alpha) / den + s / math.sqrt(den))

    target = float(mean_radius) / f
    alpha = math.atan(target)
    for _ in range(max_iter):
        h = 1e-6 * alpha
        dm = (mean_ab(alpha + h) - mean_ab(alpha - h)) / (2 * h)
        if not (math.isfinite(dm) and dm > 0):
            raise GeometryError(f"no sphere has an image of mean radius {mean_radius!r} px there")
        step = (mean_ab(alpha) - target) / dm
        alpha -= step
        if abs(step) <= tol * alpha:
            break
    a = f * _a_of_alpha(k, alpha)
    return sphere_from_ellipse_center(f, principal_point_rc, center_rc, a)


__all__ = ["LIMB_PROFILE", "PROFILE_FIXED", "LimbProfileParams", "limb_profile_intensity", "lunar_lambert_weight",
           "sphere_from_circle_fit"]
