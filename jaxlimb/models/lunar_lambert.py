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

by 20-point Gauss-Legendre quadrature, :math:`v_{0,1} = \sqrt{\max(0, R - d \mp 6\sigma_e)}`
(the substitution removes the square-root behaviour of :math:`\mu` at the limb; the window is cut to
its lit side of the terminator, :func:`_lit_limits`), and
:math:`\sigma_e^2 = \sigma^2 + 1/12` (pixel integration as a box), plus the first-order
curvature term of the 2-D blur, :math:`\sigma_e^2/(2d)\,\partial f/\partial d` (without it the
radius of a 33 px Moon came out 0.01-0.024 px short; with it |bias| <= 0.008 px from 33 to 210 px,
``benchmarks/locate_accuracy.py`` bias study).  Parameters
``(r0, c0, a, sigma, amp, ymin)`` are estimated; ``theta, rho`` (limb ellipse shape),
``sun_r, sun_c`` (unit image direction of the Sun), ``phase`` (rad), ``inv_f`` (1/focal px;
0 = orthographic) and ``L`` are held fixed (``fixed=PROFILE_FIXED``).  The Jacobian is computed in
the same pass as the intensity, by differentiating under the integral (13 columns for about
three times the cost of the intensity; ``jax.jacfwd`` took 13 times) and is checked against
``jax.jacfwd``.

Widened (:data:`LIMB_PROFILE_MINNAERT`, :class:`MinnaertProfileParams`): the radiance times
:math:`(\mu_0\mu)^{-\kappa}`, at ``L = 0`` Minnaert's law :math:`\mu_0^k\mu^{k-1}` with :math:`k = 1 - \kappa`
(Minnaert 1941); its rim diverges as :math:`\mu^{-\kappa}`, brighter than any lunar-Lambert rim.  The
derivative in :math:`\kappa` is :math:`-\ln(\mu_0\mu) I`; the pipeline frees :math:`\kappa` only when a score
test asks for it (:func:`jaxlimb.pipeline.profile.widen.widen_brightening`).

Widened (:data:`LIMB_PROFILE_GLOW`, :class:`GlowProfileParams`): plus a glow above the limb, an optically thin
shell whose emission falls as :math:`e^{-h/H}` with the altitude (a horizon glow of dust or an exosphere; the
``glow`` family of :mod:`jaxlimb.render.independent`): ``glow`` times :math:`e^{-s/H}` at a distance ``s`` above the
limb, and times half the grazing column, :math:`\tfrac12\mathrm{erfcx}(\sqrt{u/H})`, at a depth ``u`` on the disc
(:func:`_glow_inside`, :func:`_glow_outside`); ``H = exp(log_h)`` px.  The disc side is integrated with the
radiance; the sky side blurred in closed form.  The pipeline adds the glow only when a score test asks for it
(:func:`jaxlimb.pipeline.profile.glow.widen_glow`).  The shell is lit by the Sun: at the limb point of image
position angle :math:`\psi` from the Sun's image direction the solar elevation over the tangent point is
:math:`\sin^{-1}(\sin\alpha\cos\psi)` (phase :math:`\alpha`), so the glow is brighter toward the Sun.  To first
order in ``cpsi`` :math:`= \cos\psi` its radiance is ``glow (1 + glow_tilt cpsi)`` (``glow_tilt`` fitted; 0 is a
uniform glow).  Why: on the nearly full Earth of ``benchmarks/earth_full_disc.py`` (phase 4-12 deg) a glow lit as
``clip((n.s + 0.2)/0.4)`` (the independent renderer) put the uniform-glow fit's centre 0.03-0.19 px sunward with
its sigma 0.01-0.06 px (NEES 6.5-17); rendered with a uniform glow, the same frames were 0.006 and 0.017 px off.

Off the optical axis the limb is an ellipse (``a - b`` reaches ~5 px at the corner of the
default imager for the Moon at 60 000 km): the model carries the ellipse ``(r0, c0, a, theta,
rho)``; with a camera, ``theta`` and ``rho`` are held at the values of the image of a sphere
at the current estimate and iterated, exactly as the sigmoid's body-centre correction
(:func:`jaxlimb.pipeline.sphere.fits.fit_sphere_annulus`), and ``(r0, c0, a)`` map exactly to the
body centre (:func:`jaxlimb.geometry.sphere_image.sphere_from_ellipse_center`).  Without a camera
``rho = 1`` (a circle of radius ``a``).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from ._base import LimbModel, LimbParams
from .sigmoid import ellipse_coords

#: Gauss-Legendre nodes of the blur integral (module docstring).
N_NODES = 20
_GL_X, _GL_W = np.polynomial.legendre.leggauss(N_NODES)


