r"""A limb-darkened disc profile: the blurred image of a self-luminous star (the Sun) near its limb.

Why.  The continuum brightness of the photosphere falls toward the limb.  A sigmoid fitted
across that falling profile puts its 50 % level *inside* the photospheric radius: on the
512 px SDO/HMI image the circular sigmoid's radius is 0.16 px short of ``RSUN_OBS / CDELT``
(``tests/pipeline/test_sdo.py``), and the bias grows with the annulus width.  This model
fits the profile itself, so the radius is the radius of the disc's edge.

Radiance.  Quadratic limb-darkening law (Kopal 1950, Harvard Coll. Obs. Circ. 454;
the form of Allen's *Astrophysical Quantities*, Cox ed. 2000, sec. 14.7, whose 0.6 um
coefficients ``u = 0.88, v = -0.23`` in :math:`1 - u(1-\mu) - v(1-\mu^2)` give ours)

.. math:: I(\mu) = 1 - u_1 (1 - \mu) - u_2 (1 - \mu)^2, \qquad \mu = \sqrt{1 - (d'/R)^2},

at a point of the disc at distance ``d'`` from its centre (``R`` the limb radius, px),
orthographic: the Sun subtends 0.27 deg from 1 AU, so the perspective correction of
``mu`` (``~ (R/f)^2``) is ~1e-5 and the edge of the disc is the circle of radius ``R``.
``I = 0`` outside.  The measured solar law (Pierce & Slaughter 1977, Sol. Phys. 51, 25;
Neckel & Labs 1994, Sol. Phys. 153, 91: fifth-degree polynomials in ``mu``) is well
represented by the quadratic law over the ``mu < 0.5`` rim an annulus fit sees.

Blur.  As :mod:`jaxlimb.models.lunar_lambert`: the observed intensity at distance ``d`` is
``ymin + amp * (I * N_sigma_e)(d)`` along the radial direction (1-D: ``R >> sigma``; the
curvature term is ``~ sigma^2 / (2R)``, < 0.003 px here) with the depth
:math:`R - d' = v^2`,

.. math:: f(d) = y_{\min} + A \int_{v_0}^{v_1} I(R - v^2)\, N(d - R + v^2; \sigma_e)\, 2v\,dv,

24-point Gauss-Legendre in ``v`` on :math:`v_{0,1} = \sqrt{\max(0, R - d \mp 6\sigma_e)}`,
:math:`\sigma_e^2 = \sigma^2 + 1/12` (the pixel as a box).  In ``v``,
:math:`\mu = v\sqrt{2R - v^2}/R` is smooth (no square-root behaviour at the limb), so 24 nodes suffice.

Parameters ``(r0, c0, a, sigma, amp, ymin, u1, u2)``.  Free by default: ``r0, c0, a, sigma,
amp, ymin, u1``; ``u2`` is held (``SUN_FIXED``) at :data:`U2_DEFAULT`.  Measured on the
HMI 512 PNG (annulus half-widths 4-16 px): with ``u1, u2`` both free their correlation is
-1.000, ``u2`` wanders from -0.79 to +0.53 with the annulus and the radius error from +0.018 to
+0.045 px; with ``u2`` held at 0.23 the fit gives ``u1 = 0.43-0.45`` and a radius error of
+0.036 to +0.039 px for every width (the sigmoid: -0.156 px).

The profile is tabulated in ``d`` and interpolated (:func:`limb_darkened_intensity`); the
Jacobian comes from ``jax.jacfwd`` of the tables plus the per-pixel chain rule
(:func:`_value_and_columns`, all 8 columns; equal to ``jax.jacfwd`` of the intensity to
rounding, and to central differences of :func:`limb_darkened_intensity_direct`: tested).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from ._base import LimbParams, fused_model

_GL_X, _GL_W = np.polynomial.legendre.leggauss(24)
#: Distances at which the profile is tabulated by :func:`limb_darkened_intensity`.
N_TABLE = 1024

#: Quadratic-law coefficients at 0.6 um from Allen's Astrophysical Quantities (Cox 2000,
#: sec. 14.7): ``u = 0.88, v = -0.23`` in ``1 - u(1-mu) - v(1-mu^2)``, i.e.
#: ``u1 = u + 2v = 0.42``, ``u2 = -v = 0.23`` in our form.  HMI observes at 617.3 nm.
U1_DEFAULT = 0.42
U2_DEFAULT = 0.23
#: Parameters held fixed by default.
SUN_FIXED: tuple[str, ...] = ("u2",)


class LimbDarkenedParams(LimbParams):
    """Parameters of :func:`limb_darkened_intensity` (module docstring).

    ``r0, c0`` disc centre (px, ``(row, col)``); ``a`` limb radius (px); ``sigma`` Gaussian
    PSF (px, the pixel box is added); ``amp`` disc-centre radiance above ``ymin`` (the sky);
    ``u1, u2`` quadratic limb-darkening coefficients.
    """

    r0: ArrayLike
    c0: ArrayLike
    a: ArrayLike
    sigma: ArrayLike
    amp: ArrayLike
    ymin: ArrayLike
    u1: ArrayLike
    u2: ArrayLike


def limb_darkening(mu: ArrayLike, u1: ArrayLike, u2: ArrayLike):
    """Quadratic law ``I(mu) = 1 - u1 (1 - mu) - u2 (1 - mu)^2`` (Kopal 1950), ``I(1) = 1``.

    Parameters
    ----------
    mu : array_like
        Cosine of the emission angle (1 at the disc centre, 0 at the limb).
    u1, u2 : array_like
        Linear and quadratic limb-darkening coefficients.

    Returns
    -------
    jax.Array
        Radiance relative to the disc centre, shape of ``mu`` broadcast with the coefficients.
    """
    t = 1.0 - jnp.asarray(mu)
    return 1.0 - u1 * t - u2 * t * t


def _profile_parts(d, R, sigma):
    """``(S0, S1, S2)``: the blurred radial integrals of ``1``, ``1 - mu``, ``(1 - mu)^2`` inside the disc.

    The unit-amplitude profile is ``S0 - u1 S1 - u2 S2`` (module docstring: quadrature in ``v``).
    """
    se = jnp.sqrt(sigma * sigma + 1.0 / 12.0)
    v0 = jnp.sqrt(jnp.maximum(R - d - 6.0 * se, 1e-12))
    v1 = jnp.sqrt(jnp.maximum(R - d + 6.0 * se, 1e-12))
    half = 0.5 * (v1 - v0)
    v = half[..., None] * (jnp.asarray(_GL_X) + 1.0) + v0[..., None]  # (n, nodes)
    v2 = v * v
    mu = v * jnp.sqrt(jnp.maximum(2.0 * R - v2, 0.0)) / R  # sqrt(1 - (d'/R)^2), d' = R - v^2
    x = (d[..., None] - R + v2) / se
    wg = jnp.asarray(_GL_W) * jnp.exp(-0.5 * x * x) * (2.0 / (se * math.sqrt(2.0 * math.pi))) * v * half[..., None]
    t = 1.0 - mu
    return jnp.stack([jnp.sum(wg, -1), jnp.sum(wg * t, -1), jnp.sum(wg * t * t, -1)], axis=0)


def _distance(p: LimbDarkenedParams, rc):
    rc = jnp.asarray(rc)
    dr = rc[..., 0] - p.r0
    dc = rc[..., 1] - p.c0
    d2 = dr * dr + dc * dc
    return jnp.sqrt(jnp.where(d2 > 0, d2, 1.0)), dr, dc


def limb_darkened_intensity_direct(p: LimbDarkenedParams, rc):
    """Blurred limb-darkened disc (module docstring) at pixels ``rc`` ``(n, 2)``: quadrature at every pixel.

    The reference for :func:`limb_darkened_intensity` (which tabulates it).

    Parameters
    ----------
    p : LimbDarkenedParams
        Disc centre, radius, PSF, radiance scale, sky level and limb-darkening coefficients.
    rc : jax.Array (n, 2)
        Pixel coordinates as ``(row, col)``.

    Returns
    -------
    jax.Array (n,)
        Model intensity at each pixel.
    """
    S = _profile_parts(_distance(p, rc)[0], p.a, p.sigma)
    return p.ymin + p.amp * (S[0] - p.u1 * S[1] - p.u2 * S[2])


def _table(a, sigma, sk):
    """Values and ``d``-derivatives of ``(S0, S1, S2)`` at ``d = a + s_k``: ``(6, N)``."""
    dk = a + sk
    S, M = jax.jvp(lambda x: _profile_parts(x, a, sigma), (dk,), (jnp.ones_like(dk),))
    return jnp.concatenate([S, M], axis=0)


def _hermite(T, k, h, step):
    """Cubic Hermite interpolation of the tables ``T`` ``(m, 6, N)`` (values, derivatives) with basis ``h``."""
    y0, y1 = T[..., :3, :][..., k], T[..., :3, :][..., k + 1]
    m0, m1 = T[..., 3:, :][..., k], T[..., 3:, :][..., k + 1]
    return h[0] * y0 + h[1] * step * m0 + h[2] * y1 + h[3] * step * m1


def _value_and_columns(p: LimbDarkenedParams, rc):
    """Intensity and the 8 Jacobian columns (field order) in one pass (see :func:`limb_darkened_intensity`).

    The tables and their derivatives in ``(a, sigma)`` come from ``jax.jacfwd``; the per-pixel
    chain rule is written out (``s = d - a``: ``df/dr0 = -amp H'(s) dr/d``, ``df/da = -amp H'(s)
    + amp H(s; dT/da)``, ``df/du_j = -amp H(s; S_j)``), which keeps the compiled graph small.
    It equals ``jax.jacfwd`` of :func:`limb_darkened_intensity` to rounding (tested).
    """
    d, dr, dc = _distance(p, rc)
    s = d - p.a
    se = jax.lax.stop_gradient(jnp.sqrt(p.sigma * p.sigma + 1.0 / 12.0))
    ext = jax.lax.stop_gradient(jnp.max(jnp.abs(s))) + 6.0 * se + 1e-3
    step = 2.0 * ext / (N_TABLE - 1)
    sk = step * jnp.arange(N_TABLE) - ext
    T = _table(p.a, p.sigma, sk)  # (6, N)
    Ta, Ts = jax.jacfwd(_table, argnums=(0, 1))(p.a, p.sigma, sk)  # (6, N) each
    tt = (s + ext) / step
    k = jnp.clip(jnp.floor(tt), 0, N_TABLE - 2).astype(jnp.int32)
    t = tt - k
    t2, t3 = t * t, t * t * t
    h = (2 * t3 - 3 * t2 + 1, t3 - 2 * t2 + t, -2 * t3 + 3 * t2, t3 - t2)
    dh = tuple(x / step for x in (6 * t2 - 6 * t, 3 * t2 - 4 * t + 1, 6 * t - 6 * t2, 3 * t2 - 2 * t))
    u = jnp.stack([jnp.ones_like(p.u1), -p.u1, -p.u2])
    parts = _hermite(jnp.stack([T, Ta, Ts]), k, h, step)  # (3 tables, 3 parts, n)
    prof, prof_a, prof_s = (jnp.tensordot(u, parts[i], axes=1) for i in range(3))
    dprof = jnp.tensordot(u, _hermite(T, k, dh, step), axes=1)  # dH/ds
    amp = p.amp
    fd = amp * dprof
    inv_d = 1.0 / d
    cols = (-fd * dr * inv_d, -fd * dc * inv_d, amp * prof_a - fd, amp * prof_s, prof, jnp.ones_like(prof),
            -amp * parts[0, 1], -amp * parts[0, 2])
    return p.ymin + amp * prof, cols


def limb_darkened_intensity(p: LimbDarkenedParams, rc):
    """Blurred limb-darkened disc (module docstring) at pixels ``rc`` ``(n, 2)`` as ``(row, col)``.

    The profile depends on a pixel only through its distance ``d`` (``R``, ``sigma``, ``u``
    are shared), so ``(S0, S1, S2)`` are computed by quadrature on :data:`N_TABLE` distances
    ``a + s_k`` spanning the pixels (``s_k`` uniform, step ``< sigma_e / 8`` for annuli up to
    ~15 px) with their exact ``d``-derivatives, and interpolated by cubic Hermite: the error
    is ``<~ 1.5e-3 (step / sigma_e)^4`` of ``amp`` (measured < 2e-7 of ``amp``), and the cost
    no longer scales with pixels x quadrature nodes.  The grid's extent and step are
    constants for differentiation (``stop_gradient``): the derivative is that of the
    interpolant at a fixed grid.

    Parameters
    ----------
    p : LimbDarkenedParams
        Disc centre, radius, PSF, radiance scale, sky level and limb-darkening coefficients.
    rc : jax.Array (n, 2)
        Pixel coordinates as ``(row, col)``.

    Returns
    -------
    jax.Array (n,)
        Model intensity at each pixel.
    """
    return _value_and_columns(p, rc)[0]


LIMB_DARKENED = fused_model("limb_darkened", LimbDarkenedParams, limb_darkened_intensity, _value_and_columns)
"""The limb-darkened disc model (module docstring); its Jacobian the analytic columns of the fused pass."""


__all__ = ["LIMB_DARKENED", "SUN_FIXED", "U1_DEFAULT", "U2_DEFAULT", "LimbDarkenedParams", "limb_darkened_intensity",
           "limb_darkened_intensity_direct", "limb_darkening"]