@contextmanager
def quadrature_nodes(n: int) -> Iterator[None]:
    """Evaluate the profile with an ``n``-node rule inside the block (functions traced inside it).

    The analytic Jacobian is the derivative of the *integral*; ``jax.jacfwd`` and central
    differences differentiate the *rule*.  They agree to the rule's error on the derivative
    (~5e-4 of a column's scale at 20 nodes, ~1e-6 at 64), so checks of the formulas use more nodes.
    """
    global _GL_X, _GL_W
    old = _GL_X, _GL_W
    _GL_X, _GL_W = np.polynomial.legendre.leggauss(int(n))
    try:
        yield
    finally:
        _GL_X, _GL_W = old
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


class MinnaertProfileParams(LimbProfileParams):
    """:class:`LimbProfileParams` and ``kappa``, the limb-brightening exponent of
    :data:`LIMB_PROFILE_MINNAERT`: the lunar-Lambert radiance times ``(mu0 mu)^-kappa`` (at ``L = 0``
    Minnaert's law ``mu0^k mu^(k-1)``, Minnaert 1941, with ``k = 1 - kappa``)."""

    kappa: ArrayLike


class GlowProfileParams(LimbProfileParams):
    """:class:`LimbProfileParams` and an exponential glow above the limb (:data:`LIMB_PROFILE_GLOW`):
    ``glow``, its radiance just above the limb in units of ``amp`` where the limb's normal is square to the Sun's
    image direction, ``log_h``, the log of its scale height (px), and ``glow_tilt``, its linear change with the
    cosine ``cpsi`` of the angle between the limb's normal and the Sun's image direction: the glow's radiance is
    ``glow (1 + glow_tilt cpsi)`` (module docstring)."""

    glow: ArrayLike
    log_h: ArrayLike
    glow_tilt: ArrayLike = 0.0


class AnisoProfileParams(LimbProfileParams):
    """:class:`LimbProfileParams` and an anisotropic blur (:data:`LIMB_PROFILE_ANISO`): ``s2c, s2s`` (px^2), the
    cos 2psi and sin 2psi terms of the blur variance across the limb, ``sigma_e^2(psi) = sigma^2 + 1/12 + s2c cos 2psi
    + s2s sin 2psi`` with ``psi`` the angle of the ray from the centre (the limb normal's, from ``+col`` toward
    ``-row``).  A line smear of length ``l`` at angle ``phi`` adds ``l^2/12 cos^2(psi - phi)`` to a Gaussian's
    variance across an edge: ``l^2/24 (1 + cos 2(psi - phi))``, the mean in ``sigma^2``, the rest in ``s2c, s2s``."""

    s2c: ArrayLike
    s2s: ArrayLike


def _cos_sin_small(x, small):
    """``(cos x, sin x)``; by Taylor series (to 1e-16 for ``|x| <= 0.2``) when ``small`` (a
    scalar: the body's angular radius, which bounds ``|x|``, is below 0.2 rad), else
    ``jnp.cos``, ``jnp.sin`` (the series is ~5x cheaper)."""

    def series(x):
        x2 = x * x
        c = 1.0 - x2 / 2.0 * (1.0 - x2 / 12.0 * (1.0 - x2 / 30.0 * (1.0 - x2 / 56.0 * (1.0 - x2 / 90.0))))
        s = x * (1.0 - x2 / 6.0 * (1.0 - x2 / 20.0 * (1.0 - x2 / 42.0 * (1.0 - x2 / 72.0 * (1.0 - x2 / 110.0)))))
        return c, s

    return jax.lax.cond(small, series, lambda x: (jnp.cos(x), jnp.sin(x)), x)


def _radiance_parts(p: LimbProfileParams, v, R, cpsi, alpha0, brightened: bool = True):
    """Radiance and its partial derivatives at depth ``v**2`` below the limb (module docstring).

    With ``q = 1 - v^2/R`` the emission cosine is computed as ``mu = v sqrt((1 + q)/R)``
    (no cancellation in ``1 - q^2`` at the limb).  Returns ``I`` and, at fixed ``v``,
    ``dI/dR``, ``dI/dcpsi``, ``dI/dalpha0``, ``dI/dphase``, ``dI/dL``, ``dI/dkappa``.
    ``brightened``: with the limb brightening ``(mu0 mu)^-p.kappa`` (:class:`MinnaertProfileParams`);
    ``dI/dkappa`` is returned in either case (at ``kappa = 0`` without it).  A separate model and not a
    parameter held at 0: on CPU the brightening's terms cost the one-pass Jacobian 2.5-3x (XLA repeats
    them in every column's reduction; a ``lax.cond`` on ``kappa = 0`` did not help).
    """
    v2 = v * v
    inv_R = 1.0 / R
    q = jnp.clip(1.0 - v2 * inv_R, 0.0, 1.0)
    rt = jnp.sqrt((1.0 + q) * inv_R)
    mu = v * rt
    q_R = v2 * inv_R * inv_R
    mu_R = -v * q * inv_R / (R * rt)
    beta = q * alpha0
    cb, sb = _cos_sin_small(beta, jnp.abs(alpha0) <= 0.2)
    s_em = q * cb - mu * sb  # sin(e - beta)
    c_em = mu * cb + q * sb  # cos(e - beta)
    sph, cph = jnp.sin(p.phase), jnp.cos(p.phase)
    a_s = sph * cpsi
    mu0 = s_em * a_s + c_em * cph
    lit = mu0 > 0
    m0 = jnp.where(lit, mu0, 0.0)
    inv_den = 1.0 / jnp.where(lit, m0 + mu, 1.0)
    two_L = 2.0 * p.L
    ratio = m0 * inv_den  # mu0 / (mu0 + mu)
    # (mu0 mu)^-kappa: Minnaert's limb brightening (L = 0: mu0^k mu^(k-1) with k = 1 - kappa); 1 at kappa = 0
    log_mm = jnp.log(jnp.where(lit & (mu > 0), m0 * mu, 1.0))
    kappa = p.kappa if brightened else 0.0
    brighten = jnp.exp(-kappa * log_mm) if brightened else 1.0
    I = (two_L * ratio + (1.0 - p.L) * m0) * brighten
    # d/dmu0 of the brightened law: its lunar-Lambert part minus kappa I / mu0 (ratio / mu0 = inv_den)
    I_mu0 = jnp.where(lit, (two_L * (mu * inv_den - kappa) * inv_den + (1.0 - p.L) * (1.0 - kappa)) * brighten, 0.0)
    I_mu = -two_L * ratio * inv_den * brighten
    # d mu0 / d beta, / d R (fixed v), / d cpsi, / d phase
    mu0_beta = -c_em * a_s + s_em * cph
    s_R = q_R * cb - mu_R * sb
    c_R = mu_R * cb + q_R * sb
    mu0_R = s_R * a_s + c_R * cph + mu0_beta * q_R * alpha0
    # the mu part of d(mu^-kappa)/dR at fixed v: -kappa I (mu_R / mu), mu_R / mu = -q / (R (1 + q)) (finite at the limb)
    I_R = I_mu0 * mu0_R + I_mu * mu_R
    if brightened:
        I_R = I_R + kappa * I * q / (R * (1.0 + q))
    I_cpsi = I_mu0 * s_em * sph
    I_a0 = I_mu0 * mu0_beta * q
    I_ph = I_mu0 * (s_em * cph * cpsi - c_em * sph)
    I_L = (2.0 * ratio - m0) * brighten
    I_k = -log_mm * I
    return I, I_R, I_cpsi, I_a0, I_ph, I_L, I_k


def _terminator_depth(p: LimbProfileParams, R, cpsi, alpha0):
    """``v_t``, the root of the depth where the ray meets the terminator (``mu0 = 0``), and which side is lit.

    ``mu0 = sin(g) sin(phase) cpsi + cos(g) cos(phase)`` with ``g = e - beta = e - alpha0 sin e`` (module
    docstring) vanishes at ``g_t = atan(-cos(phase) / (sin(phase) cpsi))`` in ``(-pi/2, pi/2]``; ``e_t`` from
    two Newton steps on ``e - alpha0 sin e = g_t`` from ``g_t + alpha0 sin g_t`` (one left ``v_t`` off by
    O(alpha0^4) rad, and the columns 3e-4 from autodiff at a 0.21 rad body's horn), then ``v_t^2 = R (1 - sin e_t)``.
    Also returns whether the shallow side (``g > g_t``) is the lit one: ``d mu0 / dg`` at the unwrapped root
    ``atan2(-cos(phase), sin(phase) cpsi)`` is ``sqrt(a_s^2 + cos^2 phase) > 0``, and it changes sign when the
    root is shifted by pi into ``(-pi/2, pi/2]``.  A root beyond the centre (``g_t < 0``) gives ``v_t`` at the
    centre, one beyond the limb ``v_t = 0``: the caller's clip to the window then keeps all or none of it.
    """
    theta = jnp.arctan2(-jnp.cos(p.phase), jnp.sin(p.phase) * cpsi)
    wrapped = (theta > 0.5 * math.pi) | (theta <= -0.5 * math.pi)
    g = jnp.where(theta > 0.5 * math.pi, theta - math.pi, jnp.where(theta <= -0.5 * math.pi, theta + math.pi, theta))
    e = g + alpha0 * jnp.sin(g)
    for _ in range(2):  # error O(alpha0^8) rad: the cut must sit on the terminator (the columns have no boundary term)
        e = e - (e - alpha0 * jnp.sin(e) - g) / (1.0 - alpha0 * jnp.cos(e))
    return jnp.sqrt(jnp.maximum(R * (1.0 - jnp.sin(jnp.clip(e, 0.0, 0.5 * math.pi))), 1e-12)), ~wrapped  # (as v0, v1)


def _lit_limits(p: LimbProfileParams, v0, v1, R, cpsi, alpha0):
    """The blur integral's limits cut to the lit part of ``[v0, v1]``.

    The radiance is 0 beyond the terminator and its slope jumps there; a Gauss-Legendre rule across that
    kink converges slowly (at a 117 deg crescent's horn, 20 nodes put the intensity 0.17 DN of 217 off and
    the columns of the rule, which ``jax.jacfwd`` differentiates, several % off at 64 nodes), while on the lit
    segment alone the integrand is smooth.  The cut's own derivative term is the integrand at the terminator,
    which is 0, so the columns of :func:`_profile_integrals` need no boundary term.  A ray meets the
    terminator at most once (``mu0`` is a sinusoid in ``e - beta``, which spans less than pi).
    """
    # g = e - beta falls monotonically with depth (dg/de = 1 - alpha0 cos e > 0): the shallow side of v_t is
    # [v0, v_t], the deep side [v_t, v1]
    vt, shallow_lit = _terminator_depth(p, R, cpsi, alpha0)
    vt = jnp.clip(vt, v0, v1)
    return jnp.where(shallow_lit, v0, vt), jnp.where(shallow_lit, vt, v1)


def limb_geometry(p: LimbProfileParams, rc):
    """``(dr, dc, x, y, d, beta, R, cpsi)`` of the pixels ``rc``: offsets from the centre, ellipse-frame
    coordinates, distance ``d`` from the centre, the limb's radius ``R`` in the pixel's direction and the
    cosine of its angle from the Sun's image direction (module docstring)."""
    rc = jnp.asarray(rc)
    dr = rc[..., 0] - p.r0
    dc = rc[..., 1] - p.c0
    x, y = ellipse_coords(p, rc)
    d2 = dr * dr + dc * dc
    d = jnp.sqrt(jnp.where(d2 > 0, d2, 1.0))
    b2 = p.rho * p.rho * x * x + y * y
    beta = jnp.sqrt(jnp.where(b2 > 0, b2, 1.0))
    R = p.rho * p.a * d / beta
    cpsi = (dr * p.sun_r + dc * p.sun_c) / d
    return dr, dc, x, y, d, beta, R, cpsi


_INV_SQRT_PI = 1.0 / math.sqrt(math.pi)


def _erfcx(x):
    """``exp(x^2) erfc(x)`` (``jax.scipy.special.erfcx``), finite for any real ``x``."""
    return jax.scipy.special.erfcx(x)


def _glow_inside(p: GlowProfileParams, v):
    r"""The glow's radiance (units of ``amp``) at depth ``u = v^2`` inside the limb and its ``log_h`` derivative.

    An optically thin shell whose emission falls as :math:`e^{-h/H}` with the altitude ``h`` (the glow of
    :mod:`jaxlimb.render.independent.optics`, a dust or exosphere horizon glow): seen on the disc at depth ``u``
    below the limb the ray leaves the surface at the emission cosine :math:`\mu = \sqrt{2u/R}` and climbs
    :math:`h \approx \mu t + t^2/2R` along its length ``t``; its column over the grazing column
    :math:`\sqrt{2\pi R H}` (which sets ``glow``) is, with :math:`x = \sqrt{u/H}` (Chapman 1931's grazing
    integral, the half of a ray in front of the surface),

    .. math:: \frac{1}{\sqrt{2\pi RH}}\int_0^\infty e^{-(\mu t + t^2/2R)/H}\,dt = \tfrac12\,\mathrm{erfcx}(x),

    1/2 at the limb, :math:`\sqrt{H/4\pi u}` deep inside.  ``d erfcx(x)/dx = 2x erfcx(x) - 2/sqrt(pi)``,
    ``dx/dlog_h = -x/2``."""
    x = v * jnp.exp(-0.5 * p.log_h)
    ex = _erfcx(x)
    G = 0.5 * ex
    G_lh = -0.5 * x * (x * ex - _INV_SQRT_PI)
    return G, G_lh


def _glow_outside(p: GlowProfileParams, s, se, d, derivatives: bool):
    r"""The blurred glow above the limb (units of ``amp`` per unit ``glow``) at signed distance ``s = d - R``
    (px, positive outside) and, if asked, its partials in ``d``, ``R``, ``se`` and ``log_h``.

    The radiance :math:`e^{-s'/H}` for :math:`s' > 0` (the miss column of the shell,
    :math:`2p K_1(p/H) e^{p/H} e^{-(p-R)/H}`, over the grazing one, to :math:`O(s/R)`) convolved with the
    Gaussian :math:`N(\cdot;\sigma_e)`: completing the square,

    .. math:: E(s) = \int_0^\infty e^{-t/H} N(s - t)\,dt = e^{\sigma_e^2/2H^2 - s/H}\,
              \Phi\big(s/\sigma_e - \sigma_e/H\big),

    evaluated as ``exp(a - s/H + log Phi(w))`` (no overflow for ``H << se``).  Derivatives in closed form:
    :math:`E' = N - E/H`, :math:`E'' = N' - E'/H` (``N' = -s N / se^2``), :math:`\partial_{\sigma_e} E = \sigma_e E''`
    (the heat equation), :math:`H\,\partial_H E = (s E + \sigma_e^2 E')/H`.  As the profile
    (:func:`_profile_integrals`), the 2-D blur adds the curvature term :math:`\sigma_e^2/(2d)\,E'`.
    """
    H = jnp.exp(p.log_h)
    inv_H = 1.0 / H
    w = s / se - se * inv_H
    E = jnp.exp(0.5 * (se * inv_H) ** 2 - s * inv_H + jax.scipy.special.log_ndtr(w))
    N = jnp.exp(-0.5 * (s / se) ** 2) / (se * math.sqrt(2.0 * math.pi))
    E1 = N - E * inv_H
    k = se * se / (2.0 * d)
    G = E + k * E1
    if not derivatives:
        return G, None
    N1 = -s / (se * se) * N
    N2 = (s * s / se**4 - 1.0 / (se * se)) * N
    E2 = N1 - E1 * inv_H
    E3 = N2 - E2 * inv_H
    E_lh = (s * E + se * se * E1) * inv_H
    E1_lh = (E + s * E1 + se * se * E2) * inv_H  # d/ds of E_lh
    parts = {
        "G_d": E1 + k * (E2 - E1 / d),
        "G_R": -(E1 + k * E2),
        "G_se": se * E2 + k * se * E3 + se / d * E1,
        "G_lh": E_lh + k * E1_lh,
    }
    return G, parts


def _blur_nodes(d, R, se, lit=None):
    """The quadrature of the radial blur (module docstring): nodes ``v`` (depth ``v^2``) ``(n, nodes)``, the
    Gaussian's argument ``t = (d - R + v^2) / se`` and the weights ``g`` (Gaussian x ``2v dv`` x rule weights).
    ``lit = (p, cpsi, alpha0)``: the window cut to its lit side of the terminator (:func:`_lit_limits`), for
    the radiance; ``None`` for the glow, which the terminator does not bound."""
    v0 = jnp.sqrt(jnp.maximum(R - d - 6.0 * se, 1e-12))
    v1 = jnp.sqrt(jnp.maximum(R - d + 6.0 * se, 1e-12))
    if lit is not None:
        v0, v1 = _lit_limits(lit[0], v0, v1, R, lit[1], lit[2])
    xg = jnp.asarray(_GL_X)
    half = 0.5 * (v1 - v0)
    w = jnp.asarray(_GL_W) * (2.0 * half)[..., None]
    v = half[..., None] * (xg + 1.0) + v0[..., None]  # (n, nodes)
    sn = jnp.asarray(se)[..., None]  # one sigma_e per pixel (AnisoProfileParams) or one for all
    t = (d[..., None] - R[..., None] + v * v) / sn  # (d - d') / se
    g = jnp.exp(-0.5 * t * t) * (v * w / (sn * math.sqrt(2 * math.pi)))  # Gaussian x 2v dv / 2 ... x weights
    return v, t, g


def _blur_moments(J, t, g, se, second: bool):
    """The blur of ``J`` on the nodes ``(t, g)`` of :func:`_blur_nodes`: ``F1 = int J g`` and ``dF1/dd``; with
    ``second`` also ``d^2F1/dd^2`` and ``-int J t (t^2 - 3) g / se^2`` (the ``se`` partial of ``dF1/dd``, up to the
    chain factor); ``None`` for those otherwise."""
    m0, m1 = jnp.sum(J * g, axis=-1), -jnp.sum(J * t * g / jnp.asarray(se)[..., None], axis=-1)
    if not second:
        return m0, m1, None, None
    return (m0, m1, jnp.sum(J * (t * t - 1.0) * g, axis=-1) / (se * se),
            -jnp.sum(J * t * (t * t - 3.0) * g, axis=-1) / (se * se))


def _profile_integrals(p: LimbProfileParams, d, R, cpsi, derivatives: bool, brightened: bool = True,
                       glowing: bool = False, s2=None):
    """The blurred profile ``F`` (module docstring) and, if asked, its partials.

    ``F = F1 + sigma_e^2 / (2 d) dF1/dd``: the 1-D radial blur ``F1`` plus the first-order
    curvature term of the 2-D blur of a round edge (the ``(1/r) d/dr`` part of the Laplacian:
    the blurred disc's edge moves inward by ``sigma_e^2 / 2R``, 0.02 px for ``R = 33 px``,
    ``sigma = 1.2 px``).  Partials ``F_d, F_R`` (at fixed ``d``/``R``), ``F_cpsi, F_se, F_a0,
    F_ph, F_L``: the integrands differentiated under the integral; the limits sit 6 sigma out
    in the Gaussian, so their own derivative terms are below 1e-8 of ``F``'s and are dropped.
    ``brightened``: as :func:`_radiance_parts`.  ``glowing`` (:class:`GlowProfileParams`): plus ``p.glow``
    times the glow on the disc side (:func:`_glow_inside`, in the integrand) and above the limb
    (:func:`_glow_outside`, closed form); partials ``F_glow``, ``F_lh``.  ``s2``: the per-pixel anisotropic
    variance of :class:`AnisoProfileParams` (:func:`_aniso_terms`), added to ``sigma_e^2``.
    """
    alpha0 = jnp.arctan(p.rho * p.a * p.inv_f)
    se = jnp.sqrt(p.sigma * p.sigma + 1.0 / 12.0 + (0.0 if s2 is None else s2))
    v, t, g = _blur_nodes(d, R, se, (p, cpsi, alpha0))
    I, I_R, I_cpsi, I_a0, I_ph, I_L, I_k = _radiance_parts(p, v, R[..., None], cpsi[..., None], alpha0, brightened)
    tg = t * g / jnp.asarray(se)[..., None]  # -dg/dd
    F1, F1_d, F1_dd, F1_dse = _blur_moments(I, t, g, se, derivatives)
    if glowing:  # the glow seen on the disc, on its own (uncut) nodes: independent of R, alpha0, phase, L
        gl = p.glow * (1.0 + p.glow_tilt * cpsi)  # the glow at this position angle (GlowProfileParams)
        vg, t_gl, g_gl = _blur_nodes(d, R, se)
        tg_gl = t_gl * g_gl / jnp.asarray(se)[..., None]
        I_gl, I_lh = _glow_inside(p, vg)
        I_lh = gl[..., None] * I_lh
        G1, G1_d, G1_dd, G1_dse = _blur_moments(I_gl, t_gl, g_gl, se, derivatives)
        F1, F1_d = F1 + gl * G1, F1_d + gl * G1_d
    s2d = se * se / (2.0 * d)
    F = F1 + s2d * F1_d
    if glowing:
        Go, Po = _glow_outside(p, d - R, se, d, derivatives)
        F = F + gl * Go
    if not derivatives:
        return F, None
    if glowing:
        F1_dd, F1_dse = F1_dd + gl * G1_dd, F1_dse + gl * G1_dse

    def pair(J, g=g, tg=tg):  # (integral of J g, of -J tg): a partial of F1 and the matching partial of F1_d
        return jnp.sum(J * g, axis=-1), -jnp.sum(J * tg, axis=-1)

    F1_R, F1_dR = pair(I_R)
    F1_cp, F1_dcp = pair(I_cpsi)
    F1_a0, F1_da0 = pair(I_a0)
    F1_ph, F1_dph = pair(I_ph)
    F1_L, F1_dL = pair(I_L)
    F1_k, F1_dk = pair(I_k)
    F1_se = F1_dd * se
    parts = {
        "F_d": F1_d + s2d * (F1_dd - F1_d / d),
        "F_R": (-F1_d + F1_R) + s2d * (-F1_dd + F1_dR),
        "F_cpsi": F1_cp + s2d * F1_dcp,
        "F_se": F1_se + s2d * F1_dse + se / d * F1_d,
        "F_a0": F1_a0 + s2d * F1_da0,
        "F_ph": F1_ph + s2d * F1_dph,
        "F_L": F1_L + s2d * F1_dL,
        "F_k": F1_k + s2d * F1_dk,
        "alpha0": alpha0,
        "se": se,
    }
    if glowing:
        F1_g, F1_dg = pair(I_gl, g_gl, tg_gl)
        F1_lh, F1_dlh = pair(I_lh, g_gl, tg_gl)
        unit = F1_g + s2d * F1_dg + Go  # the blurred glow of unit radiance
        parts["F_glow"] = (1.0 + p.glow_tilt * cpsi) * unit
        parts["F_tilt"] = p.glow * cpsi * unit
        parts["F_cpsi"] = parts["F_cpsi"] + p.glow * p.glow_tilt * unit
        parts["F_lh"] = F1_lh + s2d * F1_dlh + gl * Po["G_lh"]
        parts["F_d"] = parts["F_d"] + gl * Po["G_d"]
        parts["F_R"] = parts["F_R"] + gl * Po["G_R"]
        parts["F_se"] = parts["F_se"] + gl * Po["G_se"]
    return F, parts


def _aniso_terms(dr, dc, d):
    """``cos 2psi, sin 2psi`` of the ray ``(dr, dc)`` (length ``d``; ``psi`` from ``+col`` toward ``-row``) and their
    partials in ``r0, c0`` (``dr = r - r0``): ``(C, S, C_r0, C_c0, S_r0, S_c0)``."""
    d4 = d * d * d * d
    dif = dc * dc - dr * dr
    return (dif / (d * d), -2.0 * dr * dc / (d * d), 4.0 * dr * dc * dc / d4, -4.0 * dc * dr * dr / d4,
            2.0 * dc * dif / d4, -2.0 * dr * dif / d4)


def _aniso_var(p: LimbProfileParams, terms):
    """The anisotropic part of the blur variance of :class:`AnisoProfileParams` per pixel from its
    :func:`_aniso_terms` (``None`` for the other profiles, ``terms`` then ``None``)."""
    if terms is None:
        return None
    return p.s2c * terms[0] + p.s2s * terms[1]


def _aniso_terms_of(p: LimbProfileParams, dr, dc, d):
    """:func:`_aniso_terms` for :class:`AnisoProfileParams`, ``None`` for the other profiles."""
    return _aniso_terms(dr, dc, d) if isinstance(p, AnisoProfileParams) else None


def limb_profile_intensity(p: LimbProfileParams, rc):
    """Blurred limb radiance (module docstring) at pixels ``rc`` ``(n, 2)``.

    Along the ray from the ellipse centre through a pixel at distance ``d``, the limb is at
    ``R = rho a d / beta`` (``beta = sqrt(rho^2 x^2 + y^2)`` in the ellipse frame of
    :func:`jaxlimb.models.ellipse_coords`); the circle formulas apply with that ``R``.
    """
    dr, dc, _, _, d, _, R, cpsi = limb_geometry(p, rc)
    F, _ = _profile_integrals(p, d, R, cpsi, False, isinstance(p, MinnaertProfileParams),
                              isinstance(p, GlowProfileParams), _aniso_var(p, _aniso_terms_of(p, dr, dc, d)))
    return p.ymin + p.amp * F


@jax.jit
def brightening_column(p: LimbProfileParams, rc):
    """The column of ``kappa`` (:class:`MinnaertProfileParams`) at ``kappa = 0``: the derivative of the
    profile ``p`` toward Minnaert-like limb brightening, for a score test (the whole brightened Jacobian
    costs 2.5x the profile's; this column alone, about one intensity)."""
    _, _, _, _, d, _, R, cpsi = limb_geometry(p, rc)
    _, P = _profile_integrals(p, d, R, cpsi, True, False)
    return p.amp * P["F_k"]


def _profile_value_and_columns(p: LimbProfileParams, rc):
    """Intensity and all 13 Jacobian columns from one pass (derivatives under the integral).

    The chain rule from the per-pixel quantities ``(d, R, cpsi, se, alpha0)`` to the
    parameters is written out; checked against ``jax.jacfwd`` of :func:`limb_profile_intensity`
    in ``tests/pipeline/test_profile.py``.
    """
    dr, dc, x, y, d, beta, R, cpsi = limb_geometry(p, rc)
    brightened = isinstance(p, MinnaertProfileParams)
    glowing = isinstance(p, GlowProfileParams)
    aniso = _aniso_terms_of(p, dr, dc, d)
    F, P = _profile_integrals(p, d, R, cpsi, True, brightened, glowing, _aniso_var(p, aniso))
    A = p.amp
    ct, st = jnp.cos(p.theta), jnp.sin(p.theta)
    # d/dr0, d/dc0 of d, beta, R, cpsi
    d_r0, d_c0 = -dr / d, -dc / d
    x_r0, x_c0, y_r0, y_c0 = st, -ct, ct, st
    rho2 = p.rho * p.rho
    b_r0 = (rho2 * x * x_r0 + y * y_r0) / beta
    b_c0 = (rho2 * x * x_c0 + y * y_c0) / beta
    R_r0 = R * (d_r0 / d - b_r0 / beta)
    R_c0 = R * (d_c0 / d - b_c0 / beta)
    cp_r0 = (-p.sun_r - cpsi * d_r0) / d
    cp_c0 = (-p.sun_c - cpsi * d_c0) / d
    # theta: x_th = -y... (x, y rotate with theta): dx/dtheta = y, dy/dtheta = -x
    b_th = (rho2 * x * y - y * x) / beta
    R_th = -R * b_th / beta
    R_rho = R / p.rho - R * (p.rho * x * x) / (beta * beta)
    u = p.rho * p.a * p.inv_f
    a0_common = 1.0 / (1.0 + u * u)
    F_d, F_R, F_cp, F_a0 = P["F_d"], P["F_R"], P["F_cpsi"], P["F_a0"]
    cols = {
        "r0": A * (F_d * d_r0 + F_R * R_r0 + F_cp * cp_r0),
        "c0": A * (F_d * d_c0 + F_R * R_c0 + F_cp * cp_c0),
        "a": A * (F_R * R / p.a + F_a0 * a0_common * p.rho * p.inv_f),
        "theta": A * F_R * R_th,
        "rho": A * (F_R * R_rho + F_a0 * a0_common * p.a * p.inv_f),
        "sigma": A * P["F_se"] * p.sigma / P["se"],
        "amp": F,
        "ymin": jnp.ones_like(F),
        "sun_r": A * F_cp * dr / d,
        "sun_c": A * F_cp * dc / d,
        "phase": A * P["F_ph"],
        "inv_f": A * F_a0 * a0_common * p.rho * p.a,
        "L": A * P["F_L"],
        "kappa": A * P["F_k"],
    }
    if glowing:
        cols.update(glow=A * P["F_glow"], log_h=A * P["F_lh"], glow_tilt=A * P["F_tilt"])
    if aniso is not None:  # d sigma_e / d s2 = (cos 2psi or sin 2psi) / (2 sigma_e); psi moves with r0, c0
        C, S, C_r0, C_c0, S_r0, S_c0 = aniso
        ws = A * P["F_se"] / (2.0 * P["se"])
        cols.update(r0=cols["r0"] + ws * (p.s2c * C_r0 + p.s2s * S_r0), c0=cols["c0"] + ws * (p.s2c * C_c0 + p.s2s * S_c0),
                    s2c=ws * C, s2s=ws * S)
    return p.ymin + A * F, tuple(cols[n] for n in type(p).field_names())


def _profile_cols(p: LimbProfileParams, rc):
    return _profile_value_and_columns(p, rc)[1]


def _profile_jac(p: LimbProfileParams, rc):
    return jnp.stack(_profile_cols(p, rc), axis=-1)


LIMB_PROFILE = LimbModel("lunar_limb", LimbProfileParams, limb_profile_intensity, _profile_jac, _profile_cols,
                         _profile_value_and_columns)
"""The physical lunar-Lambert limb profile model (circle geometry)."""
LIMB_PROFILE_MINNAERT = LimbModel("lunar_limb_minnaert", MinnaertProfileParams, limb_profile_intensity, _profile_jac,
                                  _profile_cols, _profile_value_and_columns)
"""The profile widened by a limb-brightening exponent ``kappa`` (:class:`MinnaertProfileParams`)."""
LIMB_PROFILE_GLOW = LimbModel("lunar_limb_glow", GlowProfileParams, limb_profile_intensity, _profile_jac,
                              _profile_cols, _profile_value_and_columns)
"""The profile widened by an exponential glow above the limb (:class:`GlowProfileParams`)."""
LIMB_PROFILE_ANISO = LimbModel("lunar_limb_aniso", AnisoProfileParams, limb_profile_intensity, _profile_jac,
                               _profile_cols, _profile_value_and_columns)
"""The profile with an anisotropic blur (:class:`AnisoProfileParams`: a motion smear)."""


def profile_model(p: LimbProfileParams) -> LimbModel:
    """The profile model of the parameters ``p``: :data:`LIMB_PROFILE_MINNAERT`, :data:`LIMB_PROFILE_GLOW` or
    :data:`LIMB_PROFILE`."""
    if isinstance(p, MinnaertProfileParams):
        return LIMB_PROFILE_MINNAERT
    if isinstance(p, AnisoProfileParams):
        return LIMB_PROFILE_ANISO
    return LIMB_PROFILE_GLOW if isinstance(p, GlowProfileParams) else LIMB_PROFILE


@jax.jit
def glow_column(p: LimbProfileParams, rc, log_h):
    """The column of ``glow`` (:class:`GlowProfileParams`) at ``glow = 0`` and scale height ``exp(log_h)`` px:
    the derivative of the profile ``p`` toward a glow, for a score test (the intensity's cost)."""
    q = GlowProfileParams(*[getattr(p, n) for n in LimbProfileParams.field_names()], 0.0, log_h)
    _, _, _, _, d, _, R, cpsi = limb_geometry(q, rc)
    return q.amp * _glow_unit(q, d, R, jnp.sqrt(q.sigma * q.sigma + 1.0 / 12.0))


def _glow_unit(p: GlowProfileParams, d, R, se):
    """The blurred glow of unit ``glow`` (both sides of the limb, curvature term included)."""
    v, t, g = _blur_nodes(d, R, se)
    G_in, _ = _glow_inside(p, v)
    F1, F1_d, _, _ = _blur_moments(G_in, t, g, se, False)
    return F1 + se * se / (2.0 * d) * F1_d + _glow_outside(p, d - R, se, d, False)[0]


def glow_fields(p: LimbProfileParams) -> dict[str, float]:
    """The glow of a :class:`GlowProfileParams` fit for a report: ``glow`` (units of ``amp``) and
    ``glow_scale_px`` (its scale height); ``glow = 0`` for the other profiles."""
    if not isinstance(p, GlowProfileParams):
        return {"glow": 0.0}
    return {"glow": float(p.glow), "glow_scale_px": math.exp(float(p.log_h)), "glow_tilt": float(p.glow_tilt)}


PHYSICAL_L = (-0.1, 1.1)
"""Lunar-Lambert weights ``L`` a fitted profile may take under ``profile="auto"``: ``[0, 1]`` with a
margin, widened by 3 of the fit's own sigma of ``L`` (a 33 px Moon with 10 DN of noise fits a
Lommel-Seeliger limb, ``L = 1``, at 1.13 now and then)."""


def lunar_lambert_weight(phase_rad: float, coeffs=(-0.019, 2.42e-4, -1.46e-6)) -> float:
    """McEwen's ``L(alpha)`` (alpha in degrees, clipped to [0, 1])."""
    a = math.degrees(phase_rad)
    A, B, C = coeffs
    return float(min(1.0, max(0.0, 1.0 + A * a + B * a * a + C * a**3)))


__all__ = [
    "LIMB_PROFILE",
    "LIMB_PROFILE_ANISO",
    "AnisoProfileParams",
    "LIMB_PROFILE_GLOW",
    "LIMB_PROFILE_MINNAERT",
    "GlowProfileParams",
    "LimbProfileParams",
    "MinnaertProfileParams",
    "brightening_column",
    "glow_column",
    "glow_fields",
    "PHYSICAL_L",
    "PROFILE_FIXED",
    "limb_profile_intensity",
    "lunar_lambert_weight",
    "profile_model",
    "quadrature_nodes",
]
